"""Formation kinematics: forward map, Jacobian (against finite differences), pseudo-inverse,
null-space projector and the best-fit inverse (fit_formation)."""

import numpy as np
import pytest
from helpers import random_state, random_template
from hypothesis import given
from hypothesis import strategies as st
from scipy.linalg import expm

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.formation.kinematics import (
    PINV_RTOL,
    drone_velocities,
    fit_formation,
    formation_jacobian,
    forward_kinematics,
    jacobian_pinv,
    nullspace_projector,
    velocity_size,
)
from mpcform.formation.rotation import hat
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template

seeds = st.integers(0, 2**32 - 1)
dims = st.sampled_from([2, 3])
EPS = 1e-5


def world_generators(dim):
    """Generators G_k of world-frame turns R -> expm(eps G_k) R (planar: theta -> theta + eps)."""
    if dim == 2:
        return [np.array([[0.0, -1.0], [1.0, 0.0]])]
    return [hat(e) for e in np.eye(3)]


def perturbed(state, k, eps):
    """The state moved by eps along formation-velocity component k (c, omega_world, s)."""
    c, rot, s = state.centroid_m.copy(), state.rotation_body_to_world, state.scale
    d = state.dim
    if k < d:
        c[k] += eps
    elif k < velocity_size(d) - 1:
        rot = expm(eps * world_generators(d)[k - d]) @ rot
    else:
        s += eps
    return FormationState(c, rot, s)


def central_difference(template, state, k):
    """d p / d xi_k by central differences of the forward map, stacked drone by drone."""
    plus = forward_kinematics(template, perturbed(state, k, EPS))
    minus = forward_kinematics(template, perturbed(state, k, -EPS))
    return (plus - minus).ravel() / (2 * EPS)


def rms_distance(a, b):
    return float(np.sqrt(((a - b) ** 2).sum(axis=1).mean()))


def case(seed, n, dim):
    rng = np.random.default_rng(seed)
    return random_template(rng, n, dim), random_state(rng, dim), rng


def test_forward_kinematics_is_eq_10():
    tpl = Template(np.array([[1.0, 0.0], [-1.0, 0.0]]))
    state = FormationState.from_param([5.0, 5.0], np.pi / 2, 2.0)
    np.testing.assert_allclose(forward_kinematics(tpl, state), [[5.0, 7.0], [5.0, 3.0]], atol=1e-12)


@given(seeds, st.integers(1, 6), dims)
def test_jacobian_matches_finite_differences(seed, n, dim):
    tpl, state, _ = case(seed, n, dim)
    jac = formation_jacobian(tpl, state)
    assert jac.shape == (dim * n, velocity_size(dim)) == (dim * n, {2: 4, 3: 7}[dim])
    fd = np.column_stack([central_difference(tpl, state, k) for k in range(jac.shape[1])])
    np.testing.assert_allclose(jac, fd, atol=1e-7)


@given(seeds, st.integers(1, 6), dims)
def test_drone_velocities_equal_j_times_xi_dot(seed, n, dim):
    tpl, state, rng = case(seed, n, dim)
    xi_dot = rng.normal(size=velocity_size(dim))
    expected = (formation_jacobian(tpl, state) @ xi_dot).reshape(n, dim)
    np.testing.assert_allclose(drone_velocities(tpl, state, xi_dot), expected, atol=1e-12)


@pytest.mark.parametrize(
    "call",
    [
        lambda tpl, state: forward_kinematics(tpl, state),
        lambda tpl, state: formation_jacobian(tpl, state),
        lambda tpl, state: drone_velocities(tpl, state, np.zeros(7)),
    ],
    ids=["forward_kinematics", "formation_jacobian", "drone_velocities"],
)
def test_kinematics_reject_mismatched_dimensions(call):
    with pytest.raises(ValidationError, match="state"):
        call(Template.polygon(3, dim=3), FormationState.from_param([0.0, 0.0]))


