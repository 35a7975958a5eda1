"""The tables of QP backends: every solver name is looked up here.

:data:`FAMILIES` holds the backends of the planner's sparse QP (``[controller.solve]`` with
``kind = "sparse"``, ``--solver``, ``mpcform solvers``); :data:`PER_DRONE_FAMILIES` those of the
per-drone dense QPs of decoupled mode (``kind = "per_drone"``): ``daqp`` (the default) and
``qpsolvers:<name>``. A new per-drone backend is one module
(:class:`~mpcform.solvers.dense.DenseQPBackend`) and one row there. Sparse solver names:

- ``osqp``, ``piqp``: persistent solver objects (set up once per sparsity pattern, then updated);
- ``qpsolvers:<name>``: any solver installed for qpsolvers, called afresh each step (warm-started
  through ``initvals`` where the wrapper uses it); a solver that needs a positive-definite P
  (quadprog) cannot take this QP, whose P is singular in the position variables;
- ``casadi:<plugin>``: casadi's conic interface with the plugins in
  :data:`~mpcform.solvers.casadi_conic.CASADI_CONIC_PLUGINS` (casadi sets the solver up again on
  every call; never ``highs``, which segfaulted here);
- ``casadi:ipopt``: not a QP solver: ipopt on the exact non-convex separation problem that the
  QP linearises (a quality reference), which needs the problem's meaning (``QPContext``).

Each row of the table is one of these forms: a full name, or a prefix ending in ``:`` followed by
a member (the solver or plugin). A full name is looked up before a prefix (``casadi:ipopt`` before
``casadi:``). The solver packages are imported only when a backend is built or asked whether it
is installed.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from importlib.util import find_spec
from typing import Any

from mpcform.errors import SolverError
from mpcform.solvers.base import QPBackend, SolverOptions
from mpcform.solvers.casadi_conic import CASADI_CONIC_PLUGINS, CASADI_WARM, CasadiConicBackend
from mpcform.solvers.daqp_dense import DaqpBackend
from mpcform.solvers.dense import DenseQPBackend
from mpcform.solvers.exact import CasadiIpoptBackend
from mpcform.solvers.persistent import OSQPBackend, PIQPBackend
from mpcform.solvers.qpsolvers_backend import QPSOLVERS_WARM, QPSolversBackend
from mpcform.solvers.qpsolvers_dense import QPSolversDenseBackend

DEFAULT_SOLVER = "piqp"
"""Chosen on measurements (see README, "Solvers", and ``mpcform bench solvers``): the separation
rows make the QP degenerate for ADMM (OSQP needs hundreds of iterations on swaps and stops at a
loose objective), an interior point needs about 14 and is the fastest solver that succeeds on
every recorded problem at every accuracy."""

QPSOLVERS_KNOWN = (
    "clarabel", "copt", "cvxopt", "daqp", "ecos", "gurobi", "highs", "hpipm", "jaxopt_osqp",
    "kvxopt", "mosek", "nppro", "osqp", "pdhcg", "piqp", "proxqp", "pyqpmad", "qpalm", "qpax",
    "qpoases", "qpswift", "qtqp", "quadprog", "scs", "sip",
)  # fmt: skip # a list of names reads best packed, a dozen to a line
"""Solvers qpsolvers (4.13) can call, installed or not."""
QPSOLVERS_LISTED = ("clarabel", "daqp", "highs", "osqp", "piqp", "proxqp", "quadprog", "scs")
"""qpsolvers solvers always listed by ``mpcform solvers`` (those of the ``solvers`` extra)."""
CASADI_NOTES = {
    "hpipm": "; the QP passed in stage order (not with an acceleration limit)",
    "daqp": "; proximal regularisation (P is singular)",
    "ipqp": "; QR factorisation (P is singular)",
    "qpoases": "; sparse mode",
}
"""What the listing adds about a casadi plugin's settings for this problem class."""
CASADI_INSTALL = "pip install casadi (the PyPI wheels include this plugin)"


@dataclass(frozen=True)
class Family:
    """One row of the registry: the backend named ``key``, or the backends named ``key`` + member
    when ``key`` ends with ``:``. The member of a full name is the name itself.

    ``form``: how an unknown-name error spells the row (``{members}``: the known members);
    ``build(member, options)``: the backend; ``known()``: the members a name may take, installed
    or not; ``listed()``: those ``mpcform solvers`` lists (None: all known); ``installed(member)``;
    ``warm``: the members whose ``solve`` uses ``x0``; ``persistent``: ``update`` is cheaper than
    ``setup``; ``describe(member)``: the listing note of a usable member; ``install``: the hint
    when missing (``{member}`` filled in); ``unsupported``: members that cannot take this problem
    class (P only positive semi-definite), with the reason; ``refused``: members never offered,
    with the reason.
    """

    key: str
    form: str
    build: Callable[[str, SolverOptions], Any]
    known: Callable[[], Sequence[str]]
    installed: Callable[[str], bool]
    warm: Collection[str]
    persistent: bool
    describe: Callable[[str], str]
    install: str
    listed: Callable[[], Sequence[str]] | None = None
    unsupported: Mapping[str, str] = field(default_factory=dict)
    refused: Mapping[str, str] = field(default_factory=dict)

    @property
    def is_prefix(self) -> bool:
        return self.key.endswith(":")

    def full_name(self, member: str) -> str:
        return self.key + member if self.is_prefix else member

    def listed_names(self) -> list[str]:
        return [self.full_name(m) for m in (self.listed or self.known)()]


