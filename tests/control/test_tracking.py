"""Proportional and tracking controllers: eq. 4/7 and eq. 14 commands, validation, worked example."""

import numpy as np
import pytest

from mpcform.control.laws import saturate
from mpcform.control.tracking import ProportionalController, TrackingController
from mpcform.errors import ValidationError
from mpcform.formation.kinematics import drone_velocities, forward_kinematics
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.reference.base import ExponentialReference
from mpcform.sim.simulation import simulate

GAIN, DT, V_MAX = 2.0, 0.02, 3.0
TEMPLATE = Template.polygon(3, 1.0)
START = FormationState.from_param([5.0, 5.0], 0.0, 1.0)
WORKED_REFERENCE = ExponentialReference(
    TEMPLATE, START, FormationState.from_param([5.0, 5.0], 0.0, 2.0), rate_per_s=1.0
)


def eq19(s):
    """Seed eq. 19: the desired triangle about (5, 5) at scale s, theta = 0."""
    h = np.sqrt(3.0) / 2.0
    return np.array([[5.0 + s, 5.0], [5.0 - s / 2, 5.0 + h * s], [5.0 - s / 2, 5.0 - h * s]])


def worked_example(dt=DT, feedforward="jacobian", perturbation=0.0):
    ctrl = TrackingController(WORKED_REFERENCE, GAIN, dt, v_max_mps=V_MAX, feedforward=feedforward)
    return simulate(ctrl, eq19(1.0) + perturbation, duration_s=10.0)


def tracking_errors(result):
    """Max over drones of ||p_i - p*_i|| at every sample."""
    return np.linalg.norm(result.positions_m - result.reference_m, axis=-1).max(axis=1)


def spinning_reference(dim):
    tpl = Template.polygon(4, 1.5, dim=dim)
    rot = (0.2, 1.7) if dim == 2 else ([0.0, 0.0, 0.2], [0.4, -0.3, 1.0])
    start = FormationState.from_param(np.ones(dim), rot[0], 1.0)
    goal = FormationState.from_param(-np.ones(dim), rot[1], 1.5)
    return ExponentialReference(tpl, start, goal, 0.7)


# ---- one step --------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_proportional_step_is_saturated_eq_4(dim):
    ref = spinning_reference(dim)
    p = np.random.default_rng(0).normal(size=(4, dim)) * [[1.0], [1.0], [0.0], [9.0]]
    target = forward_kinematics(ref.template, ref.state(0.4))
    raw = GAIN * (target - p)
    out = ProportionalController(ref, GAIN, DT, v_max_mps=V_MAX).step(0.4, p)
    np.testing.assert_allclose(out.command_mps, saturate(raw, V_MAX), atol=1e-12)
    assert out.info.mode == "law"
    assert out.info.saturated == int((np.linalg.norm(raw, axis=1) > V_MAX).sum())


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("feedforward", ["jacobian", "secant"])
def test_tracking_step_is_eq_14(dim, feedforward):
    ref, t = spinning_reference(dim), 0.3
    p = np.random.default_rng(1).normal(size=(4, dim))
    target = forward_kinematics(ref.template, ref.state(t))
    if feedforward == "jacobian":  # J(xi_d) xi_dot_d
        ff = drone_velocities(ref.template, ref.state(t), ref.velocity(t))
    else:  # (p*(t + dt) - p*(t)) / dt
        ff = (forward_kinematics(ref.template, ref.state(t + DT)) - target) / DT
    out = TrackingController(ref, GAIN, DT, feedforward=feedforward).step(t, p)
    np.testing.assert_allclose(out.command_mps, ff + GAIN * (target - p), atol=1e-10)
    assert out.info.saturated == 0


def test_tracking_saturation_counts_capped_drones():
    p = eq19(1.0) + [[0.0, 0.0], [30.0, 0.0], [0.0, 0.0]]  # feedforward speeds are 1 m/s
    out = TrackingController(WORKED_REFERENCE, GAIN, DT, v_max_mps=V_MAX).step(0.0, p)
    assert out.info.saturated == 1
    np.testing.assert_allclose(np.linalg.norm(out.command_mps, axis=1), [1.0, V_MAX, 1.0])


