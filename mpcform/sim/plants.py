"""Plants that turn planned velocity commands into motion, vectorised over n drones in d = 2 or 3.

A plant is reset once, then advanced one control interval at a time:
``advance(command_mps, dt_s, planned_positions_m)`` holds the command over ``[t, t + dt]`` and
returns dense :class:`PlantSamples` with both ends included, so a simulator concatenates them by
dropping the first sample of every interval but the first (:func:`concat_samples`).

Kinds (the velocity each drone reaches in response to its command ``u``):

- ``ideal``: the exact single integrator ``p' = u``; samples are the straight segments
  ``p0 + s u`` with ``s = linspace(0, dt, m + 1)`` (the end is ``p0 + dt u`` bitwise).
- ``lag``: ``v' = (u - v) / tau + c w`` per axis.
- ``second_order``: ``v'' = w_n^2 (u - v) - 2 zeta w_n v'`` per axis (optional separate vertical
  pair ``zeta_z``, ``omega_z``), with the wind force entering ``v'`` directly:
  ``v' = a + c w``, ``a' = w_n^2 (u - v) - 2 zeta w_n a``.
- ``quadrotor``: :class:`mpcform.sim.quadrotor.QuadrotorPlant`.

Wind in the linear plants. They stand for a closed velocity loop identified in still air, so the
still-air drag ``-k v`` is already inside ``tau`` (or ``w_n, zeta``); wind adds the rest of the drag
force ``-k (v - w)``, i.e. the acceleration ``c w`` with ``c = k / m`` [1/s] (default
:data:`DRAG_PER_S`, the cf2x_L250 drag of drone-models, ``0.01471782 kg/s / 0.0319 kg``). For the
lag this is the same as a velocity-command offset ``tau c w`` through the loop; a steady wind
leaves the velocity off by ``tau c w`` (second order: ``2 zeta c w / w_n``), as a loop without
integral action does. Both linear plants are discretised exactly (matrix exponential of the
per-axis system, once per step size) with the wind held over each of the m sub-steps.

Randomness: ``seed`` (int or ``numpy.random.SeedSequence``) gives two child streams, one for the
wind and one for the position noise (``noise_std_m``, added to the end-of-interval
``p_measured_m`` that a planner sees); :meth:`Plant.reset` restarts both.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import expm

from mpcform._validate import Array, dimension, finite_array, positive
from mpcform.errors import ValidationError
from mpcform.sim.wind import Wind, WindField

DRAG_PER_S = 0.01471782 / 0.0319
"""Wind coupling k_drag / m [1/s] of the linear plants: cf2x_L250 (drone-models 0.1.0)."""
KINDS = ("ideal", "lag", "second_order", "quadrotor", "crazyflow")
Loop = tuple[Array, Array, Array, Array, tuple[int, ...]]
"""A continuous velocity loop ``(A, B, E, C, axes)``: ``x' = A x + B u + E w``, ``v = C x``."""
SAMPLES_PER_STEP = 10


@dataclass(frozen=True)
class PlantSamples:
    """Dense samples of one interval (k = sub-steps + 1, both ends) and the end measurement."""

    t_s: Array  # (k,)
    p_true_m: Array  # (k, n, d)
    v_true_mps: Array  # (k, n, d)
    p_measured_m: Array  # (n, d) position at t_s[-1] as the planner sees it (noise added)
    wind_mps: Array | None = None  # (k, n, d) wind in force from each sample on (None: no wind)
    quat_xyzw: Array | None = None  # (k, n, 4) quadrotor attitude
    thrust_N: Array | None = None  # (k, n) quadrotor collective thrust force


def concat_samples(parts: list[PlantSamples]) -> PlantSamples:
    """Join consecutive intervals, dropping each later interval's first (repeated) sample."""
    if not parts:
        raise ValidationError("samples", "expected at least one interval")

    def cat(name: str) -> Array | None:
        arrays = [getattr(s, name) for s in parts]
        if arrays[0] is None:
            return None
        return np.concatenate([arrays[0]] + [a[1:] for a in arrays[1:]])

    return PlantSamples(
        t_s=cat("t_s"),  # type: ignore[arg-type]
        p_true_m=cat("p_true_m"),  # type: ignore[arg-type]
        v_true_mps=cat("v_true_mps"),  # type: ignore[arg-type]
        p_measured_m=parts[-1].p_measured_m,
        wind_mps=cat("wind_mps"),
        quat_xyzw=cat("quat_xyzw"),
        thrust_N=cat("thrust_N"),
    )


