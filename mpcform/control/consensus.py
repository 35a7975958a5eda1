"""Decentralised scale consensus (seed eq. 20), as printed and in a centroid-preserving variant.

Each drone ``i`` knows its own position and scale estimate ``s_hat_i``, the shared frame
``R(t)`` (the reference's rotation, known to all drones) and the template offsets ``r``; from
its neighbours on the communication :class:`~mpcform.control.graph.Graph` it learns only their
positions relative to its own and their scale estimates. Two position laws (gain ``k``):

- ``eq20`` (as printed): ``u_i = -k sum_j [(p_i - p_j) - s_hat_i R (r_i - r_j)]``. It fixes shape
  and scale but not the centroid: while the estimates disagree (a scale transient)
  ``sum_i u_i = k sum_i s_hat_i R (L r)_i != 0``, so the centroid drifts and stays displaced
  (a ring of 8 doubling its scale with k = gamma = lambda = 1: 0.94 m after 40 s, 1.0 m in
  the limit; the drift scales with k / gamma).
- ``centroid_preserving``: ``u_i = -k sum_j [(p_i - p_j) - R (s_hat_i r_i - s_hat_j r_j)]``; each
  edge term is antisymmetric, so ``sum_i u_i = 0`` and the centroid never moves (with ideal
  links and no saturation). It equals ``eq20`` at consensus.

Scale estimates follow ``s_hat_i' = -gamma sum_j (s_hat_i - s_hat_j) + lambda [i leader]
(s*(t) - s_hat_i)``, where ``s*(t) = reference.state(t).scale`` is the commanded scale (constant,
eq. 16 or any other reference) and only the leaders see it. With a connected graph and at
least one leader, every estimate converges to ``s*`` and relative positions to
``s* R (r_i - r_j)``. The reference's centroid is not used: eq. 20 does not control it.

Discrete time (zero-order hold, forward Euler on the estimates): the disagreement modes are
multiplied by ``1 - dt k lambda_i(L)`` and ``1 - dt lambda_i(gamma L + lambda E)`` per step (E
marks the leaders), so stability needs ``dt k lambda_max(L) < 2`` and
``dt lambda_max(gamma L + lambda E) < 2``; both are checked on construction. They assume
ideal links: delays shrink the stable range, and saturation makes the loop nonlinear.

The controller also models the network, so the simulator stays generic: every step each
drone broadcasts ``(p_i, s_hat_i)``; a message reaches each neighbour ``delay_steps`` steps
later unless it is lost (independently per directed link and step, seeded); a drone keeps
the last value it received from each neighbour. Before the start every drone knows every
neighbour's initial values.
"""

from __future__ import annotations

import warnings
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import pdist

from mpcform._validate import Array, positive
from mpcform.control.base import Controller, ControlStep, StepInfo
from mpcform.control.graph import DENSE_EIG_MAX_N, DisconnectedGraphWarning, Graph, describe_components
from mpcform.control.laws import count_saturated, saturate
from mpcform.errors import ValidationError
from mpcform.formation.kinematics import fit_formation
from mpcform.formation.template import Template
from mpcform.reference.base import Reference

CONSENSUS_LAWS = ("eq20", "centroid_preserving")
RELATIVE_POSITIONS = ("communicated", "sensed")
STABILITY_BOUND = 2.0
"""``dt * gain * lambda_max`` must stay below this (the discrete factor ``1 - x`` stays in (-1, 1))."""


