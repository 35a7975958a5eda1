"""The time series of one run, from the simulation to the metrics, the files, the figures and the exports.

T samples ``t_s`` [s] of the drones' positions ``positions_m`` and of the reference's desired
positions ``reference_m`` (eq. 13's ``p*_i(t)``), and the T - 1 velocity commands
``commands_mps``, each held over ``[t_j, t_{j+1})`` (zero-order hold). ``simulate`` returns one
(a :class:`~mpcform.sim.simulation.SimulationResult` is a trajectory with its step record), and
``load_run`` reads one back from ``trajectory.npz``.
"""

from __future__ import annotations

from dataclasses import dataclass

from mpcform._validate import Array
from mpcform.errors import ValidationError


@dataclass(frozen=True, eq=False)
class Trajectory:
    """T >= 2 samples of n drones in d = 2 (planar) or 3 (spatial) dimensions (arrays kept as given)."""

    t_s: Array  # (T,)
    positions_m: Array  # (T, n, d)
    commands_mps: Array  # (T - 1, n, d), applied over [t_j, t_{j+1})
    reference_m: Array  # (T, n, d) desired positions p*(t)

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
