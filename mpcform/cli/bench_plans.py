"""What each ``mpcform bench`` subcommand says before it starts: its plan (cases, solvers, runs and a
rough time), made from its options alone, and the run time of its defaults for its ``--help``.

The times are rough figures from this 2-core machine (shared with other jobs); the progress lines
then give the pace measured as the cases run.
"""

from __future__ import annotations

import argparse
import importlib.util
from collections.abc import Sequence
from pathlib import Path

RUN_TIMES = {
    "mpc": "roughly 3-12 min (up to --cvxpy-budget more per case with cvxpy)",
    "solvers": "roughly 15-25 min with a dozen solvers installed, about a minute per solver",
    "closed-loop": "roughly 3-10 min with every usable solver (a stalled run holds up to --timeout)",
    "scale": "roughly 5-15 min (each monolithic case up to its --monolithic-budget)",
    "split": "about 3-9 min",
    "plant": "about 5 s",
    "online": "about 25 s",
}
"""The run time of each benchmark's defaults on a 2-core machine (rough)."""

PLANT_S_PER_WORK = 1.73 / (20 * 12.0 * 500.0)
"""Wall seconds of one plant run per drone x inner step (1.73 s for the defaults)."""


def run_time_help(name: str) -> str:
    """The sentence of ``bench NAME --help`` giving its defaults' run time."""
    return f"Run time of the defaults on a 2-core machine: {RUN_TIMES[name]}."


def count(n: int, what: str) -> str:
    """``1 case``, ``2 cases``."""
    return f"{n} {what}{'' if n == 1 else 's'}"


def _names(items: Sequence[str | Path]) -> str:
    return ", ".join(Path(p).stem for p in items) or "none"


def _ns(sizes: Sequence[int]) -> str:
    return ", ".join(str(n) for n in sizes)


def mpc_plan(args: argparse.Namespace, scenarios: Sequence[str | Path]) -> str:
    """``bench mpc``'s plan."""
    cases = len(args.n) + len(args.spatial_n) + len(scenarios)
    cvxpy = f"cvxpy within {args.cvxpy_budget:g} s per case" if args.cvxpy_budget > 0 else "no cvxpy"
    if args.cvxpy_budget > 0 and importlib.util.find_spec("cvxpy") is None:  # found, not imported
        cvxpy = "no cvxpy (not installed)"
    return (
        f"{count(cases, 'case')} (planar swaps n = {_ns(args.n) or 'none'}; spatial swaps n = "
        f"{_ns(args.spatial_n) or 'none'}; scenarios: {_names(scenarios)}), one run each, {args.steps} "
        f"steps per swap, {args.coupling}, solver {args.solver}, {cvxpy}; time: about 1-50 s per case "
        "on a 2-core machine (joint spatial swaps of 20 drones the longest), plus its cvxpy time"
    )


def solvers_plan(args: argparse.Namespace, problems: int, where: str) -> str:
    """``bench solvers``' plan (before the installed solvers are looked up)."""
    names = f"solvers {', '.join(args.solvers)}" if args.solvers else "every installed solver (named next)"
    exact = "" if args.no_exact else ", then the exact casadi:ipopt reference"
    return (
        f"{count(problems, 'problem')} of {where}: the clarabel reference, then {names} side "
        f"by side in modes {', '.join(args.modes)} x settings {', '.join(args.settings)}{exact}; time limit "
        f"{args.time_limit:g} s per solve; time: about 1-2 min for each reference, then 5-10 s per "
        "solver per mode and setting on a 2-core machine"
    )


def closed_loop_plan(args: argparse.Namespace, scenarios: Sequence[str | Path]) -> str:
    """``bench closed-loop``'s plan (before the installed solvers are looked up)."""
    names = f"solvers {', '.join(args.solvers)}" if args.solvers else "every usable solver (named next)"
    duration = f"{args.duration:g} s each" if args.duration else "their own durations"
    return (
        f"scenarios {_names(scenarios)} ({duration}) x {names}: one run per pair, each in its "
        f"own process, time limit {args.timeout:g} s per run; time: about 5 s per run for piqp on the "
        "swaps (2-core machine), more for a solver set up at every call"
    )


def scale_plan(args: argparse.Namespace) -> str:
    """``bench scale``'s plan."""
    modes = [args.coupling] + (["monolithic"] if args.monolithic_budget > 0 else [])
    cases = len(args.scenario) * len(args.n) * len(modes)
    mono = f", monolithic within {args.monolithic_budget:g} s" if args.monolithic_budget > 0 else ""
    where = "in process" if args.in_process else "each in a fresh process"
    return (
        f"{count(cases, 'case')} (scenarios {', '.join(args.scenario)} x n = {_ns(sorted(args.n))} x modes "
        f"{', '.join(modes)}), {_runs(args.profile)}, {args.steps} steps, horizon {args.horizon}, solver "
        f"{args.solver} (DAQP per drone when decoupled), {where}; budget {args.budget:g} s per case"
        f"{mono}; time: a few s per case up to 300 drones, up to a minute at 1000 (2-core machine)"
    )


def split_plan(args: argparse.Namespace, scenarios: Sequence[str | Path]) -> str:
    """``bench split``'s plan."""
    steps = f"{args.steps} steps" if args.steps is not None else "their own durations"
    return (
        f"{count(len(scenarios), 'scenario')} ({_names(scenarios)}, {steps}), flown decoupled with "
        f"{max(args.rounds)} split rounds, every QP solved again jointly by clarabel and piqp; rows: "
        f"rounds {_ns(args.rounds)}; time: 10 s to 5 min per scenario on a 2-core machine (the most for "
        "swap_spatial_20 at 50 rounds)"
    )


def plant_plan(args: argparse.Namespace) -> str:
    """``bench plant``'s plan, with its time scaled from the defaults' measured run."""
    each = PLANT_S_PER_WORK * args.n * args.duration * args.rate
    time = f"about {each:.1f} s per run" if each >= 0.1 else "under 0.1 s per run"
    wind = "still air" if args.no_wind else "gusts"
    return (
        f"{count(args.repeats, 'run')} of the quadrotor plant: {args.n} drones x {args.duration:g} s at "
        f"{args.rate:g} Hz, {wind}, no solver; time: {time} on a 2-core machine"
    )


def _runs(profile: str | None) -> str:
    """How often each case runs: once, or with ``--profile`` once more under cProfile (twice the time)."""
    if profile is None:
        return "one run each"
    return f"one run each, then a second under cProfile into {profile} (about twice the time)"


def online_plan(args: argparse.Namespace) -> str:
    """``bench online``'s plan."""
    return (
        f"{count(len(args.n), 'crossing')} (n = {_ns(args.n)}), {_runs(args.profile)}, {args.steps} periods "
        f"of 0.1 s, deadline {args.budget:g} s, {args.coupling}; time: about 2 s per 100 drones per 60 "
        "periods on a 2-core machine"
    )