@dataclass(frozen=True)
class ConsensusSettings:
    """Parameters of the consensus controller.

    ``gain_per_s``: formation gain k [1/s]; ``gamma_per_s``: estimate consensus gain [1/s];
    ``leader_gain_per_s``: lambda [1/s] of the leader input ``lambda (s* - s_hat_L)``;
    ``leaders``: drones that see the commanded scale; ``law``: ``eq20`` (as printed) or
    ``centroid_preserving``; ``initial_scale``: every estimate's start value (None: the
    best-fit scale of the positions at reset, i.e. the drones agree on where they start).
    """

    gain_per_s: float = 1.0
    gamma_per_s: float = 1.0
    leader_gain_per_s: float = 1.0
    leaders: tuple[int, ...] = (0,)
    law: str = "eq20"
    initial_scale: float | None = None

    def __post_init__(self) -> None:
        for name, field in (
            ("gain_per_s", "gain"),
            ("gamma_per_s", "gamma"),
            ("leader_gain_per_s", "leader_gain"),
        ):
            object.__setattr__(self, name, positive(f"controller.{field}", getattr(self, name)))
        if self.law not in CONSENSUS_LAWS:
            raise ValidationError("controller.law", f"expected one of {CONSENSUS_LAWS}, got {self.law!r}")
        leaders = tuple(self.leaders) if isinstance(self.leaders, list | tuple | np.ndarray) else None
        if (
            not leaders
            or not all(
                isinstance(i, int | np.integer) and not isinstance(i, bool) and i >= 0 for i in leaders
            )
            or len(set(leaders)) != len(leaders)
        ):
            raise ValidationError(
                "controller.leaders",
                f"expected a non-empty list of distinct drone indices >= 0, got {self.leaders!r}",
            )
        object.__setattr__(self, "leaders", tuple(int(i) for i in leaders))
        if self.initial_scale is not None:
            object.__setattr__(
                self, "initial_scale", positive("controller.initial_scale", self.initial_scale)
            )


@dataclass(frozen=True)
class Network:
    """Link effects between neighbours.

    ``delay_steps``: whole control steps between a broadcast and its delivery (0: same step);
    ``loss_probability``: chance in [0, 1) that one message on one directed link is lost;
    ``seed``: seeds the losses; ``relative_positions``: ``communicated`` (neighbours' positions
    come over the network, delayed and lost like the estimates) or ``sensed`` (measured on
    board, always current; only the scale estimates are communicated).
    """

    delay_steps: int = 0
    loss_probability: float = 0.0
    seed: int = 0
    relative_positions: str = "communicated"

    def __post_init__(self) -> None:
        d = self.delay_steps
        if isinstance(d, bool) or not isinstance(d, int | np.integer) or d < 0:
            raise ValidationError("graph.delay_steps", f"expected an integer >= 0, got {d!r}")
        object.__setattr__(self, "delay_steps", int(d))
        loss = positive("graph.loss_probability", self.loss_probability, allow_zero=True)
        if loss >= 1.0:
            raise ValidationError("graph.loss_probability", f"expected a probability in [0, 1), got {loss!r}")
        object.__setattr__(self, "loss_probability", loss)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int | np.integer) or self.seed < 0:
            raise ValidationError("seed", f"expected an integer >= 0, got {self.seed!r}")
        if self.relative_positions not in RELATIVE_POSITIONS:
            raise ValidationError(
                "graph.relative_positions",
                f"expected one of {RELATIVE_POSITIONS}, got {self.relative_positions!r}",
            )

    @property
    def ideal(self) -> bool:
        """No delay and no loss: every drone uses its neighbours' current values."""
        return self.delay_steps == 0 and self.loss_probability == 0.0