def _installed(module: str) -> bool:
    return find_spec(module) is not None


def _qpsolvers_available() -> list[str]:
    if not _installed("qpsolvers"):
        return []
    import qpsolvers

    return list(qpsolvers.available_solvers)


def _casadi_has(kind: str, plugin: str) -> bool:
    if not _installed("casadi"):
        return False
    import casadi

    try:
        return bool(casadi.has_conic(plugin) if kind == "conic" else casadi.has_nlpsol(plugin))
    except RuntimeError:
        return False


def _single(backend: type[QPBackend], installed: Callable[[], bool], note: str, install: str) -> Family:
    """The row of one backend class, named, warm-started and persistent as the class says."""
    name = backend.name
    return Family(
        key=name,
        form=name,
        build=lambda _member, options: backend(options),
        known=lambda: (name,),
        installed=lambda _member: installed(),
        warm={name} if backend.warm_starts else set(),
        persistent=backend.persistent,
        describe=lambda _member: note,
        install=install,
    )


def _warm_text(solver: str) -> str:
    return "warm start via initvals" if solver in QPSOLVERS_WARM else "cold"


def _qpsolvers_note(solver: str) -> str:
    return f"qpsolvers, set up every call, {_warm_text(solver)}"


FAMILIES: tuple[Family, ...] = (
    _single(
        OSQPBackend,
        installed=lambda: _installed("osqp"),
        note="persistent ADMM object (update + warm start)",
        install="pip install osqp",
    ),
    _single(
        PIQPBackend,
        installed=lambda: _installed("piqp"),
        note="persistent proximal interior point (update)",
        install="pip install piqp",
    ),
    Family(
        key="qpsolvers:",
        form="qpsolvers:<name> (one of {members})",
        build=QPSolversBackend,
        known=lambda: sorted({*QPSOLVERS_KNOWN, *_qpsolvers_available()}),
        listed=lambda: sorted({*QPSOLVERS_LISTED, *_qpsolvers_available()}),
        installed=lambda solver: solver in _qpsolvers_available(),
        warm=QPSOLVERS_WARM,
        persistent=False,
        describe=_qpsolvers_note,
        install='pip install "qpsolvers[{member}]" (or "mpcform[solvers]")',
        unsupported={
            "quadprog": "needs a positive-definite P; this QP's P is singular in the position variables"
        },
    ),
    Family(
        key="casadi:",
        form="casadi:<plugin> ({members})",
        build=CasadiConicBackend,
        known=lambda: CASADI_CONIC_PLUGINS,
        installed=lambda plugin: _casadi_has("conic", plugin),
        warm=CASADI_WARM,
        persistent=False,
        describe=lambda plugin: f"casadi conic interface, set up every call{CASADI_NOTES.get(plugin, '')}",
        install=CASADI_INSTALL,
        refused={"highs": "casadi's highs plugin segfaulted on this QP class"},
    ),
    _single(
        CasadiIpoptBackend,
        installed=lambda: _casadi_has("nlpsol", "ipopt"),
        note="exact non-convex separation problem (NLP), a quality reference; slow",
        install=CASADI_INSTALL,
    ),
)
"""Every backend family, in the order ``mpcform solvers`` lists them."""
PERSISTENT_SOLVERS = tuple(f.key for f in FAMILIES if f.persistent)
"""The persistent backends' names (``bench mpc`` and ``bench scale`` measure these)."""
DEFAULT_PER_DRONE_SOLVER = "daqp"
"""The per-drone backend of decoupled mode (``PerDroneSolve``): DAQP's dual active set is exact on
these small dense QPs and gives the multipliers the split rounds use."""
PER_DRONE_FAMILIES: tuple[Family, ...] = (
    Family(
        key="daqp",
        form="daqp",
        build=lambda _member, options: DaqpBackend(options.max_iter),
        known=lambda: ("daqp",),
        installed=lambda _member: _installed("daqp"),
        warm={"daqp"},
        persistent=False,
        describe=lambda _member: "dual active set on each drone's dense QP (warm start)",
        install="pip install daqp",
    ),
    Family(
        key="qpsolvers:",
        form="qpsolvers:<name> (one of {members})",
        build=lambda solver, options: QPSolversDenseBackend(solver, options.max_iter),
        known=lambda: sorted({*QPSOLVERS_KNOWN, *_qpsolvers_available()}),
        listed=lambda: sorted({*QPSOLVERS_LISTED, *_qpsolvers_available()}),
        installed=lambda solver: solver in _qpsolvers_available(),
        warm=QPSOLVERS_WARM,
        persistent=False,
        describe=lambda solver: f"qpsolvers on each drone's dense QP to 1e-10, {_warm_text(solver)}",
        install='pip install "qpsolvers[{member}]" (or "mpcform[solvers]")',
    ),
)
"""The per-drone backends (:class:`~mpcform.solvers.dense.DenseQPBackend`), in listing order: one
row per backend family, as :data:`FAMILIES` for the sparse QP."""


