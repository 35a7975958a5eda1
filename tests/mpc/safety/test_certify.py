"""Certification: commands scaled into the ball, refused when they close a gap too far; the fallback."""

from __future__ import annotations

import numpy as np
from helpers import bounds_of

from mpcform.mpc.constraints.candidates import Candidates
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.plan import Plan
from mpcform.mpc.safety.certify import Certifier
from mpcform.mpc.settings import MPCSettings
from mpcform.world.shapes import SphereObstacle

DT = 0.1


def certifier(obstacles: tuple[SphereObstacle, ...] = (), d_min: float = 0.5) -> Certifier:
    lim = bounds_of(v_max_mps=1.0, d_min_m=d_min)
    return Certifier(DT, lim.v_max_mps, Separation(2, lim, MPCSettings(), obstacles))


def items(pairs: list[list[int]], obstacles: list[list[int]] | None = None) -> Candidates:
    p = np.array(pairs, dtype=np.intp).reshape(-1, 2)
    o = np.array(obstacles or [], dtype=np.intp).reshape(-1, 2)
    return Candidates(p, np.ones(p.shape[0], bool), o, np.ones(o.shape[0], bool), False)


def test_a_command_outside_the_ball_is_scaled_onto_it() -> None:
    p0 = np.array([[0.0, 0.0], [5.0, 0.0]])
    u = np.array([[3.0, 4.0], [0.3, 0.0]])  # drone 0 at 5 m/s
    out = certifier().certify(p0, u, items([[0, 1]]))
    assert out is not None
    np.testing.assert_allclose(out, [[0.6, 0.8], [0.3, 0.0]])  # same direction, |u| = v_max
    assert np.linalg.norm(out, axis=1).max() <= 1.0 + 1e-12


def test_with_a_vertical_bound_a_command_is_scaled_into_the_spheroid() -> None:
    """``v_max_z`` 0.5 of v_max 1: a climb of 0.8 m/s is scaled along its direction onto the
    spheroid (vertical 0.5), a slow climb is kept."""
    lim = bounds_of(v_max_mps=1.0, d_min_m=0.5, v_max_z_mps=0.5)
    cert = Certifier(DT, 1.0, Separation(3, lim, MPCSettings(), ()), scale=lim.speed_scale(3))
    p0 = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    u = np.array([[0.3, 0.0, 0.8], [0.0, 0.2, 0.3]])
    out = cert.certify(p0, u, items([[0, 1]]))
    assert out is not None
    k = 1.0 / np.hypot(0.3, 0.8 * 2.0)  # ||S u|| = v_max with S = diag(1, 1, 2)
    np.testing.assert_allclose(out, [[0.3 * k, 0.0, 0.8 * k], [0.0, 0.2, 0.3]])


def test_a_command_that_breaks_d_min_is_refused() -> None:
    """0.55 m apart, both flying at 1 m/s towards each other for 0.1 s: 0.35 m < d_min."""
    p0 = np.array([[0.0, 0.0], [0.55, 0.0]])
    towards = np.array([[1.0, 0.0], [-1.0, 0.0]])
    cert = certifier()
    assert cert.certify(p0, towards, items([[0, 1]])) is None
    assert cert.certify(p0, -towards, items([[0, 1]])) is not None  # apart
    off = Candidates(np.array([[0, 1]]), np.array([False]), np.empty((0, 2), int), np.empty(0, bool), False)
    assert cert.certify(p0, towards, off) is not None  # only items within reach are checked


def test_a_pair_already_too_close_may_not_get_closer() -> None:
    p0 = np.array([[0.0, 0.0], [0.3, 0.0]])  # inside d_min
    cert = certifier()
    assert cert.certify(p0, np.array([[0.0, 1.0], [0.0, 1.0]]), items([[0, 1]])) is not None  # parallel
    assert cert.certify(p0, np.array([[0.5, 0.0], [0.0, 0.0]]), items([[0, 1]])) is None  # closer