@pytest.mark.parametrize("xi_dot", [np.zeros(5), np.array([0, 0, np.nan, 0.0])])
def test_drone_velocities_reject_bad_xi_dot(xi_dot):
    with pytest.raises(ValidationError, match="xi_dot"):
        drone_velocities(Template.polygon(3), FormationState.from_param([0.0, 0.0]), xi_dot)


# ---- position-level inverse -----------------------------------------------------------------
def assert_fit_reproduces(tpl, state):
    positions = forward_kinematics(tpl, state)
    fit = fit_formation(tpl, positions)
    np.testing.assert_allclose(forward_kinematics(tpl, fit.state), positions, atol=1e-9)
    assert fit.residual_rms_m < 1e-9
    return fit


@given(seeds, st.integers(2, 7), dims)
def test_fit_inverts_forward_kinematics(seed, n, dim):
    tpl, state, _ = case(seed, n, dim)
    fit = assert_fit_reproduces(tpl, state)
    np.testing.assert_allclose(fit.state.centroid_m, state.centroid_m, atol=1e-9)
    assert fit.state.scale == pytest.approx(state.scale, rel=1e-9)
    # generic offsets span min(n - 1, d) dimensions; R is identifiable when they span d - 1
    assert fit.rotation_identifiable == (n >= dim)
    if fit.rotation_identifiable:
        np.testing.assert_allclose(fit.state.rotation_body_to_world, state.rotation_body_to_world, atol=1e-8)


@pytest.mark.parametrize(("dim", "identifiable"), [(2, True), (3, False)])
def test_fit_of_a_collinear_template(dim, identifiable):
    tpl = Template.line(4, spacing=0.8, dim=dim)
    state = random_state(np.random.default_rng(3), dim)
    fit = assert_fit_reproduces(tpl, state)
    assert fit.rotation_identifiable is identifiable
    assert fit.state.scale == pytest.approx(state.scale, rel=1e-9)


def test_fit_of_a_single_drone():
    fit = fit_formation(Template.line(1, dim=3), [[1.0, 2.0, 3.0]])
    np.testing.assert_allclose(fit.state.centroid_m, [1.0, 2.0, 3.0])
    assert fit.residual_rms_m == 0.0 and not fit.rotation_identifiable


@given(seeds, dims)
def test_fit_of_noisy_positions_has_a_positive_optimal_residual(seed, dim):
    tpl, state, rng = case(seed, 6, dim)
    noisy = forward_kinematics(tpl, state) + rng.normal(0.0, 0.05, (6, dim))
    fit = fit_formation(tpl, noisy)
    assert fit.residual_rms_m > 0.0
    assert fit.residual_rms_m == pytest.approx(
        rms_distance(noisy, forward_kinematics(tpl, fit.state)), rel=1e-9
    )
    # the fit is a least-squares optimum: no worse than the true state, nor than a nudged fit
    assert fit.residual_rms_m <= rms_distance(noisy, forward_kinematics(tpl, state)) + 1e-12
    for k in range(velocity_size(dim)):
        for eps in (1e-4, -1e-4):
            nudged = forward_kinematics(tpl, perturbed(fit.state, k, eps))
            assert fit.residual_rms_m <= rms_distance(noisy, nudged) + 1e-12


def test_fit_rejects_bad_positions():
    tpl = Template.polygon(3)
    with pytest.raises(ValidationError, match="positions"):
        fit_formation(tpl, np.zeros((4, 2)))
    with pytest.raises(ValidationError, match="positions"):
        fit_formation(tpl, [[0.0, 0.0], [1.0, np.nan], [2.0, 0.0]])
    with pytest.raises(ValidationError, match="positions"):
        fit_formation(tpl, np.ones((3, 2)))  # all drones coincide: no scale


