"""Keyframe missions: keyframes hit exactly, limits held, derivatives, switches, bad input, scenarios."""

from __future__ import annotations

import itertools
import tomllib
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mpcform.errors import MPCFormError, ScenarioError, ValidationError
from mpcform.formation.kinematics import drone_velocities
from mpcform.formation.rotation import rotation_matrix
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.reference.keyframes import Keyframe, MissionLimits, SpeedBudget
from mpcform.reference.mission import CAPTWarning, MissionReference
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import load_scenario, scenario_from_dict

ROOT = Path(__file__).resolve().parents[2]
H = 1e-6
TRIANGLE_6 = Template.centred(
    [[0.0, np.sqrt(3.0)], [-0.5, np.sqrt(3.0) / 2], [0.5, np.sqrt(3.0) / 2], [-1, 0], [0, 0], [1, 0]]
)[0]
LIMITS = MissionLimits(
    max_velocity={"centroid": 1.5, "rotation": 0.7, "scale": 0.4, "blend": 0.5},
    max_acceleration={"centroid": 1.0, "rotation": 0.9, "scale": 0.3, "blend": 0.6},
    max_jerk={"centroid": 2.0, "rotation": 1.1, "scale": 0.5, "blend": 0.8},
)


def rot_param(dim: int, angle: float, axis: tuple[float, ...] = (0.0, 0.0, 1.0)) -> Any:
    return angle if dim == 2 else angle * np.array(axis) / np.linalg.norm(axis)


def mission(dim: int, **kw: Any) -> MissionReference:
    """Translate, turn, scale, switch template (while moving and turning), hold, move on."""
    tpl = TRIANGLE_6 if dim == 2 else Template.sphere(6)
    line = Template.line(6, 1.0, dim)
    start = FormationState.from_param(np.zeros(dim), rot_param(dim, 0.0), 1.5)
    frames = [
        Keyframe(centroid_m=np.r_[6.0, 2.0, np.zeros(dim - 2)], hold_s=0.5),
        Keyframe(rotation=rot_param(dim, 1.2, (1.0, 0.5, 2.0)), scale=2.0),
        Keyframe(centroid_m=np.r_[8.0, -1.0, np.ones(dim - 2)], rotation=rot_param(dim, -0.4), template=line),
        Keyframe(scale=1.0, hold_s=1.0),
    ]
    kw.setdefault("limits", LIMITS)
    return MissionReference(tpl, start, frames, **kw)


def dense(ref: MissionReference, count: int = 3000) -> np.ndarray:
    return np.linspace(0.0, ref.duration_s, count)


