"""The time series of one run, from the simulation to the metrics, the files, the figures and the exports.

T samples ``t_s`` [s] of the drones' positions ``positions_m`` and of the reference's desired
positions ``reference_m`` (eq. 13's ``p*_i(t)``), and the T - 1 velocity commands
``commands_mps``, each held over ``[t_j, t_{j+1})`` (zero-order hold). ``simulate`` returns one
(a :class:`~mpcform.sim.simulation.SimulationResult` is a trajectory with its step record), and
``load_run`` reads one back from ``trajectory.npz``.

``true`` (a :class:`TrueTrajectory`) holds the plant's dense true motion between the control
samples: K >= 10 (T - 1) + 1 times that include every control sample, the true positions and
velocities, the desired positions at those times and, for the quadrotor, attitude and thrust.
``positions_m`` are what the controller saw (equal to the true positions at the control samples
unless the plant adds measurement noise).

``scale_estimates`` (T, n), for controllers that keep them (consensus, seed eq. 20): each drone's
own scale estimate ``s_hat_i`` at every sample time; None for the others.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from mpcform._validate import Array
from mpcform.errors import ValidationError


@dataclass(frozen=True, eq=False)
class TrueTrajectory:
    """K >= 2 dense samples of the true motion (arrays kept as given; see the module docstring)."""

    t_s: Array  # (K,)
    positions_m: Array  # (K, n, d)
    velocities_mps: Array  # (K, n, d)
    reference_m: Array  # (K, n, d) desired positions p*(t) at t_s
    quat_xyzw: Array | None = None  # (K, n, 4) quadrotor attitude, scalar last
    thrust_N: Array | None = None  # (K, n) quadrotor collective thrust force

    def __post_init__(self) -> None:
        p = self.positions_m
        shapes = [self.velocities_mps.shape, self.reference_m.shape]
        bad = p.ndim != 3 or self.t_s.shape != (p.shape[0],) or p.shape[0] < 2
        if bad or any(s != p.shape for s in shapes):
            raise ValidationError(
                "true trajectory",
                f"expected t_s (K,), positions, velocities and reference (K, n, d) with K >= 2, got "
                f"{self.t_s.shape}, {p.shape}, {shapes[0]} and {shapes[1]}",
            )
        if self.quat_xyzw is not None and self.quat_xyzw.shape != (*p.shape[:2], 4):
            raise ValidationError(
                "true trajectory", f"expected quat_xyzw (K, n, 4), got {self.quat_xyzw.shape}"
            )
        if self.thrust_N is not None and self.thrust_N.shape != p.shape[:2]:
            raise ValidationError("true trajectory", f"expected thrust_N (K, n), got {self.thrust_N.shape}")


@dataclass(frozen=True, eq=False)
class Trajectory:
    """T >= 2 samples of n drones in d = 2 (planar) or 3 (spatial) dimensions (arrays kept as given)."""

    t_s: Array  # (T,)
    positions_m: Array  # (T, n, d)
    commands_mps: Array  # (T - 1, n, d), applied over [t_j, t_{j+1})
    reference_m: Array  # (T, n, d) desired positions p*(t)
    true: TrueTrajectory | None = field(default=None, kw_only=True)
    scale_estimates: Array | None = field(default=None, kw_only=True)  # (T, n) s_hat_i(t_j)

    def __post_init__(self) -> None:
        t, p, u, ref = self.t_s, self.positions_m, self.commands_mps, self.reference_m
        if p.ndim != 3 or p.shape[2] not in (2, 3) or t.shape != (p.shape[0],) or p.shape[0] < 2:
            raise ValidationError(
                "trajectory",
                f"expected t_s (T,) and positions_m (T, n, 2 or 3) with T >= 2, got shapes {t.shape} "
                f"and {p.shape}",
            )
        if u.shape != (p.shape[0] - 1, *p.shape[1:]) or ref.shape != p.shape:
            raise ValidationError(
                "trajectory",
                f"expected commands_mps (T-1, n, d) and reference_m (T, n, d) for positions_m {p.shape}, "
                f"got {u.shape} and {ref.shape}",
            )
        s_hat = self.scale_estimates
        if s_hat is not None and s_hat.shape != p.shape[:2]:
            raise ValidationError(
                "trajectory", f"expected scale_estimates (T, n) = {p.shape[:2]}, got {s_hat.shape}"
            )

    @property
    def n(self) -> int:
        """Number of drones."""
        return int(self.positions_m.shape[1])

    @property
    def dim(self) -> int:
        """2 (planar) or 3 (spatial)."""
        return int(self.positions_m.shape[2])

    @property
    def steps(self) -> int:
        """Number of commands, T - 1."""
        return int(self.commands_mps.shape[0])