class Plant(ABC):
    """Interface of every plant: ``reset`` then ``advance`` once per control interval."""

    kind: str = ""

    def __init__(
        self,
        n: int,
        dim: int,
        *,
        wind: Wind | None = None,
        noise_std_m: float = 0.0,
        seed: int | np.random.SeedSequence = 0,
        samples_per_step: int = SAMPLES_PER_STEP,
    ) -> None:
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValidationError("plant.n", f"expected an integer >= 1, got {n!r}")
        if (
            isinstance(samples_per_step, bool)
            or not isinstance(samples_per_step, int)
            or samples_per_step < 10
        ):
            raise ValidationError(
                "plant.samples_per_step", f"expected an integer >= 10, got {samples_per_step!r}"
            )
        self.n, self.dim = n, dimension("plant.dim", dim)
        if wind is not None and wind.dim != self.dim:
            raise ValidationError("wind.mean", f"expected {self.dim} numbers, got {wind.dim}")
        self.wind = wind
        self.noise_std_m = positive("plant.noise_std", noise_std_m, allow_zero=True)
        self.samples_per_step = samples_per_step
        ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        self._wind_seed, self._noise_seed = ss.spawn(2)
        self.t_s = 0.0
        self._field: WindField | None = None
        self._noise_rng = np.random.default_rng(self._noise_seed)

    def reset(
        self, positions_m: ArrayLike, velocities_mps: ArrayLike | None = None, t0_s: float = 0.0
    ) -> None:
        """Start from ``positions_m`` (n, d) and ``velocities_mps`` (n, d) (None: at rest) at ``t0_s``."""
        p = finite_array("plant.positions", positions_m, (self.n, self.dim))
        v = (
            np.zeros_like(p)
            if velocities_mps is None
            else finite_array("plant.velocities", velocities_mps, (self.n, self.dim))
        )
        self.t_s = float(t0_s)
        self._field = None if self.wind is None else WindField(self.wind, self.n, self._wind_seed)
        self._noise_rng = np.random.default_rng(self._noise_seed)
        self._reset(p, v)

    def advance(
        self, command_mps: ArrayLike, dt_s: float, planned_positions_m: ArrayLike | None = None
    ) -> PlantSamples:
        """Hold ``command_mps`` (n, d) for ``dt_s``; ``planned_positions_m`` (n, d): where the plan
        has the drones at the start of the interval (used by plants with a position loop)."""
        u = finite_array("plant.command", command_mps, (self.n, self.dim))
        dt = positive("plant.dt", dt_s)
        planned = (
            None
            if planned_positions_m is None
            else finite_array("plant.planned_positions", planned_positions_m, (self.n, self.dim))
        )
        t, p, v, extra = self._advance(u, dt, planned)
        self.t_s = float(t[-1])
        meas = p[-1].copy()
        if self.noise_std_m > 0:
            meas += self._noise_rng.normal(0.0, self.noise_std_m, meas.shape)
        return PlantSamples(t_s=t, p_true_m=p, v_true_mps=v, p_measured_m=meas, **extra)

    def displace(self, delta_m: Array) -> None:
        """Move every drone's true position by ``delta_m`` (n, d) [m], velocities kept: a process
        disturbance (the simulation's ``noise``) acting at the end of an interval."""
        self._displace(finite_array("plant.displacement", delta_m, (self.n, self.dim)))

    @property
    def events(self) -> dict[str, object]:
        """What the plant saw happen to the drones, for the run's summary (crazyflow: contacts,
        floor contacts, flips; :mod:`mpcform.sim.crazyflow`); empty for the others."""
        return {}

    @property
    def lost_drones(self) -> Array:
        """Drones that can no longer follow commands (sorted): crazyflow's on the floor or flipped;
        none for the others. The simulation stops planning for them (:meth:`Controller.lose`)."""
        return np.zeros(0, dtype=int)

    @property
    def wind_clip_fraction(self) -> float:
        """Fraction of gust samples so far that the wind's bound clipped (0 without wind)."""
        return 0.0 if self._field is None else self._field.clip_fraction

    def _wind(self, h_s: float, steps: int) -> Array | None:
        return None if self._field is None else self._field.sample_grid(h_s, steps)

    @abstractmethod
    def _reset(self, p: Array, v: Array) -> None: ...

    @abstractmethod
    def _advance(self, u: Array, dt: float, planned: Array | None) -> tuple[Array, Array, Array, dict]: ...

    @abstractmethod
    def _displace(self, delta: Array) -> None: ...

    @abstractmethod
    def velocity_loops(self) -> list[Loop]:
        """Per-axis-group velocity loops at rest in still air (used by the margin)."""


class IdealPlant(Plant):
    """The exact single integrator (no wind: it is the model the planner assumes)."""

    kind = "ideal"

    def __init__(self, n: int, dim: int, **kwargs: object) -> None:
        super().__init__(n, dim, **kwargs)  # type: ignore[arg-type]
        if self.wind is not None:
            raise ValidationError("wind", "the ideal plant is the planner's own model and takes no wind")

    def _reset(self, p: Array, v: Array) -> None:
        self._p = p.copy()

    def _displace(self, delta: Array) -> None:
        self._p = self._p + delta

    def _advance(self, u: Array, dt: float, planned: Array | None) -> tuple[Array, Array, Array, dict]:
        s = np.linspace(0.0, dt, self.samples_per_step + 1)
        p = self._p + s[:, None, None] * u
        self._p = p[-1].copy()
        return self.t_s + s, p, np.broadcast_to(u, p.shape).copy(), {}

    def velocity_loops(self) -> list[Loop]:
        return []


