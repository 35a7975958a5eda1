"""Settings of the receding-horizon QP planner (scenario table ``[controller]`` with kind "mpc")."""

from __future__ import annotations

from dataclasses import dataclass

from mpcform._validate import positive
from mpcform.control.base import FEEDFORWARDS
from mpcform.errors import ValidationError
from mpcform.mpc.strategy import PerDroneSolve, SolveStrategy, SparseSolve, check_strategy, default_strategy

VELOCITY_SETS = ("polytope", "box")
COUPLINGS = ("joint", "decoupled")


@dataclass(frozen=True)
class MPCSettings:
    """Horizon, cost and constraint-shaping parameters of :class:`mpcform.MPCPlanner`.

    - ``horizon``: steps H of the plan (H * dt seconds ahead).
    - ``gain_per_s``: k of eq. 14 inside the cost ``sum_j ||u_j - ff_j - k (p*_j - p_j)||^2``.
    - ``feedforward``: ``"jacobian"`` (eq. 14) or ``"secant"``.
    - ``velocity_set``: ``"polytope"`` (``facets`` half-spaces inscribed in the ball; planar:
      a regular polygon, spatial: ``facets`` directions on a Fibonacci sphere; None picks 16
      planar, 32 spatial, which keep 98 % and 89 % of v_max in the worst direction) or
      ``"box"`` (the square or cube inscribed in the ball).
    - ``slack_weight``: exact L1 penalty per metre of separation slack [1/m], plus
      ``slack_quadratic`` [1/m^2] to help the solver's conditioning (keeps exactness).
    - ``margin_m``: separation and obstacle rows are tightened by this much so that the
      certified distance holds despite solver tolerance [m].
    - ``tie_break_rad``: when the eq. 14 rollout breaks a separation row, the desired
      velocities of the drones involved are turned by this angle about the world z axis (to the
      right), so symmetric encounters (antipodal swaps) circulate instead of deadlocking; for a
      drone that stays stalled in conflict the angle grows step by step and is kept while the
      conflict lasts (:mod:`mpcform.mpc.liveness`). It changes nothing when no row is active
      (0 disables).
    - ``coupling``: ``"joint"`` (one row per pair, ``c^T (p_i - p_k) >= d_min``) or
      ``"decoupled"`` (each pair row split into two per-drone rows about the guess's midpoint,
      ``c^T (p_i - m) >= d_min / 2``: slightly more conservative, but the QP is block-diagonal
      per drone, so it scales to large swarms; the same continuous-time guarantee holds).
    - ``solve``: how the rows are solved (:mod:`mpcform.mpc.strategy`): :class:`SparseSolve` (the
      sparse QP with a backend) or, with decoupled rows, :class:`PerDroneSolve` (each drone's dense
      QP, DAQP by default, with its split policy). None: per drone when decoupled, else sparse.
    - ``grouping``: solve only the groups of drones (connected by pair rows within reach) that
      hold a conflict; the other groups' optimum is their eq. 14 rollout (needs ``fast_path``).
      Equal to the monolithic QP up to solver tolerance.
    - ``fast_path``: return the eq. 14 rollout without a solver call when it meets every row.
    - ``plant_model``: with a ``lag``, ``second_order`` or ``quadrotor`` plant (its hover
      linearisation), write the separation rows on where its velocity loop really takes the drones,
      with the last interval's velocity offset ``delta`` estimated and held over the plan, and
      cancel it in the command (offset-free tracking: eq. 14 less a low-pass of ``delta`` when no
      row is active, :mod:`mpcform.mpc.velocity_loop`). No effect on the ideal plant.
    - ``braking``: with a finite ``a_max``, end every plan where the drones can still stop
      (:mod:`mpcform.mpc.constraints.braking`).
    - ``step_budget_s``: the deadline of one step [s] (online planning, :mod:`mpcform.online`):
      no split round starts less than two rounds before its last quarter
      (``pipeline.DEADLINE_RESERVE``, kept for the machine's jitter); a step so cut reports
      ``budget_cut``, the only case in which the machine's load changes a plan. A step that ends past
      the deadline still sends its certified command (reported as a deadline miss), so a tight
      budget slows a swarm but never holds it. None: no deadline.
    """

    horizon: int = 10
    gain_per_s: float = 1.0
    feedforward: str = "jacobian"
    velocity_set: str = "polytope"
    facets: int | None = None
    slack_weight: float = 1e3
    slack_quadratic: float = 10.0
    margin_m: float = 2e-3
    tie_break_rad: float = 0.5
    coupling: str = "joint"
    solve: SolveStrategy | None = None
    grouping: bool = True
    fast_path: bool = True
    plant_model: bool = True
    braking: bool = True
    step_budget_s: float | None = None

    @property
    def strategy(self) -> SolveStrategy:
        """The solve strategy: ``solve``, or the coupling's default (:func:`default_strategy`)."""
        return self.solve or default_strategy(self.coupling)

    @property
    def solves_per_drone(self) -> bool:
        """Whether the planner solves each drone's QP on its own (:class:`PerDroneSolve`)."""
        return isinstance(self.strategy, PerDroneSolve)

    def __post_init__(self) -> None:
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, int) or self.horizon < 1:
            raise ValidationError("controller.horizon", f"expected an integer >= 1, got {self.horizon!r}")
        positive("controller.gain", self.gain_per_s)
        if self.feedforward not in FEEDFORWARDS:
            raise ValidationError(
                "controller.feedforward",
                f"expected one of {FEEDFORWARDS}, got {self.feedforward!r}",
            )
        if self.coupling not in COUPLINGS:
            raise ValidationError(
                "controller.coupling", f"expected one of {COUPLINGS}, got {self.coupling!r}"
            )
        if self.velocity_set not in VELOCITY_SETS:
            raise ValidationError(
                "controller.velocity_set",
                f"expected one of {VELOCITY_SETS}, got {self.velocity_set!r}",
            )
        if self.facets is not None and (
            isinstance(self.facets, bool) or not isinstance(self.facets, int) or self.facets < 4
        ):
            raise ValidationError("controller.facets", f"expected an integer >= 4, got {self.facets!r}")
        positive("controller.slack_weight", self.slack_weight)
        positive("controller.slack_quadratic", self.slack_quadratic, allow_zero=True)
        positive("controller.margin", self.margin_m, allow_zero=True)
        positive("controller.tie_break", self.tie_break_rad, allow_zero=True)
        if not isinstance(self.braking, bool):
            raise ValidationError("controller.braking", f"expected true or false, got {self.braking!r}")
        if self.step_budget_s is not None:
            positive("controller.step_budget", self.step_budget_s)
        check_strategy(self.coupling, self.strategy)