# ---- pseudo-inverse and null space ------------------------------------------------------------
# With centred offsets, c_dot + w x q_i + s_dot q_i = 0 for all i forces c_dot = 0 (sum over i),
# then s_dot |q_i|^2 = 0 and w x q_i = 0. So rank J = d + 1 (scale, if some q_i != 0) + the
# rotation directions not parallel to every q_i: planar 2 (one drone) or 4; spatial 3 (one
# drone), 6 (collinear, incl. n = 2: the spin about the line is invisible) or 7.
RANK_CASES = [
    pytest.param(Template.polygon(1), 2, id="planar-single"),
    pytest.param(Template.line(2), 4, id="planar-pair"),
    pytest.param(Template.line(5), 4, id="planar-line"),
    pytest.param(Template.polygon(3), 4, id="planar-triangle"),
    pytest.param(Template.line(1, dim=3), 3, id="spatial-single"),
    pytest.param(Template.line(2, dim=3), 6, id="spatial-pair"),
    pytest.param(Template.line(5, dim=3), 6, id="spatial-line"),
    pytest.param(Template.polygon(3, dim=3), 7, id="spatial-triangle"),
    pytest.param(Template.sphere(8), 7, id="spatial-sphere"),
]


def assert_projector_properties(jac, rank):
    pinv = jacobian_pinv(jac)
    null = nullspace_projector(jac)
    assert pinv.rank == rank
    np.testing.assert_allclose(jac @ pinv.matrix @ jac, jac, atol=1e-10)  # Penrose condition
    np.testing.assert_allclose(null, null.T, atol=1e-13)
    np.testing.assert_allclose(null @ null, null, atol=1e-12)
    assert np.trace(null) == pytest.approx(jac.shape[0] - rank)
    np.testing.assert_allclose(null @ jac, 0.0, atol=1e-12)
    v = np.random.default_rng(0).normal(size=(jac.shape[0], 5))
    np.testing.assert_allclose(pinv.matrix @ null @ v, 0.0, atol=1e-12)


@pytest.mark.parametrize(("tpl", "rank"), RANK_CASES)
def test_pinv_rank_and_projector_of_structured_templates(tpl, rank):
    state = random_state(np.random.default_rng(tpl.n), tpl.dim)
    assert_projector_properties(formation_jacobian(tpl, state), rank)


@given(seeds, st.integers(3, 8), dims)
def test_pinv_rank_and_projector_of_random_templates(seed, n, dim):
    tpl, state, _ = case(seed, n, dim)
    assert_projector_properties(formation_jacobian(tpl, state), velocity_size(dim))


def test_pinv_of_full_rank_jacobian_is_the_normal_equation_inverse():
    tpl, state, _ = case(7, 5, 3)
    jac = formation_jacobian(tpl, state)
    expected = np.linalg.solve(jac.T @ jac, jac.T)  # (J^T J)^{-1} J^T, full column rank
    np.testing.assert_allclose(jacobian_pinv(jac).matrix, expected, atol=1e-10)


ISOTROPIC = [
    Template.polygon(6, radius=1.2),
    Template.polygon(3),
    Template.centred([[s0, s1, s2] for s0 in (-1, 1) for s1 in (-1, 1) for s2 in (-1, 1)])[0],
]


