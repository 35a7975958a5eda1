"""Recorded QP instances: the planner's problems, saved from closed-loop runs of scenarios.

One problem per ``.npz`` file (``numpy.savez_compressed``, no pickles), in
``<dir>/<scenario>/step_<step:04d>.npz`` (the format is documented in ``problems/README.md``):

- ``meta``: a JSON string: ``format`` ("mpcform-qp"), ``version`` (1), ``scenario``, ``step`` (the
  simulation step j, at time ``t_s = j dt``), ``t_s``, ``event`` ("setup": the sparsity pattern is
  new at this step, else "update"), ``n`` (drones in the QP), ``dim``, ``horizon``, ``n_var``,
  ``n_rows``, ``nnz_P``, ``nnz_A``, ``recorded_with`` (the solver that drove the run),
  ``mpcform_version``;
- ``P_data, P_indices, P_indptr, P_shape``: the upper triangle of P (CSC);
- ``A_data, A_indices, A_indptr, A_shape``: A (CSC, explicit zeros kept: the pattern is the
  planner's);
- ``q, l, u``: cost vector and row bounds (+-inf where a side is absent);
- ``x0`` (optional): the warm start the planner passed;
- ``ctx_*`` (optional): the :class:`~mpcform.solvers.base.QPContext` (exact separation data, used
  by ``casadi:ipopt`` and ``casadi:hpipm``): ``ctx_separation_rows`` (start, stop),
  ``ctx_start_m``, ``ctx_pairs``, ``ctx_pair_distance_m``, ``ctx_metric``,
  ``ctx_obstacle_drones``, ``ctx_obstacle_centers_m``, ``ctx_obstacle_distance_m``.

The problem is ``min 0.5 z^T P z + q^T z  s.t.  l <= A z <= u``;
:meth:`RecordedQP.to_qpsolvers` gives qpsolvers' form.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.errors import MPCFormError, ScenarioError, ValidationError
from mpcform.mpc.strategy import as_sparse
from mpcform.scenario.build import check_sparse_solver
from mpcform.scenario.check import located_problem
from mpcform.scenario.load import load_scenario
from mpcform.solvers.base import QPBackend, QPContext, QPSolution
from mpcform.solvers.registry import make_backend

FORMAT = "mpcform-qp"
VERSION = 1
REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_PROBLEMS_DIR = REPO_ROOT / "problems"
"""Where the bundled problem set lives in a source checkout."""
DEFAULT_SCENARIOS = tuple(
    REPO_ROOT / "scenarios" / f"{name}.toml"
    for name in ("swap_planar_8", "swap_spatial_12", "swap_spatial_20")
)
"""The scenarios the bundled set is recorded from: small, medium, large."""
DEFAULT_PER_SCENARIO = 12
_CTX_ARRAYS = ("start_m", "pairs", "metric", "obstacle_drones", "obstacle_centers_m", "obstacle_distance_m")


@dataclass(frozen=True, eq=False)
class RecordedQP:
    """One QP ``min 0.5 z^T P z + q^T z  s.t.  l <= A z <= u`` (P upper triangular) with its
    metadata (see the module docstring), the planner's warm start and its context."""

    P: sp.csc_matrix
    q: Array
    A: sp.csc_matrix
    l: Array  # noqa: E741 - the standard name of the lower bound
    u: Array
    meta: dict[str, Any]
    x0: Array | None = None
    context: QPContext | None = None

    @property
    def name(self) -> str:
        """``<scenario>/step_<step>``."""
        return f"{self.meta['scenario']}/step_{int(self.meta['step']):04d}"

    @property
    def n_var(self) -> int:
        return int(self.q.shape[0])

    @property
    def n_rows(self) -> int:
        return int(self.l.shape[0])

    def objective(self, x: Array) -> float:
        """``0.5 x^T P x + q^T x`` (P's upper triangle mirrored)."""
        upper = self.P @ x
        diag = self.P.diagonal() * x
        return float(x @ upper - 0.5 * x @ diag + self.q @ x)

    def primal_residual(self, x: Array) -> float:
        """Largest violation of ``l <= A x <= u`` (0 when feasible), in the rows' units."""
        ax = self.A @ x
        return float(max(np.max(self.l - ax, initial=0.0), np.max(ax - self.u, initial=0.0)))

    def to_qpsolvers(self, dense: bool = False) -> Any:
        """The problem as a :class:`qpsolvers.Problem`: ``min 0.5 x^T P x + q^T x`` s.t.
        ``G x <= h`` (each finite side of the two-sided rows), ``A x = b`` (rows with
        ``l == u``), full symmetric P; dense matrices when ``dense``."""
        from mpcform.solvers.qpsolvers_backend import qpsolvers_form

        return qpsolvers_form(self.P, self.q, self.A, self.l, self.u, dense)[0]


