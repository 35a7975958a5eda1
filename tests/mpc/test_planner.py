"""MPCPlanner: eq. 14 when nothing is active, limits held closed-loop, swaps, slack, obstacles."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import bounds_of
from hypothesis import example, given, settings
from hypothesis import strategies as st

from mpcform.control.base import ControlStep
from mpcform.control.tracking import TrackingController
from mpcform.errors import ValidationError
from mpcform.formation.geometry import min_segment_distance
from mpcform.formation.kinematics import forward_kinematics
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.strategy import SparseSolve
from mpcform.reference.base import ConstantReference, ExponentialReference, Profile
from mpcform.sim.simulation import SimulationResult, simulate
from mpcform.solvers.base import QPBackend, QPSolution, SolverOptions
from mpcform.world.closest import closest_on_segments
from mpcform.world.limits import Limits
from mpcform.world.shapes import SphereObstacle

SOLVERS = ["osqp", "piqp"]


def _rot(rng: np.random.Generator, dim: int) -> object:
    return rng.uniform(-1, 1) if dim == 2 else rng.uniform(-1, 1, 3)


def swap(n: int, dim: int, d_min: float = 0.5) -> tuple[ConstantReference, np.ndarray]:
    """Antipodal swap: drone i starts at -r_i and must reach r_i (ring or sphere template)."""
    radius = max(2.0, 0.8 / np.sin(np.pi / n)) if dim == 2 else max(2.0, 0.5 * np.sqrt(n))
    tpl = Template.polygon(n, radius) if dim == 2 else Template.sphere(n, radius)
    return ConstantReference(tpl, FormationState.from_param(np.zeros(dim))), -tpl.offsets.copy()


def check_limits(res: SimulationResult, v_max: float, d_min: float) -> None:
    assert np.all(np.isfinite(res.positions_m)) and np.all(np.isfinite(res.commands_mps))
    assert np.linalg.norm(res.commands_mps, axis=-1).max() <= v_max * (1 + 1e-12)
    pos = res.positions_m
    seg = min(min_segment_distance(a, b) for a, b in zip(pos[:-1], pos[1:], strict=True))
    assert seg >= d_min - 1e-6


@pytest.mark.parametrize("loop", [False, True])
@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("fast_path", [True, False])
@pytest.mark.parametrize("dim", [2, 3])
def test_first_input_is_eq14_when_no_row_is_active(
    dim: int, fast_path: bool, solver: str, loop: bool
) -> None:
    """Without the acceleration bound (``a_max = inf``; the default's ramp is tested below), also
    with a lag's velocity loop in the rows (the loop moved by earlier commands; the drones did not
    go where the model took them, so the command is eq. 14 less the velocity offset estimated,
    the low-pass of ``delta = (p - predicted) / dt``: offset-free tracking)."""
    from mpcform.mpc.velocity_loop import VelocityLoop

    rng = np.random.default_rng(dim)
    lag = (np.array([[-5.0]]), np.array([5.0]), np.array([1.0]), (0, 1, 2))
    model = VelocityLoop.from_groups([lag], dim, 0.05, 8) if loop else None
    tol = 1e-9 if fast_path else 1e-6
    for _ in range(8):
        tpl = Template.polygon(6, 3.0, dim)
        start = FormationState.from_param(rng.uniform(-5, 5, dim), _rot(rng, dim), 1.0)
        goal = FormationState.from_param(rng.uniform(-5, 5, dim), _rot(rng, dim), 1.5)
        ref = ExponentialReference(tpl, start, goal, 0.5)
        p = forward_kinematics(tpl, start) + rng.normal(0, 0.1, (6, dim))
        settings_ = MPCSettings(horizon=8, gain_per_s=2.0, fast_path=fast_path)
        planner = MPCPlanner(ref, 0.05, Limits(100.0, 0.2, np.inf), settings_, solver=solver, loop=model)
        planner.reset(0.0, p)
        t = float(rng.uniform(0, 3))
        if loop:  # the drones moving: the loop has a state
            planner.step(t - 0.05, p)
        out = planner.step(t, p)
        want = TrackingController(ref, 2.0, 0.05).step(t, p).command_mps
        if loop:  # the low-pass of delta, from 0 (mpcform.mpc.velocity_loop.CANCEL_TIME_S)
            delta = planner.state.offset_mps
            assert delta is not None
            np.testing.assert_allclose(delta, model.cancel_gain * planner.state.loop_state[..., -1])
            assert np.abs(delta).max() > 0.01
            want = want - delta
        assert out.info.mode == ("fast_path" if fast_path else "qp")
        np.testing.assert_allclose(out.command_mps, want, atol=tol, rtol=0)


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("fast_path", [True, False])
@pytest.mark.parametrize("dim", [2, 3])
def test_with_the_default_a_max_commands_are_eq14_after_the_ramp(
    dim: int, fast_path: bool, solver: str
) -> None:
    """The platform's a_max (1.79 m/s^2) by default: from rest each command moves by at most
    ``a_max dt`` per axis; on a slow reference (eq. 14's rollout then changes by less than that, so
    no row is active once the ramp has caught up), every command after the ramp is eq. 14's, and
    the ramp ends within 2 s."""
    from mpcform.world.limits import DEFAULT_A_MAX_MPS2

    rng, dt = np.random.default_rng(10 + dim), 0.05
    tpl = Template.polygon(6, 3.0, dim)
    start = FormationState.from_param(rng.uniform(-1, 1, dim), 0.1 * np.asarray(_rot(rng, dim)), 1.0)
    goal = FormationState.from_param(rng.uniform(-1, 1, dim), 0.1 * np.asarray(_rot(rng, dim)), 1.1)
    ref = ExponentialReference(tpl, start, goal, 2.0)
    settings_ = MPCSettings(horizon=20, gain_per_s=2.0, fast_path=fast_path)
    planner = MPCPlanner(ref, dt, Limits(v_max_mps=3.0, d_min_m=0.2), settings_, solver=solver)
    assert planner.limits.a_max_mps2 == DEFAULT_A_MAX_MPS2
    p = forward_kinematics(tpl, start) + rng.normal(0, 0.1, (6, dim))
    planner.reset(0.0, p)
    step, u_prev, matched = DEFAULT_A_MAX_MPS2 * dt, np.zeros((6, dim)), []
    for k in range(80):
        out = planner.step(k * dt, p)
        want = TrackingController(ref, 2.0, dt).step(k * dt, p).command_mps
        assert np.abs(out.command_mps - u_prev).max() <= step + 1e-9
        if np.abs(want - u_prev).max() <= step - 1e-6:  # eq. 14 within reach: nothing is active
            np.testing.assert_allclose(out.command_mps, want, atol=1e-9 if fast_path else 1e-6, rtol=0)
            matched.append(k)
        u_prev, p = out.command_mps, p + dt * out.command_mps
    assert matched and 1 <= matched[0] <= 40 and len(matched) == 80 - matched[0]


def test_secant_feedforward_matches_the_secant_law() -> None:
    tpl = Template.polygon(4, 2.0)
    ref = ExponentialReference(
        tpl,
        FormationState.from_param([0, 0], 0.0, 1.0),
        FormationState.from_param([3, 1], 1.0, 2.0),
        1.0,
    )
    p = forward_kinematics(tpl, ref.state(0.0)) + 0.05
    unbounded = Limits(v_max_mps=50.0, a_max_mps2=np.inf)
    planner = MPCPlanner(ref, 0.1, unbounded, MPCSettings(gain_per_s=3.0, feedforward="secant"))
    want = TrackingController(ref, 3.0, 0.1, feedforward="secant").step(0.7, p).command_mps
    np.testing.assert_allclose(planner.step(0.7, p).command_mps, want, atol=1e-12)


@settings(max_examples=8)
@given(
    seed=st.integers(0, 10_000),
    n=st.integers(2, 16),
    dim=st.sampled_from([2, 3]),
    coupling=st.sampled_from(["joint", "decoupled"]),
)
def test_random_scenarios_hold_speed_and_separation(seed: int, n: int, dim: int, coupling: str) -> None:
    rng = np.random.default_rng(seed)
    d_min, v_max = 0.5, 1.5
    tpl = Template.grid(int(np.ceil(np.sqrt(n))), int(np.ceil(n / np.ceil(np.sqrt(n)))), 0.9, 2)
    offsets = np.zeros((n, dim))
    offsets[:, :2] = tpl.offsets[:n]
    tpl = Template.centred(offsets)[0]
    goal = FormationState.from_param(rng.uniform(-2, 2, dim), _rot(rng, dim), rng.uniform(1.0, 1.5))
    start = rng.uniform(-4, 4, (n, dim))
    while n > 1 and min_segment_distance(start, start) < d_min:  # a separated start
        start = rng.uniform(-4, 4, (n, dim))
    planner = MPCPlanner(
        ConstantReference(tpl, goal),
        0.1,
        Limits(v_max_mps=v_max, d_min_m=d_min),
        MPCSettings(horizon=6, coupling=coupling),
    )
    check_limits(simulate(planner, start, 2.5), v_max, d_min)


@pytest.mark.parametrize(
    ("n", "coupling"),
    [
        (4, "joint"),
        (8, "joint"),
        (12, "joint"),
        (16, "joint"),
        (4, "decoupled"),
        (12, "decoupled"),
        (16, "decoupled"),
    ],  # decoupled 16: a symmetric ring stalls until the tie-break angle grows
)
def test_planar_swaps_finish(n: int, coupling: str) -> None:
    ref, start = swap(n, 2)
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), MPCSettings(coupling=coupling))
    res = simulate(planner, start, 30.0)
    check_limits(res, 1.0, 0.5)
    assert np.linalg.norm(res.positions_m[-1] - res.reference_m[-1], axis=1).max() < 1e-2


def test_spatial_swap_of_twelve_finishes() -> None:
    ref, start = swap(12, 3)
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=10))
    res = simulate(planner, start, 15.0)
    check_limits(res, 1.0, 0.5)
    assert np.linalg.norm(res.positions_m[-1] - res.reference_m[-1], axis=1).max() < 1e-2


def test_a_vertical_speed_bound_holds_in_every_command_and_the_swap_finishes() -> None:
    """``v_max_z`` 0.4 m/s: every certified command climbs or sinks at most that fast (and keeps
    v_max), the drones still arrive; a planar formation refuses the bound."""
    ref, start = swap(12, 3)
    lim = Limits(v_max_mps=1.0, d_min_m=0.5, v_max_z_mps=0.4)
    res = simulate(MPCPlanner(ref, 0.1, lim, MPCSettings(horizon=10)), start, 20.0)
    check_limits(res, 1.0, 0.5)
    assert np.abs(res.commands_mps[..., 2]).max() <= 0.4 + 1e-9
    assert np.abs(res.commands_mps[..., 2]).max() > 0.3  # the bound is met, not avoided
    assert np.linalg.norm(res.positions_m[-1] - res.reference_m[-1], axis=1).max() < 1e-2
    planar, planar_start = swap(4, 2)
    with pytest.raises(ValidationError, match="limits.v_max_z"):
        MPCPlanner(planar, 0.1, lim)


def test_infeasible_start_reports_slack_and_separates() -> None:
    tpl = Template.line(2, 2.0)
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0]))
    start = np.array([[0.0, 0.0], [0.1, 0.0]])  # closer than d_min, 4 steps to separate
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=0.5, d_min_m=0.5))
    res = simulate(planner, start, 4.0)
    first = res.infos[0]
    assert first.mode == "qp" and first.max_slack_m > 0.2 and first.slack_pairs == ((0, 1),)
    dist = np.linalg.norm(res.positions_m[:, 0] - res.positions_m[:, 1], axis=1)
    assert np.all(np.diff(dist) >= -1e-9)  # never closer than before
    assert dist[-1] >= 0.5 - 1e-6


def test_obstacle_is_avoided_and_geofence_respected() -> None:
    tpl = Template.polygon(3, 0.6)
    goal = FormationState.from_param([8.0, 0.2])
    start = forward_kinematics(tpl, FormationState.from_param([-4.0, 0.0]))
    ob = SphereObstacle(np.array([2.0, 0.0]), 1.0, clearance_m=0.25)
    lim = Limits(
        v_max_mps=1.5,
        d_min_m=0.4,
        geofence_min_m=np.array([-5.0, -2.0]),
        geofence_max_m=np.array([9.0, 2.0]),
    )
    planner = MPCPlanner(ConstantReference(tpl, goal), 0.1, lim, MPCSettings(horizon=10), obstacles=(ob,))
    res = simulate(planner, start, 14.0)
    check_limits(res, 1.5, 0.4)
    pos = res.positions_m - ob.center_m
    gap = min(
        np.linalg.norm(closest_on_segments(a, b), axis=1).min()
        for a, b in zip(pos[:-1], pos[1:], strict=True)
    )
    assert gap >= 1.25 - 1e-6
    assert np.all(res.positions_m >= lim.geofence_min_m - 1e-6) and np.all(
        res.positions_m <= lim.geofence_max_m + 1e-6
    )
    assert np.linalg.norm(res.positions_m[-1] - res.reference_m[-1], axis=1).max() < 0.05


def test_acceleration_limit_and_downwash() -> None:
    tpl = Template.line(2, 2.0, dim=3)
    ref = ConstantReference(
        tpl, FormationState.from_param([0.0, 0.0, 0.0], [0.0, np.pi / 2, 0.0])
    )  # stacked in z
    start = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    lim = Limits(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=2.0, downwash_kappa=3.0)
    res = simulate(MPCPlanner(ref, 0.1, lim), start, 6.0)
    du = np.diff(np.concatenate([np.zeros((1, 2, 3)), res.commands_mps]), axis=0)
    assert np.abs(du).max() <= 2.0 * 0.1 + 1e-9
    rel = (res.positions_m[:, 0] - res.positions_m[:, 1]) * np.array([1.0, 1.0, 1 / 3.0])
    assert np.linalg.norm(rel, axis=1).min() >= 0.5 - 1e-6
    assert abs(rel[-1, 2]) * 3.0 >= 1.5 - 1e-6  # ends stacked 2 m apart in z, metric distance >= d_min


class FailingBackend(QPBackend):
    """A backend whose every solve fails."""

    name = "failing"

    def __init__(self) -> None:
        super().__init__(SolverOptions())

    def setup(self, P: object, q: object, A: object, lo: object, hi: object) -> None:
        pass

    def update(self, q: object, lo: object, hi: object, A_data: object) -> None:
        pass

    def solve(self, x0: object = None) -> QPSolution:
        return QPSolution(None, None, False, "forced failure", 7, 0.0)


def test_solver_failure_falls_back_to_a_certified_command() -> None:
    ref, start = swap(6, 2)
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), solver=FailingBackend())
    assert planner.solver_name == "failing"
    res = simulate(planner, start, 2.0)
    assert {i.mode for i in res.infos} <= {"fallback", "fast_path"}
    assert any("forced failure" in i.status for i in res.infos)
    check_limits(res, 1.0, 0.5)


def test_plan_is_exposed_and_consistent() -> None:
    ref, start = swap(4, 2)
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=5))
    planner.reset(0.0, start)
    out: ControlStep = planner.step(0.0, start)
    plan = planner.plan
    assert plan is not None and plan.inputs_mps.shape == (5, 4, 2) and plan.positions_m.shape == (6, 4, 2)
    np.testing.assert_allclose(np.diff(plan.positions_m, axis=0), 0.1 * plan.inputs_mps, atol=1e-6)
    np.testing.assert_allclose(plan.inputs_mps[0], out.command_mps, atol=1e-6)


def test_bad_configuration_is_a_clear_error() -> None:
    ref, _ = swap(4, 2)
    with pytest.raises(ValidationError, match="limits.v_max"):
        MPCPlanner(ref, 0.1, Limits(d_min_m=0.5))
    with pytest.raises(ValidationError, match="controller.gain"):
        MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0), MPCSettings(gain_per_s=20.0))
    with pytest.raises(ValidationError, match="obstacles"):
        MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0), obstacles=(SphereObstacle(np.zeros(3), 1.0),))
    with pytest.raises(ValidationError, match="downwash"):
        MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, downwash_kappa=2.0))


@settings(max_examples=6)
@given(seed=st.integers(0, 10_000), coupling=st.sampled_from(["joint", "decoupled"]))
@example(seed=5570, coupling="joint")  # PIQP, even at 1e-9: 6e-5 apart (the gap's square root)
def test_grouping_equals_the_monolithic_qp(seed: int, coupling: str) -> None:
    """Two clusters 40 m apart, one swapping (in conflict): its group alone gives the monolithic answer
    (joint: Clarabel at 1e-12, as an interior point's primal error is about the square root of its gap
    tolerance; decoupled: DAQP, exact)."""
    rng = np.random.default_rng(seed)
    square = Template.polygon(4, 1.5).offsets
    tpl = Template(np.concatenate([square - [20.0, 0.0], square + [20.0, 0.0]]))
    ref = ConstantReference(tpl, FormationState.from_param([20.0, 0.0]))
    start = np.concatenate([-square, square + [40.0, 0.0]]) + rng.normal(0, 0.05, (8, 2))
    firsts = []
    for grouping in (True, False):
        accurate = SparseSolve("qpsolvers:clarabel", SolverOptions(1e-12, 1e-12, 4000))
        tight = None if coupling == "decoupled" else accurate
        settings_ = MPCSettings(coupling=coupling, grouping=grouping, solve=tight)
        planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), settings_)
        planner.reset(0.0, start)
        out = planner.step(0.0, start)
        assert out.info.mode == "qp" and out.info.qp_drones == (4 if grouping else 8)
        firsts.append(out.command_mps)
    np.testing.assert_allclose(firsts[0], firsts[1], atol=1e-5)


def test_close_start_separates_instead_of_freezing() -> None:
    """Three pairs start inside d_min (decoupled): they never approach, separate, and every drone
    arrives; while a pair is inside d_min the step reports it as slack."""
    from families import CLOSE_START_FREEZE, outcome

    out = outcome(CLOSE_START_FREEZE)
    assert out["completion"] == 1.0 and out["separation_violations"] == 0
    assert out["approached"] == 0 and out["unseparated"] == 0
    infos = out["infos"]
    assert not any(i.mode == "fallback" for i in infos)
    assert infos[0].max_slack_m > 0.3 and (0, 5) in infos[0].slack_pairs


@pytest.mark.parametrize("coupling", ["joint", "decoupled"])
def test_a_close_pair_never_approaches(coupling: str) -> None:
    """Two drones 0.1 m apart whose targets lie across each other: the distance never shrinks."""
    tpl = Template(np.array([[-1.0, 0.0], [1.0, 0.0]]))
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0]))
    start = np.array([[0.05, 0.01], [-0.05, -0.01]])  # each on the other's side
    res = simulate(
        MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), MPCSettings(coupling=coupling)), start, 8.0
    )
    rel = res.positions_m[:, 0] - res.positions_m[:, 1]
    steps = zip(rel[:-1], rel[1:], strict=True)
    seg = [np.linalg.norm(closest_on_segments(a[None], b[None])) for a, b in steps]
    assert min(seg) >= np.linalg.norm(rel[0]) - 1e-7
    inside = np.linalg.norm(rel[:-1], axis=1) < 0.5
    assert all(i.max_slack_m > 0 for i, close in zip(res.infos, inside, strict=True) if close)
    assert np.linalg.norm(res.positions_m[-1] - res.reference_m[-1], axis=1).max() < 1e-2


class Translating(ConstantReference):
    """The template translating at a constant velocity ``v`` [m/s] from the origin."""

    def __init__(self, template: Template, v: list[float]) -> None:
        super().__init__(template, FormationState.from_param(np.zeros(template.dim)))
        self.v = np.array(v, dtype=float)

    @property
    def end_s(self) -> float:
        return float("inf")

    def profile(self, times_s: np.ndarray) -> Profile:
        vel = np.broadcast_to(self.v, (times_s.shape[0], self.v.shape[0]))
        pos = times_s[:, None] * self.v
        return replace(super().profile(times_s), centroid_m=pos, centroid_velocity_mps=vel)


MODES = [("joint", True), ("decoupled", True), ("decoupled", False)]  # (coupling, per_drone)


def translating_run(
    tpl: Template,
    v: list[float],
    start: np.ndarray,
    mode: tuple[str, bool],
    fast_path: bool,
    duration_s: float = 0.5,
) -> np.ndarray:
    """Commands of a planner (horizon 8, v_max 20, d_min 0.3, no a_max, tight tolerances) tracking
    ``Translating``."""
    tight = SparseSolve(options=SolverOptions(1e-8, 1e-8, 4000))
    st_ = MPCSettings(horizon=8, coupling=mode[0], solve=None if mode[1] else tight, fast_path=fast_path)
    planner = MPCPlanner(Translating(tpl, v), 0.1, Limits(20.0, 0.3, np.inf), st_)
    return simulate(planner, start, duration_s).commands_mps


@pytest.mark.parametrize("mode", MODES)
def test_fast_path_on_and_off_agree_in_every_coupling(mode: tuple[str, bool]) -> None:
    """Two drones 4 m apart on x, the reference translating at 10 m/s along x (v_max 20): far apart
    all along, so with or without the fast path the first command is eq. 14's (10, 0) (the decoupled
    rows split about the rollout, not the holding guess); random translations of 2-6 drones agree
    to solver tolerance over five steps."""
    pair = Template(np.array([[-2.0, 0.0], [2.0, 0.0]]))
    for fast_path in (True, False):
        first = translating_run(pair, [10.0, 0.0], pair.offsets, mode, fast_path, 0.1)[0]
        np.testing.assert_allclose(first, [[10.0, 0.0], [10.0, 0.0]], atol=1e-5)
    rng = np.random.default_rng(3)
    for n in (2, 4, 6):
        tpl = Template.polygon(n, 1.0)
        v, start = rng.uniform(-8, 8, 2).tolist(), tpl.offsets + rng.normal(0, 0.2, (n, 2))
        on, off = (translating_run(tpl, v, start, mode, fast_path) for fast_path in (True, False))
        np.testing.assert_allclose(on, off, atol=1e-5)


@pytest.mark.slow
@pytest.mark.alone
def test_every_run_of_the_random_families_completes_safely() -> None:
    """200 runs of ``tests/families.py`` (swaps, spheres, close starts): every drone ends within 0.1 m
    of its target, pairs that start d_min apart stay so along every segment, pairs that start
    closer never approach and end separated, and no drone enters a sphere's keep-out."""
    from families import family, outcomes

    bad, late = [], []
    runs = list(family(1, 200))
    for sc, out in zip(runs, outcomes(runs), strict=True):
        checks = ("separation_violations", "approached", "unseparated", "obstacle_violations")
        unsafe = any(out[k] for k in checks)
        if unsafe or (out["completion"] < 1.0 and sc["name"] not in OPEN_INCOMPLETE):
            bad.append((sc["name"], out))
        elif out["completion"] < 1.0:
            late.append(sc["name"])
    assert not bad
    assert sorted(late) == sorted(OPEN_INCOMPLETE)  # fails once they complete: then empty the list


