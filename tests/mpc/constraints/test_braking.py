"""The braking terminal condition: the tail's limits, its shift invariance, and runs that keep d_min."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.mpc.constraints.braking import Braking
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import scenario_from_dict
from mpcform.world.limits import Limits

DT = 0.1


def tail(braking: Braking, u_last: np.ndarray, steps: int) -> np.ndarray:
    """The braking commands after a plan ending in ``u_last``: rho^m u_last, m = 1..steps."""
    return braking.rho ** np.arange(1, steps + 1)[:, None] * u_last


def test_braking_needs_a_finite_a_max_and_v_max() -> None:
    assert Braking.of(DT, Limits(v_max_mps=2.0)) is None
    b = Braking.of(DT, Limits(v_max_mps=2.0, a_max_mps2=0.5))
    assert b is not None and b.rho == pytest.approx(0.975) and b.kappa_s == pytest.approx(2.0 / 0.5 - DT)
    fast = Braking.of(DT, Limits(v_max_mps=0.1, a_max_mps2=5.0))  # stops in one step
    assert fast is not None and fast.rho == 0.0 and fast.kappa_s == 0.0


def test_a_speed_no_drone_stops_from_is_refused_naming_v_max() -> None:
    """Braking over more than MAX_STOP_M (the stop points would be numbers no QP can use; at
    v_max 2**62 the braking factor rounds to 1 and divided by zero)."""
    assert Braking.of(DT, Limits(v_max_mps=1800.0, a_max_mps2=1.79)) is not None  # 905 km
    for v_max in (2000.0, 2.0**62):
        with pytest.raises(ValidationError, match=r"limits.v_max: braking from .* would take"):
            Braking.of(DT, Limits(v_max_mps=v_max, a_max_mps2=1.79))
    assert Braking.of(DT, Limits(v_max_mps=2.0**62, a_max_mps2=1.79), enabled=False) is None


def test_the_tail_keeps_a_max_and_ends_at_the_stop_point() -> None:
    b = Braking.of(DT, Limits(v_max_mps=2.0, a_max_mps2=0.5))
    assert b is not None
    u_last = np.array([2.0, -1.2])  # |u_a| <= v_max
    u = np.vstack([u_last, tail(b, u_last, 4000)])
    assert np.abs(np.diff(u, axis=0)).max() <= 0.5 * DT + 1e-12
    x_last = np.array([1.0, 3.0])
    travelled = x_last + DT * u[1:].sum(axis=0)
    np.testing.assert_allclose(travelled, b.stop(x_last, u_last), atol=1e-9)


def test_braking_is_shift_invariant() -> None:
    """The shifted plan's own stop point is the old one: the old plan and tail contain the new."""
    b = Braking.of(DT, Limits(v_max_mps=1.5, a_max_mps2=1.0))
    assert b is not None
    rng = np.random.default_rng(0)
    u = rng.uniform(-1.0, 1.0, (6, 3, 2))
    x = DT * np.cumsum(u, axis=0)
    shifted = b.shifted(u)
    x_shift = x[0] + DT * np.cumsum(shifted, axis=0)  # the shifted plan, from where the old one went
    np.testing.assert_allclose(b.stop(x_shift[-1], shifted[-1]), b.stop(x[-1], u[-1]), atol=1e-12)
    np.testing.assert_allclose(shifted[-1], b.rho * u[-1])


def headon(plant: dict[str, object], horizon: int = 10) -> dict[str, object]:
    """Two drones head-on 16 m apart, v_max 2, a_max 0.5: braking takes 4 s, the horizon 1 s."""
    return {
        "version": 1,
        "name": "headon_amax",
        "dim": 2,
        "template": {"shape": "polygon", "n": 2, "radius": 8.0},
        "initial": {"centroid": [0.0, 0.0], "rotation": float(np.pi)},
        "reference": {"kind": "constant", "rotation": 0.0},
        "limits": {"v_max": 2.0, "d_min": 0.5, "a_max": 0.5},
        "controller": {"kind": "mpc", "gain": 3.0, "horizon": horizon},
        "simulation": {"dt": DT, "duration": 25.0},
        "plant": plant,
    }


@pytest.mark.parametrize("plant", [{"kind": "ideal"}, {"kind": "lag", "time_constant": 0.3}])
def test_head_on_with_braking_longer_than_the_horizon_keeps_d_min(plant: dict[str, object]) -> None:
    """Before the braking tail the lag's true path came to 0.434 m (d_min 0.5) with slack 0.84 m."""
    run = run_scenario(scenario_from_dict(headon(plant)))
    m, res = run.summary["metrics"], run.simulation
    truth = res.positions_m if res.true is None else res.true.positions_m  # dense on a plant
    gap = np.linalg.norm(truth[:, 0] - truth[:, 1], axis=1)
    assert gap.min() >= 0.5 and m["max_slack"] == 0.0 and m["solver_failures"] == 0
    assert m["completion"] == 1.0
    assert np.abs(np.diff(res.commands_mps, axis=0)).max() <= 0.5 * DT + 1e-9