def test_with_a_loop_a_close_pair_may_come_as_close_as_its_free_response() -> None:
    """A 0.2 s lag: drone 1 still flies at 1 m/s towards drone 0, inside d_min. Within the
    interval no command undoes that velocity (the hold's chord closes 0.079 m), so the hold and
    braking certify; a command that closes the pair beyond its free response does not."""
    from mpcform.mpc.velocity_loop import VelocityLoop

    lag = (np.array([[-5.0]]), np.array([5.0]), np.array([1.0]), (0, 1))
    loop = VelocityLoop.from_groups([lag], 2, DT, 3)
    state = loop.rest(2)
    state[1, 0, 0] = -1.0  # drone 1's velocity [m/s]
    cert = certifier()
    cert.drift = lambda u0: loop.first(state, u0)
    p0 = np.array([[0.0, 0.0], [0.4, 0.0]])
    hold = np.zeros((2, 2))
    assert cert.certify(p0, hold, items([[0, 1]])) is not None
    assert cert.certify(p0, np.array([[0.0, 0.0], [1.0, 0.0]]), items([[0, 1]])) is not None  # brake
    assert cert.certify(p0, np.array([[1.0, 0.0], [0.0, 0.0]]), items([[0, 1]])) is None  # closer
    cert.drift = None  # the single integrator: the hold keeps the distance, the same push does not
    assert cert.certify(p0, np.array([[1.0, 0.0], [0.0, 0.0]]), items([[0, 1]])) is None


def test_the_closest_point_of_the_segment_counts() -> None:
    """Passing each other sideways: 0.141 m apart at both ends of the step, 0.1 m halfway."""
    p0 = np.array([[0.0, -0.05], [0.1, 0.05]])
    u = np.array([[1.0, 0.0], [-1.0, 0.0]])
    assert certifier(d_min=0.05).certify(p0, u, items([[0, 1]])) is not None
    assert certifier(d_min=0.12).certify(p0, u, items([[0, 1]])) is None


def test_obstacle_gap_is_certified() -> None:
    ob = SphereObstacle(np.array([1.0, 0.0]), 0.5, clearance_m=0.2)  # keep 0.7 m from (1, 0)
    cert = certifier((ob,))
    p0 = np.array([[0.25, 0.0]])  # 0.75 m away; 0.65 m after 0.1 s at 1 m/s towards it
    assert cert.certify(p0, np.array([[1.0, 0.0]]), items([], [[0, 0]])) is None
    assert cert.certify(p0, np.array([[-1.0, 0.0]]), items([], [[0, 0]])) is not None


def test_fallback_takes_the_previous_plans_next_input_scaled() -> None:
    p0 = np.array([[0.0, 0.0], [5.0, 0.0]])
    inputs = np.array([[[0.1, 0.0], [0.0, 0.1]], [[2.0, 0.0], [0.0, 0.5]], [[0.3, 0.0], [0.0, 0.3]]])
    plan = Plan(inputs, np.zeros((4, 2, 2)))
    u, x, note = certifier().fallback(plan, p0, items([[0, 1]]), 3)
    assert note == "previous plan"
    np.testing.assert_allclose(u[0], [[1.0, 0.0], [0.0, 0.5]])  # 2 m/s scaled to v_max
    np.testing.assert_allclose(u[1], inputs[2])
    np.testing.assert_allclose(u[2], 0.0)  # ends in a hold
    np.testing.assert_allclose(x, DT * np.cumsum(u, axis=0))


def test_fallback_holds_when_the_previous_plan_does_not_certify() -> None:
    p0 = np.array([[0.0, 0.0], [0.55, 0.0]])
    inputs = np.array([[[0.0, 0.0], [0.0, 0.0]], [[1.0, 0.0], [-1.0, 0.0]]])  # next: head-on
    for plan in (Plan(inputs, np.zeros((3, 2, 2))), None):
        u, x, note = certifier().fallback(plan, p0, items([[0, 1]]), 2)
        assert note == "hold" and u.shape == (2, 2, 2) and not u.any() and not x.any()