OPEN_INCOMPLETE: tuple[str, ...] = ()
"""Runs that end incomplete, each a known open failure (safe, but not every drone arrives).
swap_planar_192, a decoupled planar ring of 24 drones (horizon 8), jammed under the default a_max
with 10 stalled split rounds (its braking tails' stop rows split near the ring's centre: 8 of 24
arrived); with 20, the default since, it completes at 12.0 s, as every other decoupled run does."""


def test_split_rounds_while_stalled_let_a_decoupled_ring_pass() -> None:
    """swap_planar_136 of the family (10 drones, decoupled): with the midpoint split only
    (``stalled_split = 0``) the ring jams and is still converging when its duration ends; with
    the split rounds in the stalled steps (the default) every drone arrives, and safely."""
    from families import family, outcome

    ring = next(sc for sc in family(1, 137) if sc["name"] == "swap_planar_136")
    jammed = {**ring, "controller": {**ring["controller"], "stalled_split": 0}}
    assert outcome(jammed)["completion"] < 1.0
    out = outcome(ring)
    assert out["completion"] == 1.0 and not out["separation_violations"] and not out["approached"]


@pytest.mark.parametrize("coupling", ["joint", "decoupled"])
def test_with_a_loop_every_first_row_is_hard_and_braking_meets_it(coupling: str) -> None:
    """With a velocity loop the QP's first rows carry no slack (a drone's slack at the first step
    would let it approach one partner as far as another forces it to): each is lowered at most to
    what the braking command reaches, which meets them all, and a lowered bound is reported."""
    from mpcform.mpc.velocity_loop import VelocityLoop

    lag = (np.array([[-5.0]]), np.array([5.0]), np.array([1.0]), (0, 1))
    tpl = Template(np.array([[-1.0, 0.0], [0.0, 0.0], [1.0, 0.0]]))
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0]))
    limits = Limits(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=2.0)
    planner = MPCPlanner(
        ref,
        0.1,
        limits,
        MPCSettings(horizon=6, coupling=coupling),
        loop=VelocityLoop.from_groups([lag], 2, 0.1, 6),
    )
    p0 = np.array([[-0.3, 0.0], [0.0, 0.02], [0.3, 0.0]])  # the middle drone squeezed, moving at both
    planner.reset(0.0, p0)
    steps = planner.steps
    steps.state.u_prev = np.array([[0.8, 0.0], [0.0, 0.0], [-0.8, 0.0]])
    steps.state.loop_state[..., 0] = steps.state.u_prev  # the lag's velocity
    cand = steps.candidates.select(p0)
    state = steps.state.loop_state
    rows = steps.separation.rows(p0, steps.predict.guess(steps.state.plan, p0, state), cand)
    rows = steps.predict.on_forced(rows, state, steps.separation.ends)
    hard, relaxed, _ = steps.certifier.hard_first_rows(
        rows, None, steps.state.u_prev, 6, planner.loop.forced[1, 0]
    )
    assert hard.pair_hard.all() and hard.single_hard.all() and relaxed
    assert np.all(hard.pair_lower <= rows.pair_lower) and np.all(hard.single_lower <= rows.single_lower)
    assert np.array_equal(hard.pair_lower[:, 1:], rows.pair_lower[:, 1:])
    assert np.array_equal(hard.single_lower[:, 1:], rows.single_lower[:, 1:])
    brake = steps.state.u_prev - np.clip(steps.state.u_prev, -0.2, 0.2)
    first = (0.1 + planner.loop.forced[1, 0]) * brake
    at_p = np.einsum("pd,pd->p", hard.pair_coeffs[:, 0], first[hard.pairs[:, 0]] - first[hard.pairs[:, 1]])
    at_s = np.einsum("sd,sd->s", hard.single_coeffs[:, 0], first[hard.singles])
    assert np.all(at_p >= hard.pair_lower[:, 0]) and np.all(at_s >= hard.single_lower[:, 0])
    assert (at_p < rows.pair_lower[:, 0]).any() or (at_s < rows.single_lower[:, 0]).any()