class LinearPlant(Plant):
    """Exactly discretised per-axis linear velocity loop with state (p, v, ...) per axis."""

    def __init__(
        self, n: int, dim: int, groups: list[tuple[Array, Array, Array, tuple[int, ...]]], **kwargs: object
    ) -> None:
        super().__init__(n, dim, **kwargs)  # type: ignore[arg-type]
        kept = [(a, b, e, tuple(x for x in axes if x < self.dim)) for a, b, e, axes in groups]
        self._groups = [g for g in kept if g[3]]
        self._states = self._groups[0][0].shape[0]
        self._cache: dict[float, tuple[Array, Array, Array]] = {}

    def _discrete(self, h: float) -> tuple[Array, Array, Array]:
        """Per-axis ``(Phi (d, s, s), Gu (d, s), Gw (d, s))`` of a step of ``h``, cached."""
        if h not in self._cache:
            s = self._states
            phi, gu, gw = np.empty((self.dim, s, s)), np.empty((self.dim, s)), np.empty((self.dim, s))
            for a, b, e, axes in self._groups:
                m = np.zeros((s + 2, s + 2))
                m[:s, :s], m[:s, s], m[:s, s + 1] = a, b, e
                ex = expm(m * h)
                for ax in axes:
                    phi[ax], gu[ax], gw[ax] = ex[:s, :s], ex[:s, s], ex[:s, s + 1]
            self._cache[h] = (phi, gu, gw)
        return self._cache[h]

    def _reset(self, p: Array, v: Array) -> None:
        self._x = np.zeros((self.n, self.dim, self._states))
        self._x[..., 0], self._x[..., 1] = p, v

    def _displace(self, delta: Array) -> None:
        self._x[..., 0] += delta

    def _advance(self, u: Array, dt: float, planned: Array | None) -> tuple[Array, Array, Array, dict]:
        m = self.samples_per_step
        h = dt / m
        phi, gu, gw = self._discrete(h)
        wind = self._wind(h, m)
        xs = np.empty((m + 1, *self._x.shape))
        xs[0] = self._x
        drive = u[..., None] * gu
        for i in range(m):
            nxt = np.einsum("dij,ndj->ndi", phi, xs[i]) + drive
            if wind is not None:
                nxt += wind[i][..., None] * gw
            xs[i + 1] = nxt
        self._x = xs[-1].copy()
        extra = {} if wind is None else {"wind_mps": np.concatenate([wind, wind[-1:]])}
        t = self.t_s + np.linspace(0.0, dt, m + 1)
        return t, xs[..., 0], xs[..., 1], extra

    def velocity_loops(self) -> list[Loop]:
        out = []
        for a, b, e, axes in self._groups:  # drop the position state: nothing depends on it
            c = np.zeros(a.shape[0] - 1)
            c[0] = 1.0
            out.append((a[1:, 1:], b[1:], e[1:], c, axes))
        return out


def lag_plant(
    n: int, dim: int, tau_s: float, *, drag_per_s: float = DRAG_PER_S, **kwargs: object
) -> LinearPlant:
    """First-order velocity lag ``v' = (u - v) / tau + c w`` (exact under the zero-order hold)."""
    tau = positive("plant.tau", tau_s)
    c = positive("plant.drag_per_s", drag_per_s, allow_zero=True)
    a = np.array([[0.0, 1.0], [0.0, -1.0 / tau]])
    plant = LinearPlant(n, dim, [(a, np.array([0.0, 1.0 / tau]), np.array([0.0, c]), (0, 1, 2))], **kwargs)
    plant.kind = "lag"
    return plant


def second_order_plant(
    n: int,
    dim: int,
    zeta: float,
    omega_rad_s: float,
    *,
    zeta_z: float | None = None,
    omega_z_rad_s: float | None = None,
    drag_per_s: float = DRAG_PER_S,
    **kwargs: object,
) -> LinearPlant:
    """Per-axis ``v'' = w^2 (u - v) - 2 zeta w v'``; ``zeta_z``/``omega_z`` for the vertical axis."""
    c = positive("plant.drag_per_s", drag_per_s, allow_zero=True)

    def group(z: float, w: float, axes: tuple[int, ...]) -> tuple[Array, Array, Array, tuple[int, ...]]:
        a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -w * w, -2.0 * z * w]])
        return a, np.array([0.0, 0.0, w * w]), np.array([0.0, c, 0.0]), axes

    z = positive("plant.zeta", zeta)
    w = positive("plant.omega", omega_rad_s)
    zz = z if zeta_z is None else positive("plant.zeta_z", zeta_z)
    wz = w if omega_z_rad_s is None else positive("plant.omega_z", omega_z_rad_s)
    plant = LinearPlant(n, dim, [group(z, w, (0, 1)), group(zz, wz, (2,))], **kwargs)
    plant.kind = "second_order"
    return plant
