"""Undirected communication graphs for the decentralised controllers (seed section 3.8).

A :class:`Graph` is ``n`` drones and a set of undirected edges ``(i, j)``, ``i < j``: drone ``i``
hears drone ``j`` and vice versa. Build one from a named family (:meth:`Graph.complete`,
:meth:`Graph.ring`, :meth:`Graph.path`), from geometry (:meth:`Graph.k_nearest`,
:meth:`Graph.disk`, on template offsets or positions) or from an explicit edge list. The
Laplacian comes from :func:`scipy.sparse.csgraph.laplacian` and connectivity from
:func:`scipy.sparse.csgraph.connected_components`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError

GRAPH_KINDS = ("complete", "ring", "path", "k_nearest", "disk", "explicit")
DENSE_EIG_MAX_N = 2000
"""Up to this many drones the Laplacian spectrum is computed densely (exact)."""

# the scenario key a user changes to connect a graph of each kind
_CONNECTIVITY_FIELD = {"k_nearest": "graph.k", "disk": "graph.radius", "explicit": "graph.edges"}


class DisconnectedGraphWarning(UserWarning):
    """A disconnected graph was accepted with ``allow_disconnected``: consensus cannot be reached."""


@dataclass(frozen=True, eq=False)
class Graph:
    """``n`` drones and undirected ``edges`` (m, 2), stored sorted with ``i < j`` and no duplicates.

    The constructor normalises the edge list (orders each pair, removes repeats) and rejects
    self-loops and indices outside ``[0, n)``. ``kind`` names the family it was built from.
    """

    n: int
    edges: Array
    kind: str = "explicit"

    def __post_init__(self) -> None:
        if isinstance(self.n, bool) or not isinstance(self.n, int | np.integer) or self.n < 1:
            raise ValidationError("graph.n", f"expected an integer number of drones >= 1, got {self.n!r}")
        object.__setattr__(self, "n", int(self.n))
        if self.kind not in GRAPH_KINDS:
            raise ValidationError("graph.kind", f"expected one of {GRAPH_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "edges", _normalised_edges(self.edges, self.n))

    # ---- constructors -----------------------------------------------------------------------
    @classmethod
    def complete(cls, n: int) -> Graph:
        """Every pair of drones communicates (lambda_max(L) = n)."""
        i, j = np.triu_indices(_count(n), 1)
        return cls(n, np.column_stack([i, j]), "complete")

    @classmethod
    def ring(cls, n: int) -> Graph:
        """Drone i talks to i - 1 and i + 1 (mod n); for n = 2 one edge, for n = 1 none."""
        i = np.arange(_count(n))
        return cls(n, np.column_stack([i, (i + 1) % n])[: n if n > 2 else n - 1], "ring")

    @classmethod
    def path(cls, n: int) -> Graph:
        """Drone i talks to i + 1: a chain (the slowest connected graph for consensus)."""
        i = np.arange(_count(n) - 1)
        return cls(n, np.column_stack([i, i + 1]), "path")

    @classmethod
    def k_nearest(cls, points_m: ArrayLike, k: int) -> Graph:
        """Each drone linked to its ``k`` nearest others on ``points_m`` (n, d), symmetrised.

        An edge exists when either end is among the other's k nearest (ties broken by index
        order of the k-d tree), so degrees may exceed k.
        """
        pts = finite_array("graph.points", points_m, (None, None))
        n = pts.shape[0]
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 1 <= k <= max(n - 1, 1):
            raise ValidationError("graph.k", f"expected an integer in [1, n - 1 = {n - 1}], got {k!r}")
        if n == 1:
            return cls(1, np.empty((0, 2), dtype=np.intp), "k_nearest")
        _, idx = cKDTree(pts).query(pts, k=int(k) + 1)
        rows = np.repeat(np.arange(n), int(k) + 1)
        keep = rows != idx.ravel()  # a point is its own nearest; coincident points may swap
        return cls(n, np.column_stack([rows, idx.ravel()])[keep], "k_nearest")

    @classmethod
    def disk(cls, points_m: ArrayLike, radius_m: float) -> Graph:
        """Drones within ``radius_m`` [m] of each other on ``points_m`` (n, d) communicate."""
        pts = finite_array("graph.points", points_m, (None, None))
        radius = positive("graph.radius", radius_m)
        pairs = cKDTree(pts).query_pairs(radius, output_type="ndarray")
        return cls(pts.shape[0], pairs, "disk")

    @classmethod
    def from_edges(cls, n: int, edges: ArrayLike) -> Graph:
        """An explicit undirected edge list of index pairs (m, 2)."""
        return cls(n, edges, "explicit")  # type: ignore[arg-type]

    # ---- structure ----------------------------------------------------------------------------
    @property
    def m(self) -> int:
        """Number of undirected edges."""
        return int(self.edges.shape[0])

    @cached_property
    def adjacency(self) -> sparse.csr_array:
        """Symmetric 0/1 adjacency matrix (n, n), sparse."""
        i, j = self.edges[:, 0], self.edges[:, 1]
        data = np.ones(2 * self.m)
        return sparse.csr_array((data, (np.r_[i, j], np.r_[j, i])), shape=(self.n, self.n))

    @cached_property
    def laplacian(self) -> sparse.csr_array:
        """Graph Laplacian ``L = D - A`` (n, n), sparse (scipy.sparse.csgraph.laplacian)."""
        return sparse.csr_array(csgraph.laplacian(self.adjacency))

    @cached_property
    def degrees(self) -> Array:
        """Number of neighbours of each drone (n,)."""
        return np.asarray(self.adjacency.sum(axis=1)).ravel().astype(np.intp)

    @cached_property
    def directed_edges(self) -> tuple[Array, Array]:
        """Both directions of every edge as ``(source, destination)`` index arrays (2m,)."""
        i, j = self.edges[:, 0], self.edges[:, 1]
        return np.r_[i, j], np.r_[j, i]

    def neighbours(self, i: int) -> Array:
        """Indices of drone ``i``'s neighbours, sorted."""
        return np.sort(self.adjacency.indices[self.adjacency.indptr[i] : self.adjacency.indptr[i + 1]])

    @cached_property
    def laplacian_spectrum(self) -> Array:
        """Eigenvalues of L in ascending order (n,) (dense; exact up to DENSE_EIG_MAX_N drones)."""
        return np.linalg.eigvalsh(self.laplacian.toarray())

    @property
    def lambda_max(self) -> float:
        """Largest Laplacian eigenvalue: sets the discrete stability bound ``dt k lambda_max < 2``."""
        if self.m == 0:
            return 0.0
        if self.n > DENSE_EIG_MAX_N:
            from scipy.sparse.linalg import eigsh

            return float(eigsh(self.laplacian.astype(float), k=1, which="LA", return_eigenvectors=False)[0])
        return float(self.laplacian_spectrum[-1])

    @property
    def algebraic_connectivity(self) -> float:
        """Second-smallest Laplacian eigenvalue lambda_2 (0 when disconnected; dense)."""
        return float(self.laplacian_spectrum[1]) if self.n > 1 else 0.0

    # ---- connectivity -------------------------------------------------------------------------
    @cached_property
    def components(self) -> tuple[Array, ...]:
        """Drone indices of each connected component, ordered by their smallest index."""
        count, labels = csgraph.connected_components(self.adjacency, directed=False)
        return tuple(np.flatnonzero(labels == c) for c in range(count))

    @property
    def is_connected(self) -> bool:
        """Whether every drone can reach every other one over the edges."""
        return len(self.components) == 1

    def check_connected(self, allow_disconnected: bool = False, purpose: str = "consensus") -> None:
        """Raise :class:`ValidationError` (or warn, with ``allow_disconnected``) if disconnected.

        The error names the scenario key that would connect the graph (``graph.radius`` for a
        disk graph, ``graph.k`` for k-nearest, ``graph.edges`` for an explicit list) and lists
        the components.
        """
        if self.is_connected:
            return
        message = (
            f"the {self.kind} communication graph of {self.n} drones is disconnected: "
            f"{len(self.components)} components {describe_components(self.components)}; "
            f"{purpose} cannot agree across components (each settles on its own value and the "
            f"relative positions between components are not controlled)"
        )
        if allow_disconnected:
            warnings.warn(
                f"{message}; running anyway (graph.allow_disconnected)",
                DisconnectedGraphWarning,
                stacklevel=3,
            )
            return
        hint = {"graph.k": "raise k", "graph.radius": "raise the radius", "graph.edges": "add edges"}
        field = _CONNECTIVITY_FIELD.get(self.kind, "graph")
        raise ValidationError(
            field, f"{message}; {hint.get(field, 'add edges')} or set graph.allow_disconnected = true"
        )


