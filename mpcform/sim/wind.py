"""Wind for the plants: a mean plus Ornstein-Uhlenbeck gusts, sampled exactly on a time grid.

Per axis the gust ``g`` obeys ``dg = -g / T dt + sigma sqrt(2 / T) dW`` (stationary std ``sigma``,
correlation time ``T``), so over a step ``h`` it is exactly
``g+ = g e^{-h/T} + sigma sqrt(1 - e^{-2h/T}) xi`` with ``xi ~ N(0, 1)``; it starts stationary,
``g_0 ~ N(0, sigma^2)``. The wind seen by a drone is ``mean + clip(g, -bound, bound)``: the OU state
itself is never clipped, and :attr:`WindField.clip_fraction` reports how often the clip was active.
``gust_field = "shared"`` gives every drone the same gust, ``"per_drone"`` independent ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError

GUST_FIELDS = ("per_drone", "shared")


@dataclass(frozen=True, eq=False)
class Wind:
    """Mean wind ``mean_mps`` (d,), gust std ``gust_std_mps`` and correlation time ``gust_time_s``.

    ``gust_bound_mps`` is the per-axis clip of the gust: a number or (d,) numbers, None for the
    default ``3 * gust_std_mps``, ``inf`` for no clipping.
    """

    mean_mps: Array
    gust_std_mps: float = 0.0
    gust_time_s: float = 1.0
    gust_bound_mps: ArrayLike | None = None  # (d,) once built
    gust_field: str = "per_drone"

    def __post_init__(self) -> None:
        mean = finite_array("wind.mean", self.mean_mps, (None,))
        if mean.shape[0] not in (2, 3):
            raise ValidationError("wind.mean", f"expected 2 or 3 numbers, got {mean.tolist()}")
        object.__setattr__(self, "mean_mps", mean)
        object.__setattr__(
            self, "gust_std_mps", positive("wind.gust_std", self.gust_std_mps, allow_zero=True)
        )
        object.__setattr__(self, "gust_time_s", positive("wind.gust_time", self.gust_time_s))
        if self.gust_field not in GUST_FIELDS:
            raise ValidationError(
                "wind.gust_field", f"expected one of {GUST_FIELDS}, got {self.gust_field!r}"
            )
        bound = 3.0 * self.gust_std_mps if self.gust_bound_mps is None else self.gust_bound_mps
        try:
            arr = np.broadcast_to(np.array(bound, dtype=float), mean.shape).copy()
        except (TypeError, ValueError) as exc:
            raise ValidationError(
                "wind.gust_bound", f"expected a number or {mean.shape[0]} numbers >= 0, got {bound!r}"
            ) from exc
        if np.any(np.isnan(arr)) or np.any(arr < 0):
            raise ValidationError("wind.gust_bound", f"expected numbers >= 0 (inf allowed), got {bound!r}")
        object.__setattr__(self, "gust_bound_mps", arr)

    @property
    def dim(self) -> int:
        return int(self.mean_mps.shape[0])

    def speed_bound_mps(self) -> Array:
        """Per-axis bound (d,) on the wind any drone can see: ``|mean| + gust bound`` (inf if unclipped)."""
        bound = np.asarray(self.gust_bound_mps, dtype=float)
        gust = np.where(self.gust_std_mps > 0.0, bound, 0.0)
        return np.abs(self.mean_mps) + gust


class WindField:
    """Samples :class:`Wind` for ``n`` drones on any grid of steps; own ``numpy.random.Generator``."""

    def __init__(self, wind: Wind, n: int, seed: np.random.SeedSequence | int) -> None:
        self.wind = wind
        self.n = n
        rows = 1 if wind.gust_field == "shared" else n
        self._rng = np.random.default_rng(seed)
        self._gust = self._rng.normal(0.0, 1.0, (rows, wind.dim)) * wind.gust_std_mps
        self._clipped = 0
        self._seen = 0

    def current(self) -> Array:
        """The wind (n, d) every drone sees now."""
        w = self.wind
        g = self._gust
        if w.gust_std_mps > 0.0:
            bound = np.asarray(w.gust_bound_mps)
            self._clipped += int(np.count_nonzero(np.abs(g) > bound))
            self._seen += g.size
            g = np.clip(g, -bound, bound)
        return np.broadcast_to(w.mean_mps + g, (self.n, w.dim))

    def advance(self, h_s: float) -> None:
        """Move the gusts on by ``h_s`` seconds (exact OU step)."""
        w = self.wind
        if w.gust_std_mps == 0.0:
            return
        decay = np.exp(-h_s / w.gust_time_s)
        scale = w.gust_std_mps * np.sqrt(-np.expm1(-2.0 * h_s / w.gust_time_s))
        self._gust = self._gust * decay + scale * self._rng.normal(0.0, 1.0, self._gust.shape)

    def sample_grid(self, h_s: float, steps: int) -> Array:
        """Wind (steps, n, d) at the start of each of ``steps`` steps of ``h_s``; ends one step on."""
        out = np.empty((steps, self.n, self.wind.dim))
        for i in range(steps):
            out[i] = self.current()
            self.advance(h_s)
        return out

    @property
    def clip_fraction(self) -> float:
        """Fraction of sampled gust components (time x drones x axes) that the bound clipped."""
        return self._clipped / self._seen if self._seen else 0.0
