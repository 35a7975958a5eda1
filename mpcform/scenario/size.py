"""How much memory a run of a scenario needs, estimated before anything large is allocated.

A run holds three kinds of large data:

- the time series (:class:`~mpcform.sim.simulation.SimulationResult` and the output files):
  positions, commands and reference, ``T x n x d`` values each for T = duration / dt steps;
- the MPC's sparse QP (coupling ``joint``, or ``decoupled`` with ``per_drone = false``): its
  nonzeros, about ``H n d (3 + facets)`` for the dynamics and velocity rows plus, for every
  candidate pair of drones, ``2H - 1`` separation rows of ``2d + 2`` entries;
- the per-drone dense QPs of ``decoupled`` mode with ``per_drone``: constant matrices of
  ``(H d)^2`` numbers and ``2H - 1`` dense rows of ``H d`` numbers per pair side.

The candidate pairs are counted (k-d tree, without listing them) where the drones are likely to
be closest: at the start, on the reference at nine times, and at a quarter, half and three
quarters of the straight way from the start to the reference's end (where a swap crosses);
a pair counts when it is within the planner's candidate radius ``d_min + margin + 4 v_max H dt``.
The bytes per unit were measured (peak resident memory, numpy 2, PIQP) and rounded up: 240 bytes
per time-series value and 1 KiB per step with the output files (60 and 400 without), 300 bytes
per QP nonzero (the solver's factorisation included), 20 bytes per dense per-drone row entry.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from mpcform._validate import Array
from mpcform.errors import ScenarioError
from mpcform.mpc.settings import MPCSettings
from mpcform.scenario.spec import Scenario

GIB = 2.0**30
DEFAULT_MAX_MEMORY_GIB = 4.0
"""Runs estimated above this are refused (``--max-memory`` raises it): below the memory of an 8 GB
laptop or a CI runner, and far above every bundled scenario (the largest needs about 0.1 GiB)."""
BYTES_PER_VALUE = {True: 240.0, False: 60.0}  # time series, with / without the output files
BYTES_PER_STEP = {True: 1024.0, False: 400.0}  # step records (StepInfo, times, CSV rows)
BYTES_PER_NONZERO = 300.0  # the sparse QP: planner arrays, the matrix and the solver's copy
BYTES_PER_DENSE_ENTRY = 20.0  # the per-drone QPs' dense separation rows (two copies and a product)
REFERENCE_SAMPLES = 9
CROSSING_FRACTIONS = (0.25, 0.5, 0.75)
DEFAULT_FACETS = {2: 16, 3: 32}  # as the planner's velocity polytope
DEFAULT_HORIZON = MPCSettings().horizon


@dataclass(frozen=True)
class MemoryEstimate:
    """The memory a run needs [bytes], by part, and the sizes it follows from."""

    steps: int
    n: int
    dim: int
    horizon: int | None  # None: not an MPC run
    pairs: int  # candidate drone pairs (MPC with d_min), upper bound n (n - 1) / 2
    series_bytes: float  # positions, commands, reference and per-step records
    horizon_bytes: float  # MPC rows that grow with the horizon alone (dynamics, velocity, limits)
    pair_bytes: float  # MPC separation rows of the candidate pairs and obstacle items

    @property
    def total_bytes(self) -> float:
        """The whole estimate [bytes]."""
        return self.series_bytes + self.horizon_bytes + self.pair_bytes

    @property
    def total_gib(self) -> float:
        """The whole estimate [GiB]."""
        return self.total_bytes / GIB


def estimate_memory(
    scenario: Scenario, controller: str | None = None, *, files: bool = True
) -> MemoryEstimate:
    """The memory a run of ``scenario`` needs (``controller`` overrides its kind; ``files``: the
    run writes trajectory.npz and trajectory.csv). Costs O(n log n), allocates O(n d)."""
    n, dim, steps = scenario.n, scenario.dim, scenario.steps
    series = float(steps + 1) * n * dim * BYTES_PER_VALUE[files] + float(steps + 1) * BYTES_PER_STEP[files]
    if (controller or scenario.controller.kind) != "mpc":
        return MemoryEstimate(steps, n, dim, None, 0, series, 0.0, 0.0)
    st, lim = scenario.controller.mpc, scenario.limits
    h, rows = st.horizon, 2 * st.horizon - 1
    pairs, items = _candidates(scenario)
    facets = (st.facets or DEFAULT_FACETS[dim]) if st.velocity_set == "polytope" else 2 * dim
    if st.solves_per_drone:
        nu = float(h * dim)
        constant = 8.0 * nu * (10.0 * nu + (h * facets if lim.v_max_mps is not None else 0.0))
        dense = BYTES_PER_DENSE_ENTRY * (2.0 * pairs + items) * rows * nu
        return MemoryEstimate(steps, n, dim, h, pairs, series, constant, dense)
    per_value = 3 + 2 * (lim.a_max_mps2 is not None) + (lim.geofence_min_m is not None)
    base = float(h) * n * (dim * per_value + 1 + (facets * dim if lim.v_max_mps is not None else 0))
    separation = float(rows) * (pairs * (2 * dim + 2) + items * (dim + 1))
    return MemoryEstimate(
        steps, n, dim, h, pairs, series, BYTES_PER_NONZERO * base, BYTES_PER_NONZERO * separation
    )


def check_memory(
    scenario: Scenario,
    max_gib: float = DEFAULT_MAX_MEMORY_GIB,
    controller: str | None = None,
    *,
    files: bool = True,
) -> MemoryEstimate:
    """Return the estimate, or raise :class:`ScenarioError` naming the key that drives it when
    the run would need more than ``max_gib`` GiB (``--max-memory`` raises the limit)."""
    est = estimate_memory(scenario, controller, files=files)
    if est.total_gib <= max_gib:
        return est
    parts = {
        "simulation.duration": est.series_bytes,
        "controller.horizon": est.horizon_bytes,
        _size_key(scenario): est.pair_bytes,
    }
    key = max(parts, key=lambda k: parts[k])
    if key == _size_key(scenario) and (est.horizon or 0) > DEFAULT_HORIZON:
        spec = scenario.controller
        mpc = dataclasses.replace(spec.mpc, horizon=DEFAULT_HORIZON)
        shorter = dataclasses.replace(scenario, controller=dataclasses.replace(spec, mpc=mpc))
        if estimate_memory(shorter, controller, files=files).total_gib <= max_gib:
            key = "controller.horizon"  # the long horizon brings every pair within reach
    what = {
        "simulation.duration": f"time series of {est.steps + 1:,} samples x {est.n:,} drones x "
        f"{est.dim} axes",
        "controller.horizon": f"MPC rows over a horizon of {est.horizon or 0:,} steps",
        _size_key(scenario): f"separation rows of about {est.pairs:,} drone pairs within reach x "
        f"{2 * (est.horizon or 0) - 1:,}",
    }
    shown = [f"{what[k]}: {b / GIB:,.1f} GiB" for k, b in parts.items() if b >= 0.01 * est.total_bytes]
    fix = {
        "simulation.duration": "shorten simulation.duration (or raise simulation.dt)",
        "controller.horizon": "lower controller.horizon",
    }.get(key, "use fewer drones")
    raise ScenarioError(
        key,
        f"the run would need about {est.total_gib:,.1f} GiB of memory ({'; '.join(shown)}), above the "
        f"limit of {max_gib:g} GiB: {fix}, or raise the limit with --max-memory GIB",
    )


def _size_key(scenario: Scenario) -> str:
    """The scenario key that sets the number of drones."""
    return {"grid": "template.rows", "explicit": "template.offsets"}.get(scenario.template.name, "template.n")


def _candidates(scenario: Scenario) -> tuple[int, int]:
    """Largest number of candidate pairs and of (drone, obstacle) items over the sampled positions."""
    lim, st, dt = scenario.limits, scenario.controller.mpc, scenario.simulation.dt_s
    travel = (lim.v_max_mps or 0.0) * st.horizon * dt
    samples = _sample_positions(scenario)
    pairs = 0
    if lim.d_min_m is not None and scenario.n > 1:
        radius = lim.d_min_m * (lim.downwash_kappa or 1.0) + st.margin_m + 4.0 * travel
        for points in samples:
            tree = cKDTree(points)
            pairs = max(pairs, (int(tree.count_neighbors(tree, radius)) - scenario.n) // 2)
    items = 0
    if scenario.obstacles:
        centres = np.array([o.center_m for o in scenario.obstacles])
        required = np.array([o.required_distance_m for o in scenario.obstacles])
        reach = required + st.margin_m + 2.0 * travel
        for points in samples:
            near = cKDTree(points).query_ball_point(centres, reach, return_length=True)
            items = max(items, int(near.sum()))
    return pairs, items


def _sample_positions(scenario: Scenario) -> list[Array]:
    """Where the drones are likely closest: start, reference samples, straight-way crossings."""
    start = scenario.initial_positions_m
    times = np.linspace(0.0, scenario.simulation.duration_s, REFERENCE_SAMPLES)
    reference = scenario.reference.targets(times)[0]
    crossing = [(1.0 - f) * start + f * reference[-1] for f in CROSSING_FRACTIONS]
    return [start, *reference, *crossing]
