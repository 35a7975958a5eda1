"""Settings of the receding-horizon QP planner (scenario table ``[controller]`` with kind "mpc")."""

from __future__ import annotations

from dataclasses import dataclass

from mpcform._validate import positive
from mpcform.control.base import FEEDFORWARDS
from mpcform.errors import ValidationError

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
    - ``per_drone`` (decoupled only): solve each drone's block as a small dense QP with DAQP
      (:mod:`mpcform.mpc.per_drone`) instead of one sparse block-diagonal QP with the ``solver``
      (naming another solver is then an error). DAQP solves to 1e-9 row feasibility; of the
      solver settings below only ``max_iter`` applies to it.
    - ``split_iterations`` (decoupled with ``per_drone``): rounds that move each pair row's split
      point from the midpoint towards the joint optimum (:mod:`mpcform.mpc.split`); every round's
      plans meet the joint pair rows, and the rounds converge to the joint QP's optimum
      (0: the midpoint split). ``split_budget_s``: no new round starts after this much wall time
      of a step's solve [s] (None: no limit).
    - ``stalled_split`` (decoupled with ``per_drone``; ignored otherwise): the split rounds of a
      step in which a drone is stalled in conflict (its tie-break escalated,
      :mod:`mpcform.mpc.liveness`), when ``split_iterations`` is 0: the midpoint split jams rings
      of drones that joint-quality splits let pass (0: never).
    - ``grouping``: solve only the groups of drones (connected by pair rows within reach) that
      hold a conflict; the other groups' optimum is their eq. 14 rollout (needs ``fast_path``).
      Equal to the monolithic QP up to solver tolerance.
    - ``fast_path``: return the eq. 14 rollout without a solver call when it meets every row.
    - ``plant_model``: with a ``lag``, ``second_order`` or ``quadrotor`` plant (its hover
      linearisation), write the separation rows on where its velocity loop really takes the drones,
      with the last interval's velocity offset estimated (:mod:`mpcform.mpc.loop`); the cost and
      eq. 14 are unchanged. No effect on the ideal plant.
    - ``eps_abs`` / ``eps_rel`` / ``max_iter`` / ``time_limit_s``: solver tolerances and limits.
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
    per_drone: bool = True
    split_iterations: int = 0
    split_budget_s: float | None = None
    stalled_split: int = 10
    grouping: bool = True
    fast_path: bool = True
    plant_model: bool = True
    eps_abs: float = 1e-4
    eps_rel: float = 1e-4
    max_iter: int = 4000
    time_limit_s: float = 0.0

    @property
    def solves_per_drone(self) -> bool:
        """Whether the planner solves each drone's QP with DAQP (decoupled mode with ``per_drone``)."""
        return self.coupling == "decoupled" and self.per_drone

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
        positive("controller.eps_abs", self.eps_abs)
        positive("controller.eps_rel", self.eps_rel, allow_zero=True)
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, int) or self.max_iter < 1:
            raise ValidationError("controller.max_iter", f"expected an integer >= 1, got {self.max_iter!r}")
        positive("controller.time_limit", self.time_limit_s, allow_zero=True)
        split = self.split_iterations
        if isinstance(split, bool) or not isinstance(split, int) or split < 0:
            raise ValidationError("controller.split_iterations", f"expected an integer >= 0, got {split!r}")
        if split and not self.solves_per_drone:
            raise ValidationError(
                "controller.split_iterations",
                f"expected 0 unless coupling = 'decoupled' with per_drone = true, got {split!r}",
            )
        if self.split_budget_s is not None:
            positive("controller.split_budget", self.split_budget_s)
        stalled = self.stalled_split
        if isinstance(stalled, bool) or not isinstance(stalled, int) or stalled < 0:
            raise ValidationError("controller.stalled_split", f"expected an integer >= 0, got {stalled!r}")


PLANNER_MODES = ("decoupled", "decoupled-sparse", "joint", "monolithic")
"""Named planner configurations (:func:`mode_settings`), as the benchmarks compare them."""
GROUPED_MODES = PLANNER_MODES[:-1]
"""The modes that solve only the conflicted groups of drones (``grouping=True``)."""


def mode_settings(mode: str, horizon: int) -> MPCSettings:
    """Planner settings of a mode of :data:`PLANNER_MODES`, otherwise the defaults:

    - ``decoupled``: decoupled rows, grouping, each conflicted drone's QP solved by DAQP;
    - ``decoupled-sparse``: the same rows as one sparse block-diagonal QP (``per_drone=False``);
    - ``joint``: joint pair rows, grouping;
    - ``monolithic``: joint rows without grouping: one QP over every drone whenever a solve is needed.
    """
    if mode == "monolithic":
        return MPCSettings(horizon=horizon, coupling="joint", grouping=False)
    if mode not in PLANNER_MODES:
        raise ValidationError("mode", f"expected one of {PLANNER_MODES}, got {mode!r}")
    coupling, _, solve = mode.partition("-")
    return MPCSettings(horizon=horizon, coupling=coupling, grouping=True, per_drone=solve != "sparse")