# ---- keyframes and clamping -------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_each_segment_ends_exactly_on_its_keyframe(dim: int) -> None:
    ref = mission(dim)
    c, rot, s = ref.start.centroid_m, ref.start.rotation_body_to_world, ref.start.scale
    offsets = ref.template.offsets
    for k, kf in enumerate(ref.keyframes):
        c = c if kf.centroid_m is None else kf.centroid_m
        rot = rot if kf.rotation is None else rotation_matrix(dim, kf.rotation)
        s = s if kf.scale is None else kf.scale
        if kf.template is not None:
            offsets = kf.template.offsets[ref.assignments[k]]
        t = ref.keyframe_times_s[k]
        state = ref.state(t)
        np.testing.assert_array_equal(state.centroid_m, c)
        np.testing.assert_array_equal(state.rotation_body_to_world, rot)
        assert state.scale == s
        pos, vel = ref.targets(t)
        np.testing.assert_allclose(pos[0], c + s * offsets @ rot.T, atol=1e-12)
        np.testing.assert_array_equal(vel, 0.0)
        np.testing.assert_array_equal(ref.acceleration(t), 0.0)
        before, _ = ref.targets(t - 1e-7)  # the move arrives continuously
        np.testing.assert_allclose(before[0], pos[0], atol=1e-6)
    moves = [seg for seg in ref.segments if seg.kind == "move"]
    assert [seg.keyframe for seg in moves] == [0, 1, 2, 3]
    for seg in moves:
        assert seg.end_s == pytest.approx(ref.keyframe_times_s[seg.keyframe], abs=1e-12)
    assert ref.duration_s == pytest.approx(ref.keyframe_times_s[-1] + 1.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_times_are_clamped_to_the_mission(dim: int) -> None:
    ref = mission(dim)
    for got, want in zip(ref.targets([-5.0, -1e-3]), ref.targets([0.0, 0.0]), strict=True):
        np.testing.assert_array_equal(got, want)
    for got, want in zip(ref.targets([ref.duration_s + 7.0]), ref.targets([ref.duration_s]), strict=True):
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(ref.velocity(1e6), 0.0)
    with pytest.raises(ValidationError, match="times"):
        ref.targets([np.nan])


# ---- limits ------------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_velocities_accelerations_and_jerk_respect_the_explicit_limits(dim: int) -> None:
    ref = mission(dim)
    t = dense(ref, 6000)
    pr = ref.profile(t)
    h = 1e-4
    pr_h = ref.profile(t + h)
    rows = {
        "centroid": (
            pr.centroid_velocity_mps,
            pr.centroid_acceleration_mps2,
            pr_h.centroid_acceleration_mps2,
        ),
        "rotation": (
            pr.omega_world_radps,
            pr.angular_acceleration_world_radps2,
            pr_h.angular_acceleration_world_radps2,
        ),
        "scale": (
            pr.scale_rate_per_s[:, None],
            pr.scale_acceleration_per_s2[:, None],
            pr_h.scale_acceleration_per_s2[:, None],
        ),
        "blend": (pr.blend_rate_per_s[:, None], None, None),
    }
    for group, (vel, acc, acc_h) in rows.items():
        assert np.linalg.norm(vel, axis=1).max() <= LIMITS.max_velocity[group] * (1 + 1e-9), group
        if acc is None:
            continue
        assert np.linalg.norm(acc, axis=1).max() <= LIMITS.max_acceleration[group] * (1 + 1e-9), group
        inside = t + h <= ref.duration_s
        jerk = np.linalg.norm(acc_h - acc, axis=1)[inside] / h
        assert jerk.max() <= LIMITS.max_jerk[group] * (1 + 1e-6), group
    # the blend DOF: its acceleration and jerk from the DOF samples
    _, _, v, a = ref.dofs(t)
    _, _, _, a_h = ref.dofs(t + h)
    assert np.abs(a[:, -1]).max() <= LIMITS.max_acceleration["blend"] * (1 + 1e-9)
    assert (np.abs(a_h[:, -1] - a[:, -1]) / h).max() <= LIMITS.max_jerk["blend"] * (1 + 1e-6)
    assert np.abs(v[:, -1]).max() > 0.0


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("fraction", [0.8, 0.5])
def test_derived_limits_keep_every_drone_below_the_fraction_of_v_max(dim: int, fraction: float) -> None:
    budget = SpeedBudget(3.0, fraction)
    ref = mission(dim, limits=None, budget=budget)
    t = dense(ref, 8000)
    pr = ref.profile(t)
    _, vel = ref.targets(t)
    bound = fraction * 3.0
    assert np.linalg.norm(vel, axis=-1).max() <= bound * (1 + 1e-9)
    # the triangle bound ||c_dot|| + |s_dot| |rho| + s |w| |rho| + s |alpha_dot| |r' - r| as well
    rho = np.linalg.norm(pr.offsets_m, axis=-1)
    swing = np.linalg.norm(pr.offsets_rate_mps, axis=-1)
    total = (
        np.linalg.norm(pr.centroid_velocity_mps, axis=1)[:, None]
        + (np.abs(pr.scale_rate_per_s) + pr.scale * np.linalg.norm(pr.omega_world_radps, axis=1))[:, None]
        * rho
        + pr.scale[:, None] * swing
    )
    assert total.max() <= bound * (1 + 1e-9)
    # and the bound is reached (phase synchronisation makes it exact): a long pure translation
    frames = [Keyframe(centroid_m=np.full(dim, 30.0))]
    far = MissionReference(ref.template, ref.start, frames, budget=budget)
    assert np.linalg.norm(far.targets(dense(far))[1], axis=-1).max() == pytest.approx(bound, rel=1e-9)


# ---- derivatives -------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_angular_velocity_matches_finite_differences_of_the_rotation(dim: int) -> None:
    ref = mission(dim)
    t = np.linspace(0.01, ref.duration_s - 0.01, 400)
    pr = ref.profile(t)
    rot_dot = (ref.profile(t + H).rotation_body_to_world - ref.profile(t - H).rotation_body_to_world) / (
        2 * H
    )
    w_hat = rot_dot @ np.transpose(pr.rotation_body_to_world, (0, 2, 1))  # R_dot R^T = hat(w_world)
    if dim == 2:
        np.testing.assert_allclose(w_hat[:, 1, 0], pr.omega_world_radps[:, 0], atol=1e-7)
    else:
        vee = np.stack([w_hat[:, 2, 1], w_hat[:, 0, 2], w_hat[:, 1, 0]], axis=1)
        np.testing.assert_allclose(vee, pr.omega_world_radps, atol=1e-7)
    w_dot = (ref.profile(t + H).omega_world_radps - ref.profile(t - H).omega_world_radps) / (2 * H)
    np.testing.assert_allclose(w_dot, pr.angular_acceleration_world_radps2, atol=1e-6)
    assert np.abs(pr.omega_world_radps).max() > 0.1


@pytest.mark.parametrize("dim", [2, 3])
def test_target_velocities_match_finite_differences_including_blends(dim: int) -> None:
    ref = mission(dim, limits=None, budget=SpeedBudget(2.0))
    t = np.linspace(0.0, ref.duration_s, 600)
    pos, vel = ref.targets(t)
    fd = (ref.targets(t + H)[0] - ref.targets(t - H)[0]) / (2 * H)
    inside = (t > H) & (t < ref.duration_s - H)
    np.testing.assert_allclose(vel[inside], fd[inside], atol=1e-7)
    blending = np.abs(ref.profile(t).blend_rate_per_s) > 1e-3
    assert blending.any()
    # outside blends the targets are the formation's: p_dot* = J xi_dot_d (eq. 14 feedforward)
    for j in np.flatnonzero(~blending)[::40]:
        state, offsets = ref.state(t[j]), ref.profile(t[j : j + 1]).offsets_m[0]
        tpl = Template(offsets - offsets.mean(axis=0))
        np.testing.assert_allclose(vel[j], drone_velocities(tpl, state, ref.velocity(t[j])), atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_formation_acceleration_matches_finite_differences(dim: int) -> None:
    ref = mission(dim)
    for t in np.linspace(0.05, ref.duration_s - 0.05, 37):
        fd = (ref.velocity(t + H) - ref.velocity(t - H)) / (2 * H)
        np.testing.assert_allclose(ref.acceleration(t), fd, atol=1e-6)


# ---- switching, degenerate segments ------------------------------------------------------------
def test_switch_assignment_is_optimal_and_capt_is_checked() -> None:
    rng = np.random.default_rng(3)
    tpl = Template.centred(rng.uniform(-2, 2, (5, 2)))[0]
    new = Template.centred(rng.uniform(-2, 2, (5, 2)))[0]
    start = FormationState.from_param([0.0, 0.0])
    with pytest.warns(CAPTWarning, match=r"reference\.keyframes\[0\]\.template: .*CAPT"):
        ref = MissionReference(tpl, start, [Keyframe(template=new)], budget=SpeedBudget(2.0), d_min_m=5.0)
    assert len(ref.warnings) == 1 and "sqrt(2) * d_min" in ref.warnings[0]
    perm = ref.assignments[0]
    assert perm is not None
    cost = lambda p: ((tpl.offsets - new.offsets[list(p)]) ** 2).sum()  # noqa: E731
    assert cost(perm) == pytest.approx(min(cost(p) for p in itertools.permutations(range(5))))
    with warnings.catch_warnings():
        warnings.simplefilter("error", CAPTWarning)
        line = Template.line(6, 1.0)
        ok = MissionReference(TRIANGLE_6, start, [{"template": line}], budget=SpeedBudget(2.0), d_min_m=0.5)
    assert ok.warnings == () and ok.assignments[0] is not None
    end = ok.targets(ok.duration_s)[0][0]
    np.testing.assert_allclose(np.sort(end[:, 0]), line.offsets[:, 0], atol=1e-12)


def test_zero_length_segments_and_tiny_moves() -> None:
    start = FormationState.from_param([1.0, 2.0], 0.5, 1.5)
    tpl = Template.polygon(4)
    same = [Keyframe(), Keyframe(centroid_m=[1.0, 2.0], rotation=0.5, scale=1.5), Keyframe(scale=1.5 + 1e-15)]
    ref = MissionReference(tpl, start, same, budget=SpeedBudget(1.0))
    assert ref.duration_s == 0.0 and ref.segments == ()
    pos, vel = ref.targets([0.0, 3.0])
    np.testing.assert_allclose(pos[1], pos[0])
    np.testing.assert_array_equal(vel, 0.0)
    held = MissionReference(tpl, start, [Keyframe(hold_s=2.0)], budget=SpeedBudget(1.0))
    assert held.duration_s == 2.0 and [s.kind for s in held.segments] == ["hold"]


# ---- robustness ----------------------------------------------------------------------------------
finite_or_not = st.one_of(
    st.floats(-50.0, 50.0), st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300, 1e-300, 0.0])
)
keyframe_tables = st.fixed_dictionaries(
    {},
    optional={
        "centroid_m": st.lists(finite_or_not, min_size=1, max_size=4),
        "rotation": st.one_of(finite_or_not, st.lists(finite_or_not, min_size=1, max_size=4)),
        "scale": st.one_of(st.floats(-1.0, 5.0), st.sampled_from([np.nan, 1e-300, 1e300])),
        "hold_s": st.one_of(st.floats(-1.0, 3.0), st.just(np.inf)),
        "template": st.sampled_from(
            [Template.line(4, 0.5, 2), Template.line(3, 1.0, 2), Template.line(4, 1.0, 3)]
        ),
    },
)


