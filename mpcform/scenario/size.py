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

Two checks need no built scenario: :func:`check_drone_count` refuses, from the file's keys and
before the template is built, drones whose time series alone exceed the limit, and
:func:`check_work` bounds a plant's work (its inner steps times the drones: the quadrotor's
``rate x duration``) and the planner's (its sparse QP's nonzeros times the control steps, as if
every step solved it), which cost time rather than memory (``--max-work`` raises both).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from mpcform._validate import Array, read_regular
from mpcform.errors import ScenarioError, ValidationError
from mpcform.mpc.settings import MPCSettings
from mpcform.scenario.spec import Scenario
from mpcform.world.shapes.shape_set import ShapeSet

GIB = 2.0**30
DEFAULT_MAX_MEMORY_GIB = 4.0
"""Runs estimated above this are refused (``--max-memory`` raises it): below the memory of an 8 GB
laptop or a CI runner, and far above every bundled scenario (the largest needs about 0.1 GiB)."""
DEFAULT_MAX_WORK = 5e7
"""Runs whose plant takes more inner steps x drones than this are refused (``--max-work`` raises
it): the quadrotor plant took 0.5 ms per inner step plus 2 us per drone (2-core machine), so the
bound is 2-30 minutes of plant alone; the bundled quadrotor scenario takes 7.2e5."""
QP_WORK_PER_WORK = 2.0
"""The planner's work limit per unit of ``--max-work``: 1e8 QP nonzeros x steps at the default,
about 12 minutes of joint QPs (PIQP with the default a_max took 7.5 us per nonzero: swap_spatial_20's
51,000 in 386 ms per step); the bundled swaps need 8e5-6e6."""
SECONDS_PER_NONZERO = 7.5e-6
BYTES_PER_VALUE = {True: 240.0, False: 60.0}  # time series, with / without the output files
BYTES_PER_STEP = {True: 1024.0, False: 400.0}  # step records (StepInfo, times, CSV rows)
BYTES_PER_NONZERO = 300.0  # the sparse QP: planner arrays, the matrix and the solver's copy
BYTES_PER_DENSE_ENTRY = 20.0  # the per-drone QPs' dense separation rows (two copies and a product)
REFERENCE_SAMPLES = 9
CROSSING_FRACTIONS = (0.25, 0.5, 0.75)
DEFAULT_FACETS = {2: 16, 3: 32}  # as the planner's velocity polytope
DEFAULT_HORIZON = MPCSettings().horizon
MAX_STEPS = 1e12
"""The most control steps a file may ask for (``duration / dt``); the memory estimate refuses far
fewer, but it needs the count as an integer (``duration = 1e308`` overflowed)."""
MAX_SCENARIO_BYTES = 16 * 2**20
"""The largest scenario file read, 16 MiB (the bundled ones take under 10 KiB, 10,000 explicit
offsets about 0.5 MiB): a larger file, a device (``/dev/zero``) or a FIFO is refused before a byte
of it is read."""