@pytest.mark.parametrize(("miss_m", "reported"), [(1e-9, False), (1e-3, True)])
def test_a_miss_within_the_solvers_tolerance_is_no_slack(miss_m: float, reported: bool) -> None:
    """slack_report (a solve with lowered first rows): a plan that misses a row by 1 nm needed no
    slack; by 1 mm it did, and the pair is named."""
    from mpcform.mpc.constraints.candidates import Candidates
    from mpcform.mpc.constraints.separation import Separation
    from mpcform.mpc.safety.slack import SLACK_REPORT_M, slack_report

    d_min, h = 0.5, 3
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=d_min), MPCSettings(horizon=h), ())
    p0 = np.array([[0.0, 0.0], [2.0, 0.0]])
    pairs = np.array([[0, 1]])
    rows = sep.rows(
        p0,
        np.broadcast_to(p0, (h + 1, 2, 2)),
        Candidates(pairs, np.ones(1, bool), pairs[:0], np.ones(0, bool), False),
    )
    gap = d_min + sep.pairs.margin_m - miss_m  # the rows ask d_min + margin
    x = np.zeros((h, 2, 2))
    x[:, 1, 0] = gap - 2.0  # drone 1 moves to ``gap`` from drone 0
    z = np.zeros(2 * h * 2 * 2 + h * 2)
    slack_m, items, growth_m = slack_report(sep, z, np.arange(2), x, rows, (0.0, pairs[:0]), True, h)
    assert items.tolist() == ([[0, 1]] if reported else [])
    assert slack_m == (pytest.approx(miss_m, rel=1e-6) if reported else 0.0)  # 0: not a slack step
    assert reported == (miss_m > SLACK_REPORT_M) and growth_m == 0.0