@given(
    frames=st.lists(keyframe_tables, min_size=1, max_size=4),
    dim=st.sampled_from([2, 3]),
    fraction=st.one_of(st.floats(-0.5, 1.5), st.just(np.nan)),
    explicit=st.booleans(),
)
def test_random_keyframe_sequences_never_give_nan_or_foreign_errors(
    frames: list[dict[str, Any]], dim: int, fraction: float, explicit: bool
) -> None:
    tpl = Template.polygon(4, 1.0, dim)
    start = FormationState.from_param(np.zeros(dim))
    try:
        budget = SpeedBudget(2.0, fraction)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CAPTWarning)
            warnings.simplefilter("error", RuntimeWarning)
            ref = MissionReference(
                tpl, start, frames, limits=LIMITS if explicit else None, budget=budget, d_min_m=0.3
            )
            t = np.r_[-1.0, np.linspace(0.0, ref.duration_s, 50), ref.duration_s + 1.0]
            pos, vel = ref.targets(t)
    except MPCFormError:
        return
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(vel))
    assert np.all(np.isfinite(ref.profile(t).centroid_acceleration_mps2))


TPL3, START3 = Template.sphere(5), FormationState.from_param([0.0, 0.0, 0.0])


@pytest.mark.parametrize(
    ("frames", "kw", "field"),
    [
        ([{"centroid_m": [1.0, 2.0]}], {}, r"reference\.keyframes\[0\]\.centroid"),
        ([{}, {"centroid_m": [1.0, np.nan, 0.0]}], {}, r"reference\.keyframes\[1\]\.centroid"),
        ([{}, {}, {"rotation": 0.3}], {}, r"reference\.keyframes\[2\]\.rotation"),
        ([{"rotation": [0.0, np.inf, 0.0]}], {}, r"reference\.keyframes\[0\]\.rotation"),
        ([{"scale": -1.0}], {}, r"reference\.keyframes\[0\]\.scale"),
        ([{"scale": 0.0}], {}, r"reference\.keyframes\[0\]\.scale"),
        ([{"hold_s": -2.0}], {}, r"reference\.keyframes\[0\]\.hold"),
        ([{"hold_s": np.nan}], {}, r"reference\.keyframes\[0\]\.hold"),
        ([{"template": Template.line(4, 1.0, 3)}], {}, r"reference\.keyframes\[0\]\.template"),
        ([{"template": Template.line(5, 1.0, 2)}], {}, r"reference\.keyframes\[0\]\.template"),
        ([{"spin": 1.0}], {}, r"reference\.keyframes\[0\]"),
        ([{"centroid_m": [1e300, 0.0, 0.0]}], {}, r"reference\.keyframes\[0\]\.centroid"),
        ([], {}, r"reference\.keyframes"),
        ([{"scale": 2.0}], {"budget": None}, r"reference\.max_velocity\.scale"),
        ([{"scale": 2.0}], {"limits": None, "budget": None}, r"reference: give explicit limits"),
        ([{}], {"budget": "fast"}, r"reference\.budget"),
    ],
)
def test_bad_input_names_the_keyframe_field(
    frames: list[dict[str, Any]], kw: dict[str, Any], field: str
) -> None:
    args: dict[str, Any] = {"limits": MissionLimits({"centroid": 1.0}, {"centroid": 1.0}, {"centroid": 1.0})}
    args["budget"] = SpeedBudget(2.0)
    args.update(kw)
    with pytest.raises(ValidationError, match=field):
        MissionReference(TPL3, START3, frames, **args)


