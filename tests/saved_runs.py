"""Short runs of bundled scenarios saved to a directory, as `mpcform run --out DIR --plot` leaves them."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from mpcform.outputs.rundata import formation_data, write_formation_npz
from mpcform.run.runner import RunResult, run_scenario
from mpcform.scenario.load import load_scenario
from mpcform.scenario.spec import Scenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


def shortened(scenario: Scenario, steps: int) -> Scenario:
    """``scenario`` with its duration cut to ``steps`` control steps."""
    sim = dataclasses.replace(scenario.simulation, duration_s=steps * scenario.simulation.dt_s)
    return dataclasses.replace(scenario, simulation=sim)


def short_run(
    name: str, out_dir: Path, steps: int = 40, formation: bool = True, flyable: bool = False
) -> RunResult:
    """Run ``scenarios/<name>.toml`` for ``steps`` steps into ``out_dir`` (with formation.npz;
    ``flyable``: with the platform's tracking allowance, as ``export`` requires)."""
    scenario = shortened(load_scenario(SCENARIOS / f"{name}.toml"), steps)
    scenario = scenario.flyable() if flyable else scenario
    run = run_scenario(scenario, out_dir)
    if formation:
        write_formation_npz(out_dir, formation_data(scenario, run.simulation.t_s))
    return run
