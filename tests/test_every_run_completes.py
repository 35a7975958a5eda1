"""Every run completes, on every plant (``tests/completion_family.py``), and the issue's two
reproducers arrive within their durations; the ordinary-day family (``tests/broad_family.py``)
draws as broadly as it promises."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import broad_family
import numpy as np
import pytest
from completion_family import PARTS, PLANTS, campaign, outcome, report, scenario
from scipy.spatial.distance import pdist

from mpcform.scenario.load import load_scenario, scenario_from_dict

HERE = Path(__file__).resolve().parent

OPEN_BREACHES: tuple[str, ...] = ()
"""Runs whose true path breaks d_min, each a known open failure: none. completion_14 (18 drones,
second-order loop, horizon 7 at dt 0.05) came to 0.476-0.482 m of its 0.547 m while the braking
tail's rows held only on the chord from the horizon's end to the rest point; the tail's hull
(:mod:`mpcform.mpc.constraints.tail`) keeps it at 0.551 m with no slack."""


def test_the_family_draws_what_it_promises() -> None:
    """Its first draws cover every part and plant, keep targets ``d_min + 4 delta + 0.1 m`` apart
    and give each run twice its straight-line travel at v_max, and a quadrotor a v_max below the
    speed its margin holds for."""
    seen = Counter()
    for index in range(len(PARTS) * len(PLANTS)):
        sc = scenario(np.random.default_rng([20261204, index]), index)
        s = scenario_from_dict(sc)
        seen[sc["name"].split("_", 2)[2]] += 1
        goal = s.reference.targets(np.array([1e9]))[0][0]
        gap = s.limits.d_min_m + 4.0 * s.robustness.margin_m + 0.1
        assert pdist(goal).min() >= gap - 1e-9
        travel = np.linalg.norm(goal - s.initial_positions_m, axis=1).max() / s.limits.v_max_mps
        assert s.simulation.duration_s >= 2.0 * travel + getattr(s.reference, "duration_s", 0.0)
        assert s.limits.v_max_mps <= s.robustness.valid_speed_mps
    assert len(seen) == len(PARTS) * len(PLANTS)


def test_the_ordinary_day_family_draws_as_broadly_as_it_promises() -> None:
    """Its first 48 draws load (none refused) and span what users fly: every plant with both
    couplings, 2-30 drones, dt 0.05-0.1 s, horizons from 3 to past 20, a_max from near 0.2 m/s^2 to
    the default, v_max 0.5-4 m/s, steady winds past 1.5 m/s, fences, obstacles and missions."""
    runs = [broad_family.drawn(i) for i in range(48)]
    assert [r for r in runs if isinstance(r, str)] == []
    docs = [r for r in runs if not isinstance(r, str)]
    built = [scenario_from_dict(d) for d in docs]
    groups = Counter((d.get("plant", {}).get("kind", "ideal"), d["controller"]["coupling"]) for d in docs)
    assert len(groups) == 2 * len(PLANTS), groups
    n = [s.template.n for s in built]
    h = [d["controller"]["horizon"] for d in docs]
    a = [s.limits.a_max_mps2 for s in built]
    v = [d["limits"]["v_max"] for d in docs]
    wind = [np.linalg.norm(d["plant"]["wind"]["mean"]) for d in docs if "plant" in d]
    assert min(n) == 2 and max(n) >= 20 and min(h) == 3 and max(h) >= 20
    assert {s.simulation.dt_s for s in built} <= set(broad_family.DT_S)
    assert (
        min(a) < 0.3
        and max(a) == pytest.approx(broad_family.A_MAX_MPS2)
        and 0.5 <= min(v) < 1 < 3 < max(v) <= 4
    )
    assert max(wind) > 1.5 and all(0.0 <= w <= 2.0 for w in wind)
    assert any("geofence_min" in d["limits"] for d in docs) and any(d.get("obstacles") for d in docs)
    assert any(d["reference"]["kind"] == "mission" for d in docs)


@pytest.mark.slow
@pytest.mark.alone
def test_every_run_of_the_completion_family_arrives_without_a_true_violation() -> None:
    """150 runs (both couplings, both velocity sets, dt 0.05-0.1, horizons 6-10, n 2-21, every
    plant): every drone ends within 0.1 m of its target, none breaks d_min, a sphere or the fence
    along the dense true path, except the known open breaches; none lowers a first row, and only
    the close starts (a pair inside its distance at the start) need slack."""
    results = campaign(150)
    groups = Counter((r["plant"], r["coupling"]) for r in results)
    assert all(groups[(p, c)] >= 10 for p in PLANTS for c in ("joint", "decoupled")), groups
    assert max(r["n"] for r in results) >= 20
    print(report(results))
    bad = [
        r for r in results if r["completion"] < 1.0 or (r["violations"] and r["name"] not in OPEN_BREACHES)
    ]
    assert not bad, report(bad)
    assert sorted(r["name"] for r in results if r["violations"]) == sorted(OPEN_BREACHES)
    assert [r["name"] for r in results if r["lowered"]] == []
    assert [r["name"] for r in results if r["slack_steps"] and "close_start" not in r["name"]] == []


def jammed(index: int, seed: int = 777) -> dict:
    """Run ``index`` of the small-a_max family: the completion family's swaps (planar and spatial,
    every plant) with a_max 0.2-0.5 m/s^2, horizons 3-10, dt 0.05-0.1 s and both couplings, its
    duration lengthened by twice the time ``v_max / a_max`` to reach full speed."""
    rng = np.random.default_rng([seed, index])
    sc = scenario(rng, [0, 1][index % 2] + len(PARTS) * ((index // 2) % len(PLANTS)))
    sc["limits"]["a_max"] = a_max = float(rng.uniform(0.2, 0.5))
    sc["controller"]["horizon"] = int(rng.integers(3, 11))
    sc["controller"]["coupling"] = ("decoupled", "joint")[(index // 8) % 2]
    sc["simulation"]["dt"] = float(rng.choice(broad_family.DT_S))
    sc["simulation"]["duration"] = round(sc["simulation"]["duration"] + 2 * sc["limits"]["v_max"] / a_max, 2)
    sc["name"] = f"jam_{index}_" + sc["name"]
    return sc


@pytest.mark.slow
def test_every_run_with_a_small_a_max_arrives() -> None:
    """16 swaps of 2-21 drones whose a_max (0.2-0.5 m/s^2) is far below eq. 14's braking
    (k v_max) and whose horizon (3-10 steps) sees a fraction of the braking: they arrive, on every
    plant, with no true violation. Before ``mpc.plan.braking_error``, 6 of 16 such runs (at dt 0.05
    or 0.1 s) ended short: the drones overshot goals they could not brake for and circled, and
    converging drones' stop points blocked each other."""
    results = [outcome(jammed(i)) for i in range(16)]
    print(report(results))
    assert [
        (r["name"], r["completion"], r["violations"])
        for r in results
        if r["completion"] < 1.0 or r["violations"]
    ] == []


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fz_s8080_329", "fz_s9191_72"])
def test_the_reproducers_complete_within_their_durations(name: str) -> None:
    """A decoupled 13-drone permutation on the ideal plant and a 15-drone formation flown by the
    quadrotor in gusts: once drifting away, now every drone arrives, with no true violation."""
    import tomllib

    doc = tomllib.loads((HERE / f"{name}.toml").read_text())
    assert load_scenario(HERE / f"{name}.toml").name == name
    out = outcome(doc)
    assert out["completion"] == 1.0 and out["violations"] == 0, out