@pytest.mark.parametrize(("gap_m", "slack", "into_growth"), [(0.53, 0.0, 0.005), (0.49, 0.015, 0.0)])
def test_a_plan_within_the_rows_growth_keeps_every_required_distance(
    gap_m: float, slack: float, into_growth: float
) -> None:
    """slack_report in wind: a pair 0.53 m apart from step 2 on misses its grown rows (0.5 m +
    margin + up to 2 x 0.02 m of growth: 0.542 m) by 12 mm but keeps its required distance (0.502
    m): that is the growth's buffer, reported apart, not slack. At 0.49 m it enters the required
    distance itself: slack, the pair named, by how far it misses the grown rows."""
    from mpcform.mpc.constraints.candidates import Candidates
    from mpcform.mpc.constraints.separation import Separation
    from mpcform.mpc.safety.slack import slack_report

    h, pairs = 4, np.array([[0, 1]])
    lim = bounds_of(v_max_mps=1.0, d_min_m=0.5, growth_m=0.01)
    sep = Separation(2, lim, MPCSettings(horizon=h), (), dt_s=0.1)  # E = 2: up to 0.02 m per drone
    p0 = np.array([[0.0, 0.0], [0.9, 0.0]])
    growing = sep.growing(p0 + np.array([0.0, 5.0]))
    c = Candidates(pairs, np.ones(1, bool), pairs[:0], np.ones(0, bool), False)
    rows = sep.rows(p0, np.broadcast_to(p0, (h + 1, 2, 2)), c, growing=growing)
    x = np.zeros((h, 2, 2))
    x[1:, 1, 0] = gap_m - 0.9
    z = np.zeros(2 * h * 2 * 2 + h * 2)
    z[2 * h * 2 * 2 :] = 0.01  # the solve's slack variables: a report is asked for
    grown_miss = 0.5 + sep.margin_m + 0.04 - gap_m
    slack_m, items, growth_m = slack_report(
        sep, z, np.arange(2), x, rows, (0.0, pairs[:0]), False, h, growing
    )
    assert slack_m == pytest.approx(grown_miss if slack else 0.0)
    assert items.tolist() == ([[0, 1]] if slack else [])
    assert growth_m == pytest.approx(grown_miss if into_growth else 0.0)
    no_wind = slack_report(sep, z, np.arange(2), x, rows, (0.0, pairs[:0]), False, h)  # no shares
    assert no_wind[0] == pytest.approx(grown_miss) and no_wind[2] == 0.0