def describe_components(components: tuple[Array, ...], limit: int = 8) -> str:
    """``{0, 1, 2}, {3, 4}`` with at most ``limit`` members shown per component."""
    parts = []
    for comp in components:
        shown = ", ".join(str(int(i)) for i in comp[:limit])
        parts.append("{" + shown + (f", ... ({comp.size} drones)" if comp.size > limit else "") + "}")
    return ", ".join(parts)


def _count(n: object) -> int:
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValidationError("graph.n", f"expected an integer number of drones >= 1, got {n!r}")
    return int(n)


def _normalised_edges(edges: object, n: int) -> Array:
    arr = np.asarray(edges if edges is not None else [], dtype=object)
    if arr.size == 0:
        return np.empty((0, 2), dtype=np.intp)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValidationError("graph.edges", f"expected pairs [i, j] of drone indices, got shape {arr.shape}")
    flat = arr.ravel()
    if not all(isinstance(x, int | np.integer) and not isinstance(x, bool) for x in flat):
        raise ValidationError("graph.edges", f"expected integer drone indices, got {arr.tolist()}")
    e = arr.astype(np.intp)
    bad = (e < 0) | (e >= n)
    if bad.any():
        pair = e[np.flatnonzero(bad.any(axis=1))[0]].tolist()
        raise ValidationError("graph.edges", f"edge {pair} names a drone outside [0, {n - 1}]")
    loops = e[:, 0] == e[:, 1]
    if loops.any():
        raise ValidationError("graph.edges", f"edge {e[np.flatnonzero(loops)[0]].tolist()} is a self-loop")
    e = np.unique(np.sort(e, axis=1), axis=0)
    e.setflags(write=False)
    return e