# ---- scenarios ------------------------------------------------------------------------------------
def test_mission_scenario_loads_and_reaches_eq19_with_scale_2() -> None:
    scenario = load_scenario(ROOT / "scenarios" / "worked_example_ruckig.toml")
    ref = scenario.reference
    assert isinstance(ref, MissionReference) and ref.budget is not None
    assert ref.budget.fraction == 0.8 and ref.budget.v_max_mps == 3.0
    assert ref.state(ref.duration_s).scale == 2.0
    sim = run_scenario(scenario).simulation
    root3 = np.sqrt(3.0)
    eq19 = np.array([[5.0 + 2.0, 5.0], [5.0 - 1.0, 5.0 + root3], [5.0 - 1.0, 5.0 - root3]])
    assert np.linalg.norm(sim.positions_m[-1] - eq19, axis=1).max() < 1e-3
    assert np.linalg.norm(sim.commands_mps, axis=-1).max() < 3.0


def test_template_switch_scenario_builds_the_switch() -> None:
    scenario = load_scenario(ROOT / "scenarios" / "mission_template_switch.toml")
    ref = scenario.reference
    assert isinstance(ref, MissionReference) and ref.warnings == ()
    assert ref.assignments[1] is not None and sorted(ref.assignments[1]) == list(range(6))