def test_a_solve_that_leaves_slack_the_shifted_plan_avoids_keeps_the_plan() -> None:
    """Slack weights far below the rows' multipliers (no exact penalty, even raised) let PIQP buy
    slack on QPs the previous plan, shifted, meets: with braking that plan is kept instead (theorem
    (ii)), reported as such, and no step after the first has slack (that one has no plan to keep)."""
    ref, start = swap(6, 2)
    settings = MPCSettings(horizon=8, slack_weight=1e-6, slack_quadratic=1e-6)
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=1.0), settings)
    res = simulate(planner, start, 6.0)
    kept = [i for i in res.infos if i.status.endswith("previous plan (the solve left slack)")]
    assert len(kept) >= 3 and res.infos[0].max_slack_m > 0.01
    assert all(i.max_slack_m == 0.0 for i in res.infos[1:])
    check_limits(res, 1.0, 0.5)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [({"limits": {"v_max": 1.0}}, "limits"), ({"settings": {"horizon": 5}}, "settings")],
)
def test_a_planner_refuses_what_is_not_its_types(kwargs: dict, field: str) -> None:
    """``MPCPlanner(ref, 0.1, {"v_max": 1.0})``: a ValidationError naming the argument, not an
    AttributeError deep inside."""
    ref = ConstantReference(Template.polygon(3, 1.0), FormationState.from_param([0.0, 0.0]))
    with pytest.raises(ValidationError, match=rf"^{field}: expected mpcform\."):
        MPCPlanner(ref, 0.1, **kwargs)