PLANNER_MODES = ("decoupled", "decoupled-sparse", "joint", "monolithic")
"""Named planner configurations (:func:`mode_settings`), as the benchmarks compare them."""
GROUPED_MODES = PLANNER_MODES[:-1]
"""The modes that solve only the conflicted groups of drones (``grouping=True``)."""


def mode_settings(mode: str, horizon: int) -> MPCSettings:
    """Planner settings of a mode of :data:`PLANNER_MODES`, otherwise the defaults:

    - ``decoupled``: decoupled rows, grouping, each conflicted drone's QP solved by DAQP;
    - ``decoupled-sparse``: the same rows as one sparse block-diagonal QP (:class:`SparseSolve`);
    - ``joint``: joint pair rows, grouping;
    - ``monolithic``: joint rows without grouping: one QP over every drone whenever a solve is needed.
    """
    if mode == "monolithic":
        return MPCSettings(horizon=horizon, coupling="joint", grouping=False)
    if mode not in PLANNER_MODES:
        raise ValidationError("mode", f"expected one of {PLANNER_MODES}, got {mode!r}")
    coupling, _, sparse = mode.partition("-")
    solve = SparseSolve() if sparse or coupling == "joint" else PerDroneSolve()
    return MPCSettings(horizon=horizon, coupling=coupling, grouping=True, solve=solve)
