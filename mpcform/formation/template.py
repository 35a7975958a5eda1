"""Formation templates: centred offsets ``r_i`` of the virtual body (seed section 3.2)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from mpcform._validate import Array, dimension, finite_array, positive
from mpcform.errors import ValidationError, shown
from mpcform.formation.geometry import min_pair_distance

CENTRED_RTOL = 1e-9
COINCIDENT_RTOL = 1e-9
"""Points closer than this times max(1 m, their extent) coincide (:func:`check_distinct`)."""


@dataclass(frozen=True, eq=False)
class Template:
    """Offsets ``r_i`` [m] (shape (n, d), d in {2, 3}) measured from the shape's centroid.

    The constructor rejects offsets whose mean is not zero; use :meth:`centred` to centre
    arbitrary points.
    """

    offsets: Array
    name: str = "explicit"

    def __post_init__(self) -> None:
        r = finite_array("template.offsets", self.offsets, (None, None))
        if r.shape[0] < 1:
            raise ValidationError("template.offsets", "expected at least one drone, got none")
        dimension("template.offsets (number of columns)", r.shape[1])
        mean = r.mean(axis=0)
        size = max(float(np.abs(r).max()), 1.0)
        if np.linalg.norm(mean) > CENTRED_RTOL * size:
            raise ValidationError(
                "template.offsets",
                f"offsets must be centred (sum r_i = 0), but their mean is {mean.tolist()}; "
                "use Template.centred(points) to shift them",
            )
        r.setflags(write=False)
        object.__setattr__(self, "offsets", r)

    @property
    def n(self) -> int:
        """Number of drones."""
        return int(self.offsets.shape[0])

    @property
    def dim(self) -> int:
        """Spatial dimension d (2 planar, 3 spatial)."""
        return int(self.offsets.shape[1])

    def min_distance(self) -> float:
        """Smallest distance between two offsets [m] (inf for one drone); k-d tree, O(n log n)."""
        return min_pair_distance(self.offsets)

    # ---- constructors -------------------------------------------------------------------
    @classmethod
    def centred(cls, points: ArrayLike, name: str = "explicit") -> tuple[Template, Array]:
        """Centre ``points`` (n, d), real, finite and distinct (as a scenario's offsets:
        :func:`check_distinct`): returns the template and the shift that was subtracted."""
        p = finite_array("template.offsets", points, (None, None))
        shift = p.mean(axis=0)
        template = cls(p - shift, name=name)
        check_distinct(template.offsets, "template.offsets")
        return template, shift

    @classmethod
    def polygon(cls, n: int, radius: float = 1.0, dim: int = 2, phase: float = 0.0) -> Template:
        """Regular n-gon of circumradius ``radius`` [m] in the x-y plane, first vertex at ``phase``."""
        n = _count("template.n", n, 1)
        radius = positive("template.radius", radius)
        dim = dimension("template.dim", dim)
        ang = phase + 2.0 * np.pi * np.arange(n) / n
        r = np.zeros((n, dim))
        r[:, 0], r[:, 1] = radius * np.cos(ang), radius * np.sin(ang)
        return cls(_clean(r), name="polygon")

    ring = polygon  # a ring of n drones is the regular polygon of its positions

    @classmethod
    def line(cls, n: int, spacing: float = 1.0, dim: int = 2) -> Template:
        """n drones on the x axis, ``spacing`` [m] apart."""
        n = _count("template.n", n, 1)
        spacing = positive("template.spacing", spacing)
        r = np.zeros((n, dimension("template.dim", dim)))
        r[:, 0] = spacing * (np.arange(n) - (n - 1) / 2.0)
        return cls(r, name="line")

    @classmethod
    def grid(cls, rows: int, cols: int, spacing: float = 1.0, dim: int = 2, layers: int = 1) -> Template:
        """rows x cols (x layers, spatial) lattice with ``spacing`` [m] between neighbours."""
        dim = dimension("template.dim", dim)
        rows, cols = _count("template.rows", rows, 1), _count("template.cols", cols, 1)
        layers = _count("template.layers", layers, 1)
        if dim == 2 and layers != 1:
            raise ValidationError("template.layers", f"a planar grid has one layer, got {layers}")
        spacing = positive("template.spacing", spacing)
        axes = [np.arange(k) - (k - 1) / 2.0 for k in (rows, cols, layers)[:dim]]
        pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
        return cls(spacing * pts, name="grid")

    @classmethod
    def sphere(cls, n: int, radius: float = 1.0) -> Template:
        """n points spread evenly on a sphere of ``radius`` [m] (Fibonacci lattice), centred."""
        n = _count("template.n", n, 2)
        radius = positive("template.radius", radius)
        i = np.arange(n) + 0.5
        z = 1.0 - 2.0 * i / n
        phi = np.pi * (1.0 + 5**0.5) * i
        rho = np.sqrt(1.0 - z * z)
        pts = radius * np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])
        return cls(_clean(pts - pts.mean(axis=0)), name="sphere")


def check_distinct(points_m: Array, field: str, what: str = "offsets") -> None:
    """Raise :class:`ValidationError` naming ``field`` when two rows of ``points_m`` (n, d) are at
    one point, closer than :data:`COINCIDENT_RTOL` times max(1 m, their extent), or all are zero
    (n >= 2): no separation d_min > 0 can hold between them."""
    n = points_m.shape[0]
    if n < 2:
        return
    tol = COINCIDENT_RTOL * max(1.0, float(np.abs(points_m).max()))
    if float(np.abs(points_m).max()) <= tol:
        raise ValidationError(
            field,
            f"all {n} {what} are zero: the drones would share one point, and no "
            "separation d_min > 0 can hold between them",
        )
    dist, idx = cKDTree(points_m).query(points_m, k=2)
    i = int(np.argmin(dist[:, 1]))
    if dist[i, 1] > tol:
        return
    j = int(idx[i, 1] if idx[i, 1] != i else idx[i, 0])
    i, j = min(i, j), max(i, j)
    at = "[" + ", ".join(f"{x:.4g}" for x in points_m[i]) + "]"
    raise ValidationError(
        field,
        f"{what} {i} and {j} coincide at {at} (distance {dist[i, 1]:.3g} m): no separation "
        "d_min > 0 can hold between them; expected distinct points",
    )


def _count(field: str, value: object, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValidationError(field, f"expected an integer >= {minimum}, got {shown(value)}")
    return int(value)


def _clean(r: Array) -> Array:
    """Remove the rounding residue of trigonometric layouts so the mean is exactly ~0."""
    r = r - r.mean(axis=0)
    r[np.abs(r) < 1e-15] = 0.0
    return r
