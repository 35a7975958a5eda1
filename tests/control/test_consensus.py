"""Scale consensus (eq. 20): convergence, centroid drift (closed form), stability, network effects."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

from mpcform import (
    ConsensusController,
    ConsensusSettings,
    ConstantReference,
    ExponentialReference,
    FormationState,
    Graph,
    Network,
    Template,
    ValidationError,
    simulate,
)
from mpcform.cli.main import main
from mpcform.control.consensus import relative_position_error
from mpcform.control.graph import DENSE_EIG_MAX_N, DisconnectedGraphWarning
from mpcform.formation.kinematics import forward_kinematics
from mpcform.reference.base import Profile, Reference
from mpcform.run.runner import run_scenario
from mpcform.scenario.build import build_controller
from mpcform.scenario.load import load_scenario

ROOT = Path(__file__).resolve().parents[2]
RING = ROOT / "scenarios" / "consensus_ring.toml"
LOSSY = ROOT / "scenarios" / "consensus_ring_lossy.toml"
LAWS = ("eq20", "centroid_preserving")


def ring_doubling(n: int = 8) -> tuple[Template, ConstantReference]:
    """A ring of n at scale 1 about the origin, commanded to scale 2 (a step for the leader)."""
    tpl = Template.polygon(n)
    return tpl, ConstantReference(tpl, FormationState.from_param([0.0, 0.0], 0.0, 2.0))


def fast(law: str, **kw: object) -> ConsensusSettings:
    return ConsensusSettings(gain_per_s=2.0, gamma_per_s=3.0, leader_gain_per_s=3.0, law=law, **kw)  # type: ignore[arg-type]


# ---- convergence ------------------------------------------------------------------------------
@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("kind", ["ring", "path", "complete", "k_nearest", "disk"])
def test_planar_estimates_and_relative_positions_converge(law: str, kind: str) -> None:
    tpl = Template.polygon(8)
    goal = FormationState.from_param([3.0, -1.0], 0.6, 2.0)  # R(0.6) is the shared frame
    ref = ConstantReference(tpl, goal)
    graph = {
        "ring": Graph.ring(8),
        "path": Graph.path(8),
        "complete": Graph.complete(8),
        "k_nearest": Graph.k_nearest(tpl.offsets, 3),
        "disk": Graph.disk(tpl.offsets, 1.5),
    }[kind]
    ctrl = ConsensusController(ref, graph, 0.05, fast(law, leaders=(0, 4)))
    start = forward_kinematics(tpl, FormationState.from_param([0.0, 0.0], 0.0, 1.0))
    sim = simulate(ctrl, start, 60.0)
    np.testing.assert_allclose(ctrl.scale_estimates, 2.0, atol=1e-6)
    assert relative_position_error(tpl, sim.positions_m[-1], 2.0, goal.rotation_body_to_world) < 1e-5
    assert all(info.mode == "law" and info.saturated == 0 for info in sim.infos)


@pytest.mark.parametrize("law", LAWS)
def test_spatial_formation_turns_into_the_shared_frame_and_scales(law: str) -> None:
    tpl = Template.sphere(6)
    goal = FormationState.from_param([0.0, 0.0, 2.0], [0.3, -0.5, 0.8], 1.5)
    ref = ConstantReference(tpl, goal)
    ctrl = ConsensusController(ref, Graph.complete(6), 0.05, fast(law))
    start = forward_kinematics(tpl, FormationState.from_param([0.0, 0.0, 2.0], None, 1.0))
    sim = simulate(ctrl, start, 40.0)
    np.testing.assert_allclose(ctrl.scale_estimates, 1.5, atol=1e-6)
    assert relative_position_error(tpl, sim.positions_m[-1], 1.5, goal.rotation_body_to_world) < 1e-6


class RampReference(Reference):
    """A scale ramp 1 -> 2 over 5 s then a hold (any reference works, e.g. a mission)."""

    def __init__(self, template: Template) -> None:
        self.template = template

    def profile(self, times_s: np.ndarray) -> Profile:
        t = np.clip(times_s, 0.0, None)
        k = t.shape[0]
        scale = 1.0 + np.minimum(t, 5.0) / 5.0
        rate = np.where(t < 5.0, 0.2, 0.0)
        eye = np.broadcast_to(np.eye(2), (k, 2, 2))
        return Profile(np.zeros((k, 2)), eye, scale, np.zeros((k, 2)), np.zeros((k, 1)), rate)


def test_leader_follows_any_reference_scale() -> None:
    tpl = Template.polygon(8)
    ctrl = ConsensusController(RampReference(tpl), Graph.ring(8), 0.05, fast("centroid_preserving"))
    ctrl.reset(0.0, tpl.offsets)
    p = tpl.offsets.copy()
    leader = []
    for j in range(1200):
        p = p + 0.05 * ctrl.step(0.05 * j, p).command_mps
        leader.append(ctrl.scale_estimates[0])
    assert 1.0 < leader[40] < 1.45  # follows the ramp (with a lag) at t = 2 s
    np.testing.assert_allclose(ctrl.scale_estimates, 2.0, atol=1e-4)
    assert relative_position_error(tpl, p, 2.0, np.eye(2)) < 1e-3


def test_exponential_reference_ring_and_initial_estimates() -> None:
    tpl = Template.polygon(8)
    start = FormationState.from_param([0.0, 0.0], 0.0, 1.3)
    ref = ExponentialReference(tpl, start, FormationState.from_param([0.0, 0.0], 0.0, 2.0), 1.0)
    ctrl = ConsensusController(ref, Graph.ring(8), 0.05, fast("eq20"))
    ctrl.reset(0.0, forward_kinematics(tpl, start))
    np.testing.assert_allclose(ctrl.scale_estimates, 1.3)  # the best-fit scale of the start
    other = ConsensusController(ref, Graph.ring(8), 0.05, fast("eq20", initial_scale=1.0))
    other.reset(0.0, forward_kinematics(tpl, start))
    np.testing.assert_allclose(other.scale_estimates, 1.0)
    sim = simulate(ctrl, forward_kinematics(tpl, start), 60.0)
    np.testing.assert_allclose(ctrl.scale_estimates, 2.0, atol=1e-4)
    assert relative_position_error(tpl, sim.positions_m[-1], 2.0, np.eye(2)) < 1e-3


# ---- the centroid: eq. 20 as printed lets it drift, the centroid-preserving law keeps it ----
def test_eq20_as_printed_drifts_as_the_closed_form_predicts() -> None:
    """Ring of 8 doubling its scale, k = gamma = lambda = 1: the centroid moves about 0.9 m.

    Summing eq. 20 over the drones, ``c_{j+1} = c_j + dt (k/n) sum_i s_hat_i R (L r)_i``, and the
    estimate error obeys ``z_{j+1} = (I - dt M) z_j``, ``M = gamma L + lambda E``. So after J
    steps ``c_J = (k/n) (L r)^T M^{-1} (I - (I - dt M)^J) z_0`` exactly.
    """
    tpl, ref = ring_doubling()
    graph, dt, steps = Graph.ring(8), 0.05, 800
    ctrl = ConsensusController(ref, graph, dt, ConsensusSettings(law="eq20"))
    sim = simulate(ctrl, tpl.offsets, dt * steps)
    lap = graph.laplacian.toarray()
    m = lap + np.diag([1.0] + [0.0] * 7)
    z0 = np.full(8, 1.0 - 2.0)
    summed = np.linalg.solve(m, (np.eye(8) - np.linalg.matrix_power(np.eye(8) - dt * m, steps)) @ z0)
    predicted = (lap @ tpl.offsets).T @ summed / 8
    drift = sim.positions_m[-1].mean(axis=0)
    np.testing.assert_allclose(drift, predicted, atol=1e-12)
    assert 0.9 < np.linalg.norm(drift) < 0.95  # 0.936 m after 40 s
    asymptote = np.linalg.norm((lap @ tpl.offsets).T @ np.linalg.solve(m, z0) / 8)
    assert asymptote == pytest.approx(1.0, abs=0.01)  # and stays displaced: 1.0 m in the limit
    # the shape and scale are still right: only the centroid is lost
    assert relative_position_error(tpl, sim.positions_m[-1], 2.0, np.eye(2)) < 0.15


def test_centroid_preserving_variant_keeps_the_centroid_to_machine_precision() -> None:
    tpl, ref = ring_doubling()
    ctrl = ConsensusController(ref, Graph.ring(8), 0.05, ConsensusSettings(law="centroid_preserving"))
    sim = simulate(ctrl, tpl.offsets, 40.0)
    assert np.abs(sim.positions_m.mean(axis=1)).max() < 1e-13
    assert np.abs(sim.commands_mps.sum(axis=1)).max() < 1e-13  # sum_i u_i = 0 at every step


def test_both_laws_agree_at_consensus() -> None:
    tpl, ref = ring_doubling()
    p = np.random.default_rng(1).normal(size=(8, 2))
    steps = []
    for law in LAWS:
        ctrl = ConsensusController(ref, Graph.ring(8), 0.05, ConsensusSettings(law=law, initial_scale=2.0))
        ctrl.reset(0.0, p)
        steps.append(ctrl.step(0.0, p).command_mps)
    np.testing.assert_allclose(steps[0], steps[1], atol=1e-14)


# ---- what cannot work is reported ------------------------------------------------------------
def test_complete_graph_of_50_at_dt_005_is_rejected_with_the_reason() -> None:
    tpl = Template.polygon(50, radius=5.0)
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0], 0.0, 1.0))
    with pytest.raises(ValidationError) as err:
        ConsensusController(ref, Graph.complete(50), 0.05)
    msg = str(err.value)
    assert err.value.field == "controller.gain"
    assert "= 2.5 must be < 2" in msg and "lambda_max = 50" in msg and "diverges" in msg
    assert "below 0.8 /s" in msg and "dt below 0.04 s" in msg
    # just inside the bound it converges (the check is not conservative)
    settings = ConsensusSettings(gamma_per_s=0.5, leader_gain_per_s=0.5, initial_scale=1.0)
    ctrl = ConsensusController(ref, Graph.complete(50), 0.039, settings)
    start = tpl.offsets + np.random.default_rng(2).normal(0.0, 0.1, (50, 2))
    sim = simulate(ctrl, start, 0.039 * 400)
    assert relative_position_error(tpl, sim.positions_m[-1], 1.0, np.eye(2)) < 1e-6


def test_unstable_gamma_is_rejected() -> None:
    tpl, ref = ring_doubling()
    with pytest.raises(ValidationError) as err:
        ConsensusController(ref, Graph.ring(8), 0.1, ConsensusSettings(gamma_per_s=5.0))
    assert err.value.field == "controller.gamma" and "gamma L + lambda E" in str(err.value)


def test_disconnected_graph_is_reported_or_run_with_warnings() -> None:
    tpl, ref = ring_doubling()
    split = Graph.from_edges(8, [[0, 1], [1, 2], [2, 3], [4, 5], [5, 6], [6, 7]])
    with pytest.raises(ValidationError) as err:
        ConsensusController(ref, split, 0.05)
    assert err.value.field == "graph.edges"
    assert "2 components {0, 1, 2, 3}, {4, 5, 6, 7}" in str(err.value)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ctrl = ConsensusController(ref, split, 0.05, fast("centroid_preserving"), allow_disconnected=True)
    messages = [str(w.message) for w in caught if issubclass(w.category, DisconnectedGraphWarning)]
    assert any("running anyway" in m for m in messages)
    assert any("{4, 5, 6, 7} contain no leader" in m for m in messages)
    simulate(ctrl, tpl.offsets, 30.0)
    np.testing.assert_allclose(ctrl.scale_estimates[:4], 2.0, atol=1e-4)  # the leader's component
    np.testing.assert_allclose(ctrl.scale_estimates[4:], 1.0)  # never hears of s*


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"leaders": ()}, "controller.leaders"),
        ({"leaders": (1, 1)}, "controller.leaders"),
        ({"leaders": (-1,)}, "controller.leaders"),
        ({"law": "eq21"}, "controller.law"),
        ({"gamma_per_s": 0.0}, "controller.gamma"),
        ({"leader_gain_per_s": -1.0}, "controller.leader_gain"),
        ({"initial_scale": 0.0}, "controller.initial_scale"),
    ],
)
def test_settings_validation(kwargs: dict[str, object], field: str) -> None:
    with pytest.raises(ValidationError) as err:
        ConsensusSettings(**kwargs)  # type: ignore[arg-type]
    assert err.value.field == field


def test_controller_validation() -> None:
    tpl, ref = ring_doubling()
    with pytest.raises(ValidationError) as err:
        ConsensusController(ref, Graph.ring(8), 0.05, ConsensusSettings(leaders=(8,)))
    assert err.value.field == "controller.leaders" and "[8]" in str(err.value)
    with pytest.raises(ValidationError) as err:
        ConsensusController(ref, Graph.ring(7), 0.05)
    assert err.value.field == "graph"
    bad_networks = [
        ({"delay_steps": -1}, "graph.delay_steps"),
        ({"loss_probability": 1.0}, "graph.loss_probability"),
        ({"relative_positions": "x"}, "graph.relative_positions"),
    ]
    for kw, field in bad_networks:
        with pytest.raises(ValidationError) as err:
            Network(**kw)  # type: ignore[arg-type]
        assert err.value.field == field
    with pytest.raises(ValidationError):
        ConsensusController(ref, Graph.ring(8), 0.05).scale_estimates  # noqa: B018 - before reset


def test_saturation_per_drone() -> None:
    tpl, ref = ring_doubling()
    ctrl = ConsensusController(ref, Graph.ring(8), 0.05, fast("centroid_preserving"), v_max_mps=0.1)
    sim = simulate(ctrl, tpl.offsets, 10.0)
    assert np.linalg.norm(sim.commands_mps, axis=-1).max() <= 0.1 * (1 + 1e-12)
    assert sum(info.saturated for info in sim.infos) > 0


# ---- network effects --------------------------------------------------------------------------
def test_ideal_network_is_the_undelayed_law_and_step_without_reset_starts() -> None:
    tpl, ref = ring_doubling()
    start = tpl.offsets + np.random.default_rng(3).normal(0.0, 0.1, (8, 2))
    runs = [
        simulate(
            ConsensusController(ref, Graph.ring(8), 0.05, fast("eq20"), network=Network(**kw)), start, 5.0
        )
        for kw in ({}, {"relative_positions": "sensed"}, {"seed": 9})
    ]
    for other in runs[1:]:
        np.testing.assert_array_equal(runs[0].positions_m, other.positions_m)
    lazy = ConsensusController(ref, Graph.ring(8), 0.05, fast("eq20"))
    np.testing.assert_array_equal(lazy.step(0.0, start).command_mps, runs[0].commands_mps[0])


@pytest.mark.parametrize("relative_positions", ["communicated", "sensed"])
def test_delay_and_loss_stay_finite_and_converge(relative_positions: str) -> None:
    tpl, ref = ring_doubling()
    net = Network(delay_steps=2, loss_probability=0.2, seed=11, relative_positions=relative_positions)
    ctrl = ConsensusController(ref, Graph.ring(8), 0.05, fast("centroid_preserving"), network=net)
    sim = simulate(ctrl, tpl.offsets, 60.0)
    assert np.all(np.isfinite(sim.positions_m))
    assert ctrl.messages_lost / ctrl.messages_sent == pytest.approx(0.2, abs=0.01)
    final = relative_position_error(tpl, sim.positions_m[-1], 2.0, np.eye(2))
    assert final < 1e-2, final
    np.testing.assert_allclose(ctrl.scale_estimates, 2.0, atol=1e-2)
    # asymmetric (delayed, lost) edge terms break sum u = 0: the centroid wanders, a little
    assert 0.0 < np.abs(sim.positions_m.mean(axis=1)).max() < 0.1


def test_packet_losses_are_seeded() -> None:
    tpl, ref = ring_doubling()

    def final(seed: int) -> np.ndarray:
        net = Network(delay_steps=1, loss_probability=0.3, seed=seed)
        ctrl = ConsensusController(ref, Graph.ring(8), 0.05, fast("eq20"), network=net)
        return simulate(ctrl, tpl.offsets, 5.0).positions_m[-1]

    np.testing.assert_array_equal(final(4), final(4))
    assert not np.array_equal(final(4), final(5))


# ---- scenarios and CLI ------------------------------------------------------------------------
def test_ring_scenario_doubles_after_the_leader() -> None:
    scenario = load_scenario(RING)
    ctrl = build_controller(scenario)
    assert isinstance(ctrl, ConsensusController) and ctrl.settings.law == "centroid_preserving"
    sim = simulate(ctrl, scenario.initial_positions_m, scenario.simulation.duration_s)
    np.testing.assert_allclose(ctrl.scale_estimates, 2.0, atol=1e-3)
    recorded = sim.scale_estimates  # every drone's s_hat_i at every sample
    assert recorded is not None and recorded.shape == (sim.t_s.size, scenario.n) == (801, 8)
    np.testing.assert_array_equal(recorded[-1], ctrl.scale_estimates)
    s_ref_end = scenario.reference.profile(sim.t_s[-1:]).scale[0]  # 2 - e^-40
    np.testing.assert_allclose(recorded[-1], s_ref_end, atol=1e-3)
    assert np.all(recorded[0] == 1.0) and recorded[100, 0] > recorded[100, 4]  # the leader leads
    assert relative_position_error(scenario.template, sim.positions_m[-1], 2.0, np.eye(2)) < 1e-3
    assert np.abs(sim.positions_m.mean(axis=1)).max() < 1e-13


def test_lossy_scenario_reports_its_final_error() -> None:
    scenario = load_scenario(LOSSY)
    assert scenario.network == Network(2, 0.2, scenario.seed, "communicated")
    run = run_scenario(scenario)
    metrics = run.summary["metrics"]
    assert np.all(np.isfinite(run.simulation.positions_m))
    assert 0.0 < metrics["final_tracking_error"] < 0.05 and metrics["speed_violations"] == 0
    short = dataclasses.replace(scenario, simulation=dataclasses.replace(scenario.simulation, duration_s=2.0))
    other_seed = dataclasses.replace(short, network=dataclasses.replace(short.network, seed=1))
    first, second = (run_scenario(s).simulation.positions_m[-1] for s in (short, other_seed))
    assert not np.array_equal(first, second)


def test_cli_runs_consensus_and_explains_a_missing_graph(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ring = tmp_path / "ring.toml"
    ring.write_text(RING.read_text().replace("duration = 40.0", "duration = 1.0"))
    assert main(["run", str(ring), "--out", str(tmp_path / "ring")]) == 0
    assert "consensus" in capsys.readouterr().out
    assert main(["run", str(ring), "--controller", "tracking", "--out", str(tmp_path / "t")]) == 0
    worked = ROOT / "scenarios" / "worked_example.toml"
    assert main(["run", str(worked), "--controller", "consensus", "--out", str(tmp_path / "w")]) == 2
    assert "graph: missing table [graph]" in capsys.readouterr().err


# ---- the stability bounds, by simulation ---------------------------------------------------------
class _Unchecked(ConsensusController):
    """The same controller with the construction-time stability check skipped (to fly past it)."""

    def _check_stability(self) -> tuple[float, float]:
        try:
            return super()._check_stability()
        except ValidationError:
            return float("nan"), float("nan")


def _disagreement(factor_position: float, factor_scale: float, check: bool) -> tuple[float, float]:
    """Final/initial ratio of the position and scale disagreement after 300 steps on a ring of 8
    (lambda_max(L) = 4) whose two discrete loop factors are ``dt k lambda_max(L)`` and
    ``dt lambda_max(gamma L + lambda E)`` = the given values. When the position factor is probed,
    the estimates start at the commanded scale (2), so only the position loop is tested."""
    tpl, ref = ring_doubling(8)
    graph, dt = Graph.ring(8), 0.05
    gamma, leader = 2.0, 1.0
    m = gamma * graph.laplacian.toarray() + np.diag(np.eye(8)[0] * leader)
    scale = factor_scale / (dt * float(np.linalg.eigvalsh(m)[-1]))
    settings = ConsensusSettings(
        gain_per_s=factor_position / (dt * 4.0),
        gamma_per_s=gamma * scale,
        leader_gain_per_s=leader * scale,
        leaders=(0,),
        law="centroid_preserving",
        initial_scale=1.0 if factor_position == 1.0 else 2.0,
    )
    ctrl = (ConsensusController if check else _Unchecked)(ref, graph, dt, settings)
    rng = np.random.default_rng(3)
    start = forward_kinematics(tpl, FormationState.from_param([0.0, 0.0], 0.0, 1.0))
    start = start + 0.05 * rng.normal(size=(8, 2))
    sim = simulate(ctrl, start, 300 * dt)
    s_hat = ctrl.scale_estimates
    s_shape = 2.0 if settings.initial_scale == 2.0 else float(np.clip(s_hat.mean(), 0.0, 4.0))
    first = relative_position_error(tpl, sim.positions_m[0], s_shape, np.eye(2))
    last = relative_position_error(tpl, sim.positions_m[-1], s_shape, np.eye(2))
    return last / first, float(np.abs(s_hat - 2.0).max())  # scale: the estimates start 1.0 from s* = 2


@pytest.mark.parametrize("which", ["position", "scale"])
def test_consensus_converges_just_inside_and_diverges_just_outside_each_bound(which: str) -> None:
    inside = (1.96, 1.0) if which == "position" else (1.0, 1.96)
    outside = (2.04, 1.0) if which == "position" else (1.0, 2.04)
    pos, sc = _disagreement(*inside, check=True)
    assert (pos if which == "position" else sc) < 1e-2
    with pytest.raises(ValidationError, match="gain" if which == "position" else "gamma"):
        _disagreement(*outside, check=True)
    pos, sc = _disagreement(*outside, check=False)  # flown anyway: the refusal was right
    assert (pos if which == "position" else sc) > 10.0


def test_a_large_swarm_never_builds_a_dense_laplacian(monkeypatch: pytest.MonkeyPatch) -> None:
    n = DENSE_EIG_MAX_N + 1
    tpl, ref = ring_doubling(n)
    graph = Graph.ring(n)
    calls = []
    original = type(graph.laplacian).toarray

    def counted(self: object, *args: object, **kwargs: object) -> object:
        calls.append(1)
        return original(self, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(type(graph.laplacian), "toarray", counted)
    ConsensusController(ref, graph, 0.1, ConsensusSettings())  # stable: the bound on lambda_max is used
    assert calls == []  # an (n, n) matrix would be 8 n^2 bytes: 32 GB for 64,000 drones
    ConsensusController(*ring_doubling(8)[1:], Graph.ring(8), 0.1, ConsensusSettings())
    assert calls  # small swarms: the exact eigenvalue