OPEN_ADVERSARIAL: dict[int, str] = {}  # none now: run 154 (mean wind towards a fence) came 2.4 mm
# beyond it until the tie-break stopped counting drones deflected at speed as stalled; its cause,
# the velocity loop taking the observed wind offset as decaying, remains
"""Known breaches of the family, each with its cause (listed so a fix shows up as a failure)."""


@pytest.mark.slow
@pytest.mark.alone
def test_adversarial_family_keeps_every_limit_on_the_true_path() -> None:
    """200 seeded runs (tests/families.py ``adversarial``): every run is refused at load with the
    broken assumption named (at most 20 %), or keeps 0 true separation, obstacle and geofence
    violations along the dense true path and 0 command changes beyond ``a_max dt`` (but the
    :data:`OPEN_ADVERSARIAL` ones), with no slack and no lowered first row (no pair starts inside
    its distance here; in wind a plan may reach into its rows' growth, which is not slack)."""
    from concurrent.futures import ProcessPoolExecutor

    from families import adversarial_outcome

    with ProcessPoolExecutor(2) as pool:
        runs = list(pool.map(adversarial_outcome, range(200)))
    refused = [r for r in runs if r["refused"]]
    assert len(refused) <= 40, refused
    breaches = [
        r
        for r in runs
        if not r["refused"] and (r["separation"] or r["obstacle"] or r["geofence"] or r["jumps"])
    ]
    assert [r["index"] for r in breaches] == sorted(OPEN_ADVERSARIAL), breaches
    flown = [r for r in runs if not r["refused"]]
    grown = sum(r["growth_slack_steps"] > 0 for r in flown)
    print(f"adversarial: {len(runs)} runs, {len(refused)} refused, {len(breaches)} open, {grown} used growth")
    assert [r["index"] for r in flown if r["slack_steps"] or r["lowered"]] == []


def test_a_corridor_under_a_lag_holds_on_the_true_path() -> None:
    """|y| <= 0.3 m flown head-on under a 0.3 s lag: the fence rows are on the loop's positions.
    Before, the true path reached |y| = 0.463 m and the QP went infeasible at 3.5 s."""
    sc = headon({"kind": "lag", "time_constant": 0.3})
    sc["limits"] = {"v_max": 3.0, "d_min": 0.5, "geofence_min": [-20.0, -0.3], "geofence_max": [20.0, 0.3]}
    sc["simulation"]["duration"] = 8.0
    m = run_scenario(scenario_from_dict(sc)).summary["metrics"]
    assert m["geofence_violations_true"] == 0 and m["separation_violations_true"] == 0
    assert m["solver_failures"] == 0 and m["slack_steps"] == 0


FZ_S9191_125 = Path(__file__).parent / "fz_s9191_125.toml"


@pytest.mark.slow
def test_a_21_drone_ring_with_a_short_horizon_keeps_d_min_under_a_lag() -> None:
    """A held-out random run (horizon 6 at dt 0.05: 0.3 s of look-ahead against 1.1 s of braking)
    that came to 0.446 m (d_min 0.595) with 484 true violations."""
    from mpcform.scenario.load import load_scenario

    m = run_scenario(load_scenario(FZ_S9191_125)).summary["metrics"]
    assert m["separation_violations_true"] == 0 and m["min_separation_true"] >= 0.5951389406813115


def test_with_a_rest_command_the_shifted_plan_brakes_towards_it() -> None:
    """A drone resting at ``-delta`` (a velocity offset held over the plan) brakes its velocity over
    ground ``u + delta``: the shifted plan's last input is ``rest + rho (u_{H-1} - rest)``."""
    b = Braking.of(DT, Limits(v_max_mps=1.5, a_max_mps2=1.0))
    assert b is not None
    u = np.random.default_rng(1).uniform(-1.0, 1.0, (6, 3, 2))
    rest = np.array([[0.2, -0.1], [0.0, 0.0], [-0.3, 0.05]])
    shifted = b.shifted(u, rest)
    np.testing.assert_array_equal(shifted[:-1], u[1:])
    np.testing.assert_allclose(shifted[-1] - rest, b.rho * (u[-1] - rest))
    np.testing.assert_array_equal(b.shifted(u, np.zeros((3, 2)))[-1], b.shifted(u)[-1])
