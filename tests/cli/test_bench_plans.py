"""Each benchmark's plan names its cases, solvers and runs, from the options alone, and its --help
sentence names the defaults' run time."""

from __future__ import annotations

import importlib.util

import pytest

from mpcform.cli import bench_plans as plans
from mpcform.cli.main import build_parser

BENCHES = ("mpc", "solvers", "closed-loop", "scale", "split", "plant", "online")


def _args(*argv: str):
    return build_parser().parse_args(["bench", *argv])


@pytest.mark.parametrize("name", BENCHES)
def test_every_bench_has_a_run_time(name: str) -> None:
    text = plans.run_time_help(name)
    assert text.startswith("Run time of the defaults on a 2-core machine: ") and text.endswith(".")
    assert " s" in text or " min" in text


def test_plans_of_the_defaults() -> None:
    mpc = plans.mpc_plan(_args("mpc"), ("scenarios/swap_planar_8.toml",))
    assert mpc.startswith(
        "6 cases (planar swaps n = 8, 16, 32, 64; spatial swaps n = 20; scenarios: swap_planar_8)"
    )
    cvxpy = "no cvxpy (not installed)" if importlib.util.find_spec("cvxpy") is None else "cvxpy within 60 s"
    assert "solver piqp" in mpc and cvxpy in mpc and "time: " in mpc
    assert "no cvxpy;" in plans.mpc_plan(_args("mpc", "--cvxpy-budget", "0"), ())
    scale = plans.scale_plan(_args("scale"))
    assert scale.startswith("20 cases (scenarios formation, crossing x n = 10, 30, 100, 300, 1000 x modes")
    assert plans.online_plan(_args("online")).startswith("3 crossings (n = 20, 100, 1000), one run each")
    assert "every installed solver (named next)" in plans.solvers_plan(_args("solvers"), 36, "problems")
    loop = plans.closed_loop_plan(_args("closed-loop", "--solvers", "piqp"), ("a/swap.toml",))
    assert loop.startswith("scenarios swap (their own durations) x solvers piqp: one run per pair")
    split = plans.split_plan(_args("split", "--rounds", "0", "3"), ("s/one.toml",))
    assert split.startswith("1 scenario (one, their own durations), flown decoupled with 3 split rounds")


def test_the_plant_plan_scales_its_time_with_the_work() -> None:
    assert "about 1.7 s per run" in plans.plant_plan(_args("plant"))
    assert "about 3.5 s per run" in plans.plant_plan(_args("plant", "--n", "40"))
    assert "under 0.1 s per run" in plans.plant_plan(_args("plant", "--n", "1", "--duration", "0.1"))
    assert plans.count(1, "run") == "1 run" and plans.count(3, "run") == "3 runs"


def test_plans_say_the_profiled_runs() -> None:
    online = plans.online_plan(_args("online", "--profile", "p.txt"))
    assert "(n = 20, 100, 1000), one run each, then a second under cProfile into p.txt" in online
    scale = plans.scale_plan(_args("scale", "--profile", "p.txt"))
    assert "modes decoupled, monolithic), one run each, then a second under cProfile into p.txt" in scale