class ConsensusController(Controller):
    """Scale consensus of seed eq. 20 (``law="eq20"``) or its centroid-preserving variant.

    See the module docstring for the laws, the leader input, the stability checks and the
    network model. ``v_max_mps`` saturates each drone's command (eq. 7); a saturated step
    breaks ``sum_i u_i = 0`` of the centroid-preserving law. A disconnected graph raises a
    :class:`~mpcform.errors.ValidationError` unless ``allow_disconnected`` (then it warns).
    After a run, :attr:`scale_estimates` holds the drones' estimates and
    :attr:`messages_lost` / :attr:`messages_sent` count the link outcomes.
    """

    name = "consensus"

    def __init__(
        self,
        reference: Reference,
        graph: Graph,
        dt_s: float,
        settings: ConsensusSettings | None = None,
        v_max_mps: float | None = None,
        network: Network | None = None,
        allow_disconnected: bool = False,
    ) -> None:
        self.reference, self.graph = reference, graph
        self.dt_s = positive("simulation.dt", dt_s)
        self.settings = st = settings or ConsensusSettings()
        self.network = network or Network()
        self.v_max_mps = None if v_max_mps is None else positive("limits.v_max", v_max_mps)
        n = reference.template.n
        if not isinstance(graph, Graph) or graph.n != n:
            got = graph.n if isinstance(graph, Graph) else type(graph).__name__
            raise ValidationError("graph", f"expected a Graph of {n} drones (the template's), got {got}")
        bad = [i for i in st.leaders if i >= n]
        if bad:
            raise ValidationError("controller.leaders", f"drone indices {bad} are outside [0, {n - 1}]")
        graph.check_connected(allow_disconnected)
        self._warn_leaderless()
        self._leader = np.zeros(n)
        self._leader[list(st.leaders)] = 1.0
        self.lambda_max_position, self.lambda_max_scale = self._check_stability()
        self._src, self._dst = graph.directed_edges
        self._estimates = np.empty(0)  # s_hat (n,), set by reset

    # ---- checks -----------------------------------------------------------------------------
    def _warn_leaderless(self) -> None:
        leaders = set(self.settings.leaders)
        orphans = [c for c in self.graph.components if not set(c.tolist()) & leaders]
        if orphans:
            warnings.warn(
                f"components {describe_components(tuple(orphans))} contain no leader: their scale "
                "estimates never see the commanded scale",
                DisconnectedGraphWarning,
                stacklevel=3,
            )

    def _check_stability(self) -> tuple[float, float]:
        st, dt, g = self.settings, self.dt_s, self.graph
        lam_p = g.lambda_max
        x = dt * st.gain_per_s * lam_p
        if x >= STABILITY_BOUND:
            raise ValidationError(
                "controller.gain",
                f"dt * gain * lambda_max(L) = {dt:g} s * {st.gain_per_s:g} /s * {lam_p:.4g} = {x:.4g} "
                f"must be < 2: the discrete update p+ = p - dt k L p multiplies the fastest "
                f"disagreement mode by 1 - {x:.4g} = {1 - x:.4g} each step, so the formation "
                f"{_fate(x)} ({g.kind} graph of {g.n} drones, lambda_max = {lam_p:.4g}); lower the gain "
                f"below {STABILITY_BOUND / (dt * lam_p):.4g} /s, dt below "
                f"{STABILITY_BOUND / (st.gain_per_s * lam_p):.4g} s, or use a sparser graph",
            )
        if g.n <= DENSE_EIG_MAX_N:  # a dense (n, n) matrix only for small swarms
            m = st.gamma_per_s * g.laplacian.toarray() + np.diag(st.leader_gain_per_s * self._leader)
            lam_s = float(np.linalg.eigvalsh(m)[-1])
        else:  # Weyl's bound: lambda_max(A + B) <= lambda_max(A) + lambda_max(B)
            lam_s = st.gamma_per_s * g.lambda_max + st.leader_gain_per_s
        y = dt * lam_s
        if y >= STABILITY_BOUND:
            raise ValidationError(
                "controller.gamma",
                f"dt * lambda_max(gamma L + lambda E) = {dt:g} s * {lam_s:.4g} /s = {y:.4g} must be "
                f"< 2 (gamma = {st.gamma_per_s:g} /s, leader_gain = {st.leader_gain_per_s:g} /s, "
                f"lambda_max(L) = {lam_p:.4g}): the scale estimates' fastest mode is multiplied "
                f"by {1 - y:.4g} each step, so they {_fate(y)}; lower gamma or leader_gain, or dt",
            )
        return lam_p, lam_s

    # ---- state ------------------------------------------------------------------------------
    def reset(self, t_s: float, positions_m: Array) -> None:
        """Start a run: every scale estimate at ``initial_scale`` (default: the best-fit scale of
        ``positions_m``), the link buffers filled with the start, the loss draws reseeded."""
        p = self._check_positions(positions_m)
        s0 = self.settings.initial_scale
        if s0 is None:
            s0 = fit_formation(self.reference.template, p).state.scale  # 1 for a single drone
        s = np.full(self.graph.n, float(s0))
        self._estimates = s
        net = self.network
        self._rng = np.random.default_rng([net.seed, 2])  # independent of the simulation noise
        self._history: deque[tuple[Array, Array]] = deque(
            [(p.copy(), s.copy())] * (net.delay_steps + 1), maxlen=net.delay_steps + 1
        )
        self._recv_pos = p[self._src].copy()  # what dst last heard from src, per directed link
        self._recv_scale = s[self._src].copy()
        self.messages_sent = 0
        self.messages_lost = 0

    @property
    def scale_estimates(self) -> Array:
        """Each drone's current scale estimate ``s_hat_i`` (n,) (a copy)."""
        if self._estimates.size == 0:
            raise ValidationError("controller", "no estimates yet: call reset() or step() first")
        return self._estimates.copy()

    # ---- one step ---------------------------------------------------------------------------
    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        """Exchange positions and estimates over the graph (delayed, lossy), then eq. 20: each drone's
        command from its neighbours' relative positions and its updated scale estimate."""
        p = self._check_positions(positions_m)
        if self._estimates.size == 0:  # step() without reset(): start here
            self.reset(t_s, p)
        s = self._estimates
        q_src, s_src = self._exchange(p, s)
        st, src, dst = self.settings, self._src, self._dst
        goal = self.reference.profile(np.array([t_s], dtype=float))  # R(t), s*(t) known to all
        rr = self.reference.template.offsets @ goal.rotation_body_to_world[0].T  # R r_i
        if st.law == "eq20":
            terms = (p[dst] - q_src) - s[dst, None] * (rr[dst] - rr[src])
        else:
            terms = (p[dst] - q_src) - (s[dst, None] * rr[dst] - s_src[:, None] * rr[src])
        raw = np.zeros_like(p)
        np.add.at(raw, dst, -st.gain_per_s * terms)
        disagreement = np.zeros_like(s)
        np.add.at(disagreement, dst, s[dst] - s_src)
        rate = -st.gamma_per_s * disagreement + st.leader_gain_per_s * self._leader * (goal.scale[0] - s)
        self._estimates = s + self.dt_s * rate
        u = saturate(raw, self.v_max_mps)
        return ControlStep(u, StepInfo("law", saturated=count_saturated(raw, u)))

    def _exchange(self, p: Array, s: Array) -> tuple[Array, Array]:
        """Broadcast ``(p, s_hat)``; return what each directed link's receiver now holds."""
        net, src = self.network, self._src
        self._history.append((p.copy(), s.copy()))
        sent_p, sent_s = self._history[0]  # broadcast delay_steps steps ago
        if net.loss_probability > 0.0:
            arrived = self._rng.random(src.size) >= net.loss_probability
        else:
            arrived = np.ones(src.size, dtype=bool)
        self.messages_sent += int(src.size)
        self.messages_lost += int(src.size - arrived.sum())
        self._recv_pos[arrived] = sent_p[src[arrived]]
        self._recv_scale[arrived] = sent_s[src[arrived]]
        q = p[src] if net.relative_positions == "sensed" else self._recv_pos
        return q, self._recv_scale


def relative_position_error(template: Template, positions_m: Array, scale: float, rotation: Array) -> float:
    """``max_{i<j} ||(p_i - p_j) - s R (r_i - r_j)||`` [m]: distance from the commanded shape and scale."""
    if template.n < 2:
        return 0.0
    deviation = positions_m - scale * template.offsets @ np.asarray(rotation).T
    return float(pdist(deviation).max())


def _fate(x: float) -> str:
    return "oscillates without decaying" if x == STABILITY_BOUND else "oscillates and diverges"