@pytest.mark.parametrize("tpl", ISOTROPIC, ids=lambda t: f"{t.n}x{t.dim}")
@pytest.mark.parametrize("seed", range(3))
def test_fit_of_a_mirrored_start_falls_back_instead_of_failing(tpl: Template, seed: int) -> None:
    """A reflection of an isotropic template, permuted: no proper rotation with s > 0 fits it (such
    starts were rejected as 'all drones coincide'); the fit says so and falls back."""
    rng = np.random.default_rng(seed)
    mirror = np.diag([-1.0] + [1.0] * (tpl.dim - 1))
    positions = 3.0 + 2.0 * tpl.offsets[rng.permutation(tpl.n)] @ mirror.T
    positions = positions if seed else 3.0 + 2.0 * tpl.offsets @ mirror.T  # seed 0: the exact mirror
    fit = fit_formation(tpl, positions)
    spread = np.sqrt(((positions - positions.mean(0)) ** 2).sum() / (tpl.offsets**2).sum())
    assert fit.state.scale > 0 and np.isfinite(fit.residual_rms_m)
    np.testing.assert_allclose(fit.state.centroid_m, positions.mean(0), atol=1e-12)
    if not fit.scale_identifiable:
        assert fit.state.scale == pytest.approx(spread)
    if seed == 0:  # planar: s = sv1 - sv2 = 0; spatial: s = sv1 + sv2 - sv3 = 1/3 of the mirror's
        assert fit.scale_identifiable == (tpl.dim == 3)
    proper = fit_formation(tpl, 3.0 + 2.0 * tpl.offsets)
    assert proper.scale_identifiable and proper.state.scale == pytest.approx(2.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_fit_of_a_mirrored_random_template_has_a_positive_scale(dim: int) -> None:
    rng = np.random.default_rng(dim)
    for _ in range(50):
        tpl = Template.centred(rng.normal(size=(int(rng.integers(2, 12)), dim)))[0]
        positions = tpl.offsets[rng.permutation(tpl.n)] * np.r_[-1.0, np.ones(dim - 1)]
        assert fit_formation(tpl, positions).state.scale > 0


def test_fit_keeps_the_coincide_message_for_zero_spread() -> None:
    with pytest.raises(ValidationError, match="all drones coincide"):
        fit_formation(Template.polygon(4), np.full((4, 2), 2.5))


def _bent_line_jacobian(eps: float) -> Array:
    """J of a spatial line of 5 drones bent by ``eps`` [m] in y (eps = 0: rank 6, the turn about
    the line is invisible; its singular value grows linearly with eps)."""
    x = np.linspace(-1.0, 1.0, 5)
    offsets = np.column_stack([x, eps * (x**2 - (x**2).mean()), np.zeros(5)])
    return formation_jacobian(Template.centred(offsets)[0], FormationState.from_param(np.zeros(3)))


@pytest.mark.parametrize("factor", [0.3, 0.9, 0.99, 1.01, 1.1, 3.0])
def test_projected_motion_keeps_the_formation_velocity_near_the_rank_threshold(factor: float) -> None:
    """``J^+ N u = 0`` while the smallest singular value of J sits at ``factor`` x the cut
    ``PINV_RTOL * sigma_max`` of the pseudo-inverse, on either side of it: the drone velocities
    ``J J^+ N u`` and the centroid, scale and well-seen rotation rates stay at roundoff; only the
    rate about the weakest direction (the turn about the nearly straight line) carries roundoff
    amplified by ``sigma_max / sigma_min`` (at most ``1 / PINV_RTOL``), as any pseudo-inverse does."""
    s = np.linalg.svd(_bent_line_jacobian(1e-6), compute_uv=False)
    jac = _bent_line_jacobian(1e-6 * factor * PINV_RTOL * s[0] / s[-1])
    s = np.linalg.svd(jac, compute_uv=False)
    assert s[-1] / (PINV_RTOL * s[0]) == pytest.approx(factor, rel=1e-3)
    pinv, proj = jacobian_pinv(jac), nullspace_projector(jac)
    u = np.random.default_rng(7).normal(size=(jac.shape[0], 20))
    xi_dot = pinv.matrix @ proj @ u  # rows: c_dot (3), omega (3; omega_x about the line), s_dot
    eps = np.finfo(float).eps * np.abs(u).max()
    assert np.abs(jac @ xi_dot).max() <= 100 * eps
    assert np.abs(np.delete(xi_dot, 3, axis=0)).max() <= 100 * eps
    assert np.abs(xi_dot[3]).max() <= 100 * eps * s[0] / s[-1]
    assert pinv.rank == (7 if factor > 1 else 6)