def test_with_no_offset_estimated_a_loop_planner_commands_eq14_bitwise() -> None:
    """Offset-free tracking cancels only an estimated offset: at the first step (the loop at rest,
    ``delta = 0``) a lag planner's command is eq. 14 bitwise, the ideal planner's; once the drones
    drift by ``r`` per interval, the command is eq. 14 less the low-pass of ``delta = r / dt``."""
    from mpcform.mpc.velocity_loop import VelocityLoop

    tpl = Template.polygon(6, 3.0)
    ref = ConstantReference(tpl, FormationState.from_param(np.array([1.0, -2.0])))
    p = forward_kinematics(tpl, FormationState.from_param(np.zeros(2)))
    lag = (np.array([[-5.0]]), np.array([5.0]), np.array([1.0]), (0, 1))
    limits = Limits(v_max_mps=100.0, d_min_m=0.2, a_max_mps2=np.inf)
    settings_ = MPCSettings(horizon=8, gain_per_s=2.0)
    plain = MPCPlanner(ref, 0.05, limits, settings_)
    looped = MPCPlanner(ref, 0.05, limits, settings_, loop=VelocityLoop.from_groups([lag], 2, 0.05, 8))
    want = TrackingController(ref, 2.0, 0.05).step(0.0, p).command_mps
    np.testing.assert_array_equal(plain.step(0.0, p).command_mps, want)
    np.testing.assert_array_equal(looped.step(0.0, p).command_mps, want)
    drift = np.array([0.002, -0.001])
    loop = looped.loop
    assert loop is not None
    for k in range(1, 30):  # a steady offset: 2.2 mm per interval more than modelled, then foreseen
        p1 = looped._predicted + (drift if k == 1 else 0.0)
        out = looped.step(0.05 * k, p1)
        cancelled = (1.0 - (1.0 - loop.cancel_gain) ** k) * drift / 0.05  # the low-pass, from 0
        want = TrackingController(ref, 2.0, 0.05).step(0.05 * k, p1).command_mps - cancelled
        np.testing.assert_allclose(out.command_mps, want, atol=1e-9, rtol=0)