@dataclass(frozen=True)
class SolverInfo:
    """One backend as ``mpcform solvers`` lists it.

    ``usable``: installed and able to take this problem class; ``note``: the install hint when
    missing, the reason when unsupported, otherwise what the backend is.
    """

    name: str
    installed: bool
    usable: bool
    warm_start: bool
    persistent: bool
    note: str


def _family(name: str, families: tuple[Family, ...]) -> tuple[Family | None, str]:
    """The row a name falls under (full name first, then prefix) and its member."""
    by_key = {f.key: f for f in families}
    if name in by_key:
        return by_key[name], name
    prefix, colon, member = name.partition(":")
    return by_key.get(prefix + colon) if colon else None, member


def _lookup(name: str, families: tuple[Family, ...] = FAMILIES) -> tuple[Family, str]:
    """The row and member of a known name; raises :class:`SolverError` listing the accepted
    forms, with a did-you-mean hint, for an unknown one."""
    family, member = _family(name, families)
    if family is not None and member in family.known():
        return family, member
    every = [f.full_name(m) for f in families for m in f.known()]
    close = difflib.get_close_matches(name, every, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    why = f"{family.refused[member]}; " if family is not None and member in family.refused else ""
    forms = [f.form.format(members=", ".join(f.known())) for f in families]
    expected = f"{', '.join(forms[:-1])} or {forms[-1]}"
    kind = "per-drone solver" if families is PER_DRONE_FAMILIES else "solver"
    raise SolverError(name, f"unknown {kind}; {why}expected {expected}{hint}")


def check_solver_name(name: str, per_drone: bool = False) -> str:
    """Return ``name`` if it names a backend (installed or not; ``per_drone``: a per-drone one),
    else raise :class:`SolverError` listing the accepted forms, with a did-you-mean hint."""
    _lookup(name, PER_DRONE_FAMILIES if per_drone else FAMILIES)
    return name


def solver_names(per_drone: bool = False) -> list[str]:
    """Every name :func:`solver_infos` lists, in its order."""
    return [name for f in (PER_DRONE_FAMILIES if per_drone else FAMILIES) for name in f.listed_names()]


def solver_info(name: str, per_drone: bool = False) -> SolverInfo:
    """Whether ``name`` is installed and usable here (raises :class:`SolverError` if unknown)."""
    family, member = _lookup(name, PER_DRONE_FAMILIES if per_drone else FAMILIES)
    installed = family.installed(member)
    reason = family.unsupported.get(member)
    if not installed:
        note = "not installed: " + family.install.format(member=member)
    elif reason is not None:
        note = f"unsupported: {reason}"
    else:
        note = family.describe(member)
    usable = installed and reason is None
    return SolverInfo(name, installed, usable, member in family.warm, family.persistent, note)


def solver_infos(per_drone: bool = False) -> list[SolverInfo]:
    """Every backend this package knows: installed or not, usable or not (``mpcform solvers``)."""
    return [solver_info(name, per_drone) for name in solver_names(per_drone)]


def make_backend(name: str, options: SolverOptions) -> QPBackend:
    """The backend called ``name`` (see ``mpcform solvers``).

    Raises :class:`SolverError` for an unknown name, a solver that is not installed (with the
    install hint) or one that cannot take this problem class.
    """
    info = solver_info(name)
    if not info.usable:
        raise SolverError(name, info.note)
    family, member = _lookup(name)
    backend: QPBackend = family.build(member, options)
    return backend


def make_per_drone_backend(name: str, max_iter: int | None) -> DenseQPBackend:
    """The per-drone backend called ``name`` (``daqp`` or ``qpsolvers:<name>``), capped at
    ``max_iter`` iterations a solve; raises :class:`SolverError` as :func:`make_backend`."""
    info = solver_info(name, per_drone=True)
    if not info.usable:
        raise SolverError(name, info.note)
    family, member = _lookup(name, PER_DRONE_FAMILIES)
    backend: DenseQPBackend = family.build(member, SolverOptions(None, None, max_iter))
    return backend