def test_fallback_separates_a_close_pair_rather_than_holding() -> None:
    """0.3 m apart (d_min 0.5), the previous plan flies them together: the fallback pushes them apart."""
    p0 = np.array([[0.0, 0.0], [0.3, 0.0]])
    inputs = np.array([[[0.0, 0.0], [0.0, 0.0]], [[1.0, 0.0], [-1.0, 0.0]]])
    u, x, note = certifier().fallback(Plan(inputs, np.zeros((3, 2, 2))), p0, items([[0, 1]]), 2)
    assert note.startswith("separating command")
    np.testing.assert_allclose(u[0], [[-1.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(u[1], 0.0)
    np.testing.assert_allclose(x, DT * np.cumsum(u, axis=0))


def test_fallback_scales_the_solved_command_back_until_it_certifies() -> None:
    """0.7 m apart, the solved command closes 0.4 m in a step: half of it (0.2 m) certifies."""
    p0 = np.array([[0.0, 0.0], [0.7, 0.0]])
    solved = np.array([[2.0, 0.0], [-2.0, 0.0]])
    cert = Certifier(DT, 3.0, Separation(2, bounds_of(v_max_mps=3.0, d_min_m=0.5), MPCSettings(), ()))
    u, _, note = cert.fallback(None, p0, items([[0, 1]]), 3, solved)
    assert note == "solved command x 0.5"
    np.testing.assert_allclose(u[0], 0.5 * solved)


def test_fallback_keeps_within_a_max() -> None:
    """With a_max 2 m/s^2 (0.2 m/s per step) every fallback command stays within 0.2 m/s of the last
    one, and the plan after it slows down by at most that much per step."""
    lim = bounds_of(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=2.0)
    cert = Certifier(DT, 1.0, Separation(2, lim, MPCSettings(), ()), lim.a_max_mps2)
    p0 = np.array([[0.0, 0.0], [0.3, 0.0]])
    u_prev = np.array([[0.0, 0.5], [0.0, 0.5]])  # flying side by side
    u, _, note = cert.fallback(None, p0, items([[0, 1]]), 6, None, u_prev)
    assert note.startswith("separating command")
    steps = np.diff(np.concatenate([u_prev[None], u]), axis=0)
    assert np.abs(steps).max() <= 0.2 + 1e-12
    np.testing.assert_allclose(u[-1], 0.0)
    far = np.array([[0.0, 0.0], [5.0, 0.0]])  # nothing to separate: decelerate
    u, _, note = cert.fallback(None, far, items([[0, 1]]), 4, None, u_prev)
    assert note == "decelerate"
    np.testing.assert_allclose(u[0], [[0.0, 0.3], [0.0, 0.3]])


def test_the_floor_is_the_braking_commands_chord() -> None:
    """1.0 m apart (d_min 0.5) under a 0.2 s lag, drone 1 still flying at 12 m/s towards drone 0:
    no command keeps the pair apart in this interval. The floor is where the braking command the
    QP's first rows are lowered to (``floor_command``) takes the pair: that command certifies, one
    that closes the pair beyond it does not, and a floor command that brakes less lowers the floor."""
    from mpcform.mpc.velocity_loop import VelocityLoop

    lag = (np.array([[-5.0]]), np.array([5.0]), np.array([1.0]), (0, 1))
    loop = VelocityLoop.from_groups([lag], 2, DT, 3)
    state = loop.rest(2)
    state[1, 0, 0] = -12.0
    cert = certifier()
    cert.drift = lambda u0: loop.first(state, u0)
    p0 = np.array([[0.0, 0.0], [1.0, 0.0]])
    brake = np.array([[0.0, 0.0], [-1.0, 0.0]])
    cert.floor_command = brake
    assert cert.certify(p0, brake, items([[0, 1]])) is not None
    assert cert.certify(p0, brake + [[0.5, 0.0], [0.0, 0.0]], items([[0, 1]])) is None
    cert.floor_command = brake + [[0.5, 0.0], [0.0, 0.0]]
    assert cert.certify(p0, brake + [[0.5, 0.0], [0.0, 0.0]], items([[0, 1]])) is not None


def test_the_kept_plan_is_the_shifted_plan_when_it_meets_the_rows_and_certifies() -> None:
    """``kept``: with braking, the previous plan shifted one step (its last input braking, its first
    moved within ``a_max dt`` of the last command) when ``meets`` accepts it and its first input
    certifies; None when ``meets`` refuses it, when it would close a pair, or without braking."""
    from mpcform.mpc.constraints.braking import Braking

    lim = bounds_of(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=2.0)
    braking = Braking.of(DT, lim)
    assert braking is not None
    cert = Certifier(DT, 1.0, Separation(2, lim, MPCSettings(), (), braking), 2.0, braking)
    p0 = np.array([[0.0, 0.0], [3.0, 0.0]])
    u = np.tile(np.array([[0.5, 0.0], [-0.5, 0.0]]), (4, 1, 1))
    plan = Plan.from_relative(p0, u, DT * np.cumsum(u, axis=0))
    kept = cert.kept(plan, p0, items([[0, 1]]), u[0], lambda u, x: True)
    assert kept is not None
    np.testing.assert_allclose(kept[0], braking.shifted(u))
    np.testing.assert_allclose(kept[1], DT * np.cumsum(braking.shifted(u), axis=0))
    assert cert.kept(plan, p0, items([[0, 1]]), u[0], lambda u, x: False) is None
    close = np.array([[0.0, 0.0], [0.55, 0.0]])  # the first interval would bring them within d_min
    assert cert.kept(plan, close, items([[0, 1]]), u[0], lambda u, x: True) is None
    plain = Certifier(DT, 1.0, Separation(2, lim, MPCSettings(), ()), 2.0)
    assert plain.kept(plan, p0, items([[0, 1]]), u[0], lambda u, x: True) is None