def read_scenario_bytes(path: str | Path) -> bytes:
    """The bytes of the scenario file ``path``, a regular file of at most :data:`MAX_SCENARIO_BYTES`
    (:func:`mpcform._validate.read_regular`); else a :class:`ScenarioError` naming the path."""
    try:
        return read_regular(path, MAX_SCENARIO_BYTES, "scenario file")
    except FileNotFoundError:
        raise ScenarioError(str(path), "no such scenario file") from None
    except ValidationError as exc:
        raise ScenarioError(exc.field, exc.message) from None
    except OSError as exc:
        raise ScenarioError(str(path), f"cannot read the file: {exc.strerror or exc}") from None


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
    series = _series_bytes(steps, n, dim, files)
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
    bounded = lim.a_max_mps2 is None or lim.a_max_bounded  # unset: the MPC's default
    per_value = 3 + 2 * bounded + (lim.geofence_min_m is not None)
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
    size_key = _drone_key(scenario.template.name)
    parts = {
        "simulation.duration": est.series_bytes,
        "controller.horizon": est.horizon_bytes,
        size_key: est.pair_bytes,
    }
    key = max(parts, key=lambda k: parts[k])
    if key == size_key and (est.horizon or 0) > DEFAULT_HORIZON:
        spec = scenario.controller
        mpc = dataclasses.replace(spec.mpc, horizon=DEFAULT_HORIZON)
        shorter = dataclasses.replace(scenario, controller=dataclasses.replace(spec, mpc=mpc))
        if estimate_memory(shorter, controller, files=files).total_gib <= max_gib:
            key = "controller.horizon"  # the long horizon brings every pair within reach
    what = {
        "simulation.duration": f"time series of {est.steps + 1:,} samples x {est.n:,} drones x "
        f"{est.dim} axes",
        "controller.horizon": f"MPC rows over a horizon of {est.horizon or 0:,} steps",
        size_key: f"separation rows of about {est.pairs:,} drone pairs within reach x "
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


def check_drone_count(
    template: Mapping[str, Any], steps: float, dim: int, max_gib: float, *, files: bool = True
) -> None:
    """Raise :class:`ScenarioError` naming the key that sets the number of drones when the parsed
    ``[template]`` keys ask for more drones than fit within ``max_gib`` GiB with their time series
    alone over ``steps`` control steps (the estimate's smallest part): before the template is built."""
    shape, key = template["shape"], _drone_key(template["shape"])
    if shape == "grid":
        n = template["rows"] * template["cols"] * (template["layers"] or 1)
    else:
        n = len(template["offsets"]) if shape == "explicit" else template["n"]
    if not 0.0 <= steps <= MAX_STEPS:  # refused by the loader, naming simulation.duration
        return
    need = _series_bytes(round(steps), n, dim, files) / GIB
    if need > max_gib and n > steps:  # else the duration drives it: check_memory names it
        raise ScenarioError(
            key,
            f"{n:,} drones would need about {need:,.1f} GiB of memory for their time series alone "
            f"({round(steps) + 1:,} samples x {n:,} drones x {dim} axes), above the limit of "
            f"{max_gib:g} GiB: use fewer drones, or raise the limit with --max-memory GIB",
        )


def plant_work(scenario: Scenario) -> float:
    """The plant's work: its inner steps x drones (the quadrotor's ``rate x duration x n``; 0 for
    the ideal and linear plants, which take exact steps at the control samples)."""
    rate = getattr(scenario.plant, "rate_hz", None)
    return 0.0 if rate is None else float(rate) * scenario.steps * scenario.simulation.dt_s * scenario.n


def planner_work(scenario: Scenario, controller: str | None = None) -> float:
    """The planner's work: its sparse QP's nonzeros (:func:`estimate_memory`) times the control
    steps, as if every step solved it (0 for per-drone solves and for other controllers, whose
    steps cost little)."""
    return _qp_work(scenario, estimate_memory(scenario, controller, files=False))


def _qp_work(scenario: Scenario, est: MemoryEstimate) -> float:
    """:func:`planner_work` from the run's memory estimate."""
    if est.horizon is None or scenario.controller.mpc.solves_per_drone:
        return 0.0
    return (est.horizon_bytes + est.pair_bytes) / BYTES_PER_NONZERO * est.steps


def check_work(
    scenario: Scenario, max_work: float = DEFAULT_MAX_WORK, controller: str | None = None
) -> float:
    """Return :func:`plant_work`, or raise :class:`ScenarioError` naming ``plant.rate`` when it is
    above ``max_work``, or the key that drives it when :func:`planner_work` is above
    :data:`QP_WORK_PER_WORK` times ``max_work`` (``--max-work`` raises both limits)."""
    est = estimate_memory(scenario, controller, files=False)
    qp_work, qp_limit = _qp_work(scenario, est), QP_WORK_PER_WORK * max_work
    if qp_work > qp_limit:
        key = (
            _drone_key(scenario.template.name) if est.pair_bytes > est.horizon_bytes else "controller.horizon"
        )
        raise ScenarioError(
            key,
            f"the MPC would solve QPs of about {qp_work / est.steps:,.3g} nonzeros ({est.pairs:,} drone "
            f"pairs within reach, horizon {est.horizon}) over {est.steps:,} steps: {qp_work:.3g} nonzeros x "
            f"steps, about {qp_work * SECONDS_PER_NONZERO / 3600:,.3g} h if every step solves it, above the "
            f'limit of {qp_limit:.3g}: use fewer drones, coupling = "decoupled" (per-drone solves), a '
            "shorter horizon or duration, or raise the limit with --max-work N",
        )
    work = plant_work(scenario)
    if work <= max_work:
        return work
    rate, flight_s = float(scenario.plant.rate_hz), scenario.steps * scenario.simulation.dt_s  # type: ignore[attr-defined]
    raise ScenarioError(
        "plant.rate",
        f"the plant would take {work:.3g} inner steps x drones ({rate * flight_s:,.0f} steps at {rate:g} "
        f"Hz over {flight_s:g} s x {scenario.n:,} drones), above the limit of "
        f"{max_work:.3g} (about 0.5 ms per inner step): lower plant.rate, shorten simulation.duration "
        "or use fewer drones, or raise the limit with --max-work N",
    )


def _series_bytes(steps: int, n: int, dim: int, files: bool) -> float:
    """The time series and step records of ``steps`` control steps of ``n`` drones [bytes]."""
    return float(steps + 1) * n * dim * BYTES_PER_VALUE[files] + float(steps + 1) * BYTES_PER_STEP[files]


def _drone_key(shape: str) -> str:
    """The scenario key that sets the number of drones of a template ``shape``."""
    return {"grid": "template.rows", "explicit": "template.offsets"}.get(shape, "template.n")


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
        shapes = ShapeSet(scenario.obstacles, scenario.dim)
        reach = shapes.required_m + st.margin_m + 2.0 * travel
        for points in samples:
            items = max(items, int((shapes.core_distances(points) <= reach).sum()))
    return pairs, items


def _sample_positions(scenario: Scenario) -> list[Array]:
    """Where the drones are likely closest: start, reference samples, straight-way crossings."""
    start = scenario.initial_positions_m
    times = np.linspace(0.0, scenario.simulation.duration_s, REFERENCE_SAMPLES)
    reference = scenario.reference.targets(times)[0]
    crossing = [(1.0 - f) * start + f * reference[-1] for f in CROSSING_FRACTIONS]
    return [start, *reference, *crossing]
