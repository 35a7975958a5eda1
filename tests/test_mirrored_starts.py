"""Mirrored starts run for every reference kind, in 2-D and 3-D (they were refused as 'all drones
coincide'), and random planar permutation swaps with separated drones are never refused."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.formation.template import Template
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import scenario_from_dict

HEXAGON = Template.polygon(6, radius=1.2).offsets  # isotropic: its mirror image has no proper fit


def mirrored(dim: int, kind: str, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    offsets = HEXAGON if dim == 2 else np.column_stack([HEXAGON, 0.4 * np.array([1, -1] * 3)])
    flip = np.diag([-1.0] + [1.0] * (dim - 1))
    start = (offsets @ flip.T)[rng.permutation(len(offsets))]
    zero = 0.0 if dim == 2 else [0.0, 0.0, 0.0]
    reference = {
        "constant": {"kind": "constant", "centroid": [0.0] * dim, "rotation": zero, "scale": 1.0},
        "exponential": {"kind": "exponential", "centroid": [1.0] * dim, "rate": 0.5},
        "mission": {"kind": "mission", "keyframes": [{"centroid": [2.0] * dim}]},
    }[kind]
    return {
        "version": 1,
        "name": f"mirrored_{dim}d_{kind}",
        "dim": dim,
        "seed": seed,
        "template": {"shape": "explicit", "offsets": offsets.tolist()},
        "initial": {"positions": start.tolist()},
        "reference": reference,
        "limits": {"v_max": 1.5, "d_min": 0.5},
        "controller": {"kind": "mpc", "horizon": 8, "coupling": "decoupled"},
        "simulation": {"dt": 0.1, "duration": 1.0},
    }


@pytest.mark.parametrize("kind", ["constant", "exponential", "mission"])
@pytest.mark.parametrize("dim", [2, 3])
def test_a_mirrored_permuted_start_runs_for_every_reference_kind(dim: int, kind: str) -> None:
    run = run_scenario(scenario_from_dict(mirrored(dim, kind, seed=dim)))
    assert np.all(np.isfinite(run.simulation.positions_m))
    assert run.summary["metrics"]["separation_violations"] == 0


def test_the_issue_reproducer_loads_and_starts_from_the_centroid() -> None:
    data = mirrored(2, "exponential", seed=0)
    data["initial"]["positions"] = (HEXAGON @ np.diag([-1.0, 1.0])).tolist()  # the exact mirror
    scenario = scenario_from_dict(data)
    np.testing.assert_allclose(scenario.start.centroid_m, 0.0, atol=1e-12)
    assert scenario.start.scale == pytest.approx(1.0)  # the RMS size ratio


def test_random_planar_permutation_swaps_are_never_refused() -> None:
    rng = np.random.default_rng(2026)
    for _ in range(120):
        n = int(rng.integers(2, 33))
        offsets = Template.centred(rng.uniform(-4.0, 4.0, (n, 2)))[0].offsets
        if rng.random() < 0.5:
            offsets = Template.polygon(n, radius=max(1.0, n / 4.0)).offsets
        d = np.linalg.norm(offsets[:, None] - offsets[None], axis=-1)
        d_min = 0.9 * float(d[np.triu_indices(n, 1)].min()) if n > 1 else 0.5
        start = offsets[rng.permutation(n)] * ([-1.0, 1.0] if rng.random() < 0.5 else 1.0)
        data = mirrored(2, "constant", 0) | {
            "template": {"shape": "explicit", "offsets": offsets.tolist()},
            "initial": {"positions": start.tolist()},
            "limits": {"v_max": 1.0, "d_min": d_min},
        }
        scenario_from_dict(data)  # raises if refused