def _csc(arrays: Any, key: str) -> sp.csc_matrix:
    shape = tuple(int(s) for s in arrays[f"{key}_shape"])
    return sp.csc_matrix(
        (arrays[f"{key}_data"], arrays[f"{key}_indices"], arrays[f"{key}_indptr"]), shape=shape
    )


def save_problem(path: str | Path, qp: RecordedQP) -> Path:
    """Write ``qp`` to ``path`` (``.npz``, compressed), creating the directory."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {
        "meta": np.array(json.dumps(qp.meta, sort_keys=True)),
        "q": qp.q,
        "l": qp.l,
        "u": qp.u,
    }
    for key, M in (("P", qp.P), ("A", qp.A)):
        M = sp.csc_matrix(M)
        arrays.update(
            {
                f"{key}_data": M.data,
                f"{key}_indices": M.indices.astype(np.int32),
                f"{key}_indptr": M.indptr.astype(np.int32),
                f"{key}_shape": np.array(M.shape, dtype=np.int64),
            }
        )
    if qp.x0 is not None:
        arrays["x0"] = qp.x0
    ctx = qp.context
    if ctx is not None:
        arrays["ctx_separation_rows"] = np.array(ctx.separation_rows, dtype=np.int64)
        arrays["ctx_pair_distance_m"] = np.array(ctx.pair_distance_m)
        arrays.update({f"ctx_{name}": getattr(ctx, name) for name in _CTX_ARRAYS})
    with path.open("wb") as f:
        np.savez_compressed(f, **arrays)
    return path


def load_problem(path: str | Path) -> RecordedQP:
    """Read a problem written by :func:`save_problem` (raises :class:`MPCFormError` if it is not one)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
        meta = json.loads(str(arrays["meta"]))
    except (OSError, ValueError, KeyError) as exc:
        raise MPCFormError(f"{path}: not a recorded QP ({exc})") from exc
    if meta.get("format") != FORMAT or meta.get("version") != VERSION:
        got = f"{meta.get('format')!r} version {meta.get('version')!r}"
        raise MPCFormError(f"{path}: expected format {FORMAT!r} version {VERSION}, got {got}")
    ctx = None
    if "ctx_start_m" in arrays:
        ctx = QPContext(
            int(meta["n"]),
            int(meta["dim"]),
            int(meta["horizon"]),
            (int(arrays["ctx_separation_rows"][0]), int(arrays["ctx_separation_rows"][1])),
            pair_distance_m=float(arrays["ctx_pair_distance_m"]),
            **{name: arrays[f"ctx_{name}"] for name in _CTX_ARRAYS},
        )
    return RecordedQP(
        _csc(arrays, "P"),
        arrays["q"],
        _csc(arrays, "A"),
        arrays["l"],
        arrays["u"],
        meta,
        arrays.get("x0"),
        ctx,
    )


def problem_files(directory: str | Path = DEFAULT_PROBLEMS_DIR) -> list[Path]:
    """The problem files under ``directory`` (``<scenario>/step_*.npz``), sorted by scenario and step."""
    files = sorted(Path(directory).glob("*/step_*.npz"))
    if not files:
        raise MPCFormError(
            f"no recorded problems (*/step_*.npz) in {directory}; run `mpcform problems export`"
        )
    return files


def load_problems(directory: str | Path = DEFAULT_PROBLEMS_DIR) -> list[RecordedQP]:
    """Every problem under ``directory``, sorted by scenario and step."""
    return [load_problem(p) for p in problem_files(directory)]