def worked_mission(**reference: Any) -> dict[str, Any]:
    data = tomllib.loads((ROOT / "scenarios" / "worked_example_ruckig.toml").read_text())
    data["reference"] = {"kind": "mission", "keyframes": [{"scale": 2.0}], **reference}
    return data


@pytest.mark.parametrize(
    ("reference", "limits", "field"),
    [
        ({"keyframes": [{"scal": 2.0}]}, None, "reference.keyframes[0].scal"),
        ({"keyframes": [{"centroid": [1.0]}]}, None, "reference.keyframes[0].centroid"),
        ({"keyframes": []}, None, "reference.keyframes"),
        ({"keyframes": [{"template": {"shape": "line", "n": 4}}]}, None, "reference.keyframes[0].template"),
        ({"keyframes": [{"template": {"shape": "line"}}]}, None, "reference.keyframes[0].template.n"),
        (
            {"keyframes": [{"template": {"shape": "line", "n": 3, "spacing": -1.0}}]},
            None,
            "reference.keyframes[0].template.spacing",
        ),
        ({"rate": 1.0}, None, "reference.rate"),
        ({"scale": 2.0}, None, "reference.scale"),
        ({"speed_fraction": 1.5}, None, "reference.speed_fraction"),
        ({"speed_fraction": 0.5}, {}, "reference.speed_fraction"),
        ({"max_velocity": {"spin": 1.0}}, None, "reference.max_velocity.spin"),
        ({"max_velocity": 1.0}, None, "reference.max_velocity"),
        ({}, {}, "reference.max_velocity.scale"),
    ],
)
def test_mission_scenario_errors_name_the_key(
    reference: dict[str, Any], limits: dict[str, Any] | None, field: str
) -> None:
    data = worked_mission(**reference)
    if limits is not None:
        data["limits"] = limits
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(data)
    assert err.value.field == field


def test_mission_scenario_explicit_limits_and_acceleration_budget() -> None:
    data = worked_mission(max_velocity={"scale": 0.25}, drone_acceleration=0.5, drone_jerk=1.0)
    data["limits"]["a_max"] = 10.0
    ref = scenario_from_dict(data).reference
    assert isinstance(ref, MissionReference) and ref.budget is not None
    assert ref.budget.budgets == pytest.approx((2.4, 0.5, 1.0))
    assert np.abs(ref.profile(dense(ref)).scale_rate_per_s).max() == pytest.approx(0.25, rel=1e-9)
    data = worked_mission()
    data["limits"]["a_max"] = 2.0  # default acceleration budget: speed_fraction * a_max
    ref = scenario_from_dict(data).reference
    assert isinstance(ref, MissionReference) and ref.budget is not None
    assert ref.budget.budgets[1] == pytest.approx(1.6)