@pytest.mark.parametrize("cls", [ProportionalController, TrackingController])
@pytest.mark.parametrize(
    ("gain", "dt", "v_max", "match"),
    [
        (60.0, 0.02, None, "controller.gain"),  # k dt = 1.2
        (0.0, 0.02, None, "controller.gain"),
        (1.0, 0.0, None, "simulation.dt"),
        (1.0, 0.02, -3.0, "limits.v_max"),
    ],
)
def test_controllers_reject_bad_parameters(cls, gain, dt, v_max, match):
    with pytest.raises(ValidationError, match=match):
        cls(WORKED_REFERENCE, gain, dt, v_max_mps=v_max)


def test_controllers_accept_k_dt_equal_to_one():
    out = ProportionalController(WORKED_REFERENCE, 50.0, 0.02).step(0.0, eq19(1.0) + 0.5)
    np.testing.assert_allclose(eq19(1.0) + 0.5 + 0.02 * out.command_mps, eq19(1.0), atol=1e-12)


def test_tracking_rejects_unknown_feedforward():
    with pytest.raises(ValidationError, match="controller.feedforward"):
        TrackingController(WORKED_REFERENCE, GAIN, DT, feedforward="euler")


@pytest.mark.parametrize("positions", [np.zeros((2, 2)), np.zeros((3, 3)), np.full((3, 2), np.nan)])
def test_step_rejects_bad_positions(positions):
    with pytest.raises(ValidationError, match="positions"):
        TrackingController(WORKED_REFERENCE, GAIN, DT).step(0.0, positions)


# ---- the worked example (seed section 3.7) -------------------------------------------------------
# Unit triangle at c = (5, 5), theta = 0, s = 1; eq. 16 with lambda = 1/s and s* = 2; k = 2/s,
# dt = 0.02 s for 10 s, v_max = 3 m/s (never binding). The centroid stays at (5, 5), the drones end
# within 1e-3 m of eq. 19 with s = 2, and the tracking error is O(dt) and decays.
@pytest.fixture(scope="module")
def worked():
    return worked_example()


def test_worked_example_reference_is_eq_19(worked):
    for t, p_ref in zip(worked.t_s, worked.reference_m, strict=True):
        np.testing.assert_allclose(p_ref, eq19(2.0 - np.exp(-t)), atol=1e-12)  # eq. 16


def test_worked_example_centroid_stays_put(worked):
    assert worked.t_s.size == 501
    np.testing.assert_allclose(worked.positions_m.mean(axis=1), 5.0, atol=1e-12)


def test_worked_example_ends_on_the_doubled_triangle(worked):
    np.testing.assert_allclose(worked.positions_m[-1], eq19(2.0), atol=1e-3)


def test_worked_example_never_saturates(worked):
    assert all(info.saturated == 0 for info in worked.infos)
    assert np.linalg.norm(worked.commands_mps, axis=-1).max() < V_MAX


def test_worked_example_tracking_error_is_first_order_in_dt_and_decays(worked):
    err, err_half = tracking_errors(worked), tracking_errors(worked_example(dt=DT / 2))
    # e_{j+1} = (1 - k dt) e_j + delta_j with |delta_j| <= dt^2 / 2 max|p*''| and
    # max|p*''| = lambda^2 (s* - s0) |r_i| = 1 m/s^2, so |e| <= dt / (2 k) (1 + o(1)).
    assert err.max() <= 1.05 * DT / (2 * GAIN)
    assert 1.8 <= err.max() / err_half.max() <= 2.2
    assert err[-1] < 1e-3 * err.max()
    assert err[0] == 0.0


def test_worked_example_secant_error_decays_exactly_geometrically():
    perturbation = np.random.default_rng(0).normal(0.0, 0.3, (3, 2))
    err = tracking_errors(worked_example(feedforward="secant", perturbation=perturbation))
    predicted = err[0] * (1.0 - GAIN * DT) ** np.arange(err.size)
    # positions of ~7 m carry ~1e-15 m of rounding per step: compare while the error is >= 1e-4 m
    check = predicted >= 1e-4
    assert check.sum() > 150
    np.testing.assert_allclose(err[check], predicted[check], rtol=1e-9)