# ---- recording ------------------------------------------------------------------------------
@dataclass
class RecordingBackend(QPBackend):
    """Delegates to ``inner`` and keeps every problem it is asked to solve, with the warm start,
    the context and the simulation step (set ``step`` from outside, e.g. a progress callback)."""

    inner: QPBackend
    scenario: str = ""
    dt_s: float = 0.0
    step: int = 0
    problems: list[RecordedQP] = field(default_factory=list)

    warm_starts = True  # always record the planner's warm start
    needs_context = True

    def __post_init__(self) -> None:
        self.name, self.options = self.inner.name, self.inner.options
        self._P: sp.csc_matrix | None = None
        self._event = "setup"
        self._context: QPContext | None = None

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        self._P, self._A, self._event = P.copy(), A.copy(), "setup"
        self._q, self._lo, self._hi = q.copy(), lo.copy(), hi.copy()
        self.inner.setup(P, q, A, lo, hi)

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        self._A = self._A.copy()
        self._A.data = A_data.copy()
        self._q, self._lo, self._hi, self._event = q.copy(), lo.copy(), hi.copy(), "update"
        self.inner.update(q, lo, hi, A_data)

    def set_context(self, context: QPContext) -> None:
        self._context = context
        if self.inner.needs_context:
            self.inner.set_context(context)

    def solve(self, x0: Array | None = None) -> QPSolution:
        if self._P is None:
            return self.inner.solve(x0)
        ctx = self._context
        n, dim, horizon = (ctx.n, ctx.dim, ctx.horizon) if ctx is not None else (0, 0, 0)
        meta = {
            "format": FORMAT,
            "version": VERSION,
            "scenario": self.scenario,
            "step": self.step,
            "t_s": self.step * self.dt_s,
            "event": self._event,
            "n": n,
            "dim": dim,
            "horizon": horizon,
            "n_var": int(self._q.shape[0]),
            "n_rows": int(self._lo.shape[0]),
            "nnz_P": int(self._P.nnz),
            "nnz_A": int(self._A.nnz),
            "recorded_with": self.inner.name,
            "mpcform_version": _version(),
        }
        self.problems.append(
            RecordedQP(
                self._P, self._q, self._A, self._lo, self._hi, meta, None if x0 is None else x0.copy(), ctx
            )
        )
        return self.inner.solve(x0 if self.inner.warm_starts else None)


def _version() -> str:
    try:
        return metadata.version("mpcform")
    except metadata.PackageNotFoundError:
        return "0+unknown"


def record_scenario(path: str | Path, solver: str | None = None) -> list[RecordedQP]:
    """Run the scenario at ``path`` closed-loop with the MPC planner and return every QP it solved."""
    from mpcform.run.runner import run_scenario

    scenario = load_scenario(path)
    sparse = as_sparse(scenario.controller.mpc.strategy)
    recorder = RecordingBackend(
        make_backend(solver or sparse.backend, sparse.options), scenario.name, scenario.simulation.dt_s
    )

    def at_step(done: int, total: int) -> None:
        recorder.step = done  # the next step's index

    run_scenario(scenario, controller="mpc", solver=recorder, progress=at_step)
    return recorder.problems


def export_problems(
    scenarios: tuple[str | Path, ...] | list[str | Path] = DEFAULT_SCENARIOS,
    out_dir: str | Path = DEFAULT_PROBLEMS_DIR,
    per_scenario: int = DEFAULT_PER_SCENARIO,
    solver: str | None = None,
) -> list[Path]:
    """Record each scenario and write ``per_scenario`` of its QPs to ``out_dir/<scenario>/``,
    replacing what that directory held: a contiguous sequence (for warm-start replay) from the
    middle of the run, where the swap's conflicts are.

    Every scenario is loaded before the first run, and nothing is written unless each one recorded
    a QP: a scenario whose planner never solved one (every step took the eq. 14 rollout, as no
    separation, obstacle or limit row was ever active) is an error naming it.
    """
    if isinstance(per_scenario, bool) or not isinstance(per_scenario, int) or per_scenario < 1:
        raise ValidationError("--per-scenario", f"expected an integer >= 1, got {per_scenario!r}")
    for path in scenarios:
        try:
            scenario = load_scenario(path)  # per-drone DAQP solves no sparse QP to record:
            name = solver or as_sparse(scenario.controller.mpc.strategy).backend
            check_sparse_solver(scenario.controller.mpc, "controller.solve.kind", name)
        except ScenarioError as exc:
            raise MPCFormError(located_problem(exc, path).text(path)) from None
    kept: list[list[RecordedQP]] = []
    for path in scenarios:
        problems = record_scenario(path, solver)
        if not problems:
            raise MPCFormError(
                f"{path}: no QP to record: the mpc planner never solved one in this run (at every step the "
                "eq. 14 rollout met every row: no separation, obstacle or limit row was active); choose a "
                "scenario whose drones come within reach of d_min, an obstacle or a limit"
            )
        first = max(0, (len(problems) - per_scenario) // 2)
        kept.append(problems[first : first + per_scenario])
    written: list[Path] = []
    for problems in kept:
        target = Path(out_dir) / str(problems[0].meta["scenario"])
        if target.exists():
            shutil.rmtree(target)
        for qp in problems:
            written.append(save_problem(target / f"step_{int(qp.meta['step']):04d}.npz", qp))
    return written
