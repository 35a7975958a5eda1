"""The one table of QP backends (:data:`FAMILIES`): every solver name is looked up here.

Solver names (``--solver``, scenario key ``controller.solver``, ``mpcform solvers``):

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

from mpcform.errors import SolverError
from mpcform.solvers.base import QPBackend, SolverOptions
from mpcform.solvers.casadi_conic import CASADI_CONIC_PLUGINS, CASADI_WARM, CasadiConicBackend
from mpcform.solvers.exact import CasadiIpoptBackend
from mpcform.solvers.persistent import OSQPBackend, PIQPBackend
from mpcform.solvers.qpsolvers_backend import QPSOLVERS_WARM, QPSolversBackend

DEFAULT_SOLVER = "piqp"
"""Chosen on measurements (see README, "Solvers", and ``mpcform bench solvers``): the separation
rows make the QP degenerate for ADMM (OSQP needs hundreds of iterations on swaps and stops at a
loose objective), an interior point needs about 14 and is the fastest solver that succeeds on
every recorded problem at every accuracy."""

QPSOLVERS_KNOWN = (
    "clarabel", "copt", "cvxopt", "daqp", "ecos", "gurobi", "highs", "hpipm", "jaxopt_osqp",
    "kvxopt", "mosek", "nppro", "osqp", "pdhcg", "piqp", "proxqp", "pyqpmad", "qpalm", "qpax",
    "qpoases", "qpswift", "qtqp", "quadprog", "scs", "sip",
)  # fmt: skip
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
    build: Callable[[str, SolverOptions], QPBackend]
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


def _qpsolvers_note(solver: str) -> str:
    warm = "warm start via initvals" if solver in QPSOLVERS_WARM else "cold"
    return f"qpsolvers, set up every call, {warm}"


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
_BY_KEY = {f.key: f for f in FAMILIES}


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


def _family(name: str) -> tuple[Family | None, str]:
    """The row a name falls under (full name first, then prefix) and its member."""
    if name in _BY_KEY:
        return _BY_KEY[name], name
    prefix, colon, member = name.partition(":")
    return _BY_KEY.get(prefix + colon) if colon else None, member


def _lookup(name: str) -> tuple[Family, str]:
    """The row and member of a known name; raises :class:`SolverError` listing the accepted
    forms, with a did-you-mean hint, for an unknown one."""
    family, member = _family(name)
    if family is not None and member in family.known():
        return family, member
    every = [f.full_name(m) for f in FAMILIES for m in f.known()]
    close = difflib.get_close_matches(name, every, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    why = f"{family.refused[member]}; " if family is not None and member in family.refused else ""
    forms = [f.form.format(members=", ".join(f.known())) for f in FAMILIES]
    expected = f"{', '.join(forms[:-1])} or {forms[-1]}"
    raise SolverError(name, f"unknown solver; {why}expected {expected}{hint}")


def check_solver_name(name: str) -> str:
    """Return ``name`` if it names a backend (installed or not), else raise :class:`SolverError`
    listing the accepted forms, with a did-you-mean hint."""
    _lookup(name)
    return name


def solver_names() -> list[str]:
    """Every name :func:`solver_infos` lists, in its order."""
    return [name for f in FAMILIES for name in f.listed_names()]


def solver_info(name: str) -> SolverInfo:
    """Whether ``name`` is installed and usable here (raises :class:`SolverError` if unknown)."""
    family, member = _lookup(name)
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


def solver_infos() -> list[SolverInfo]:
    """Every backend this package knows: installed or not, usable or not (``mpcform solvers``)."""
    return [solver_info(name) for name in solver_names()]


def make_backend(name: str, options: SolverOptions) -> QPBackend:
    """The backend called ``name`` (see ``mpcform solvers``).

    Raises :class:`SolverError` for an unknown name, a solver that is not installed (with the
    install hint) or one that cannot take this problem class.
    """
    info = solver_info(name)
    if not info.usable:
        raise SolverError(name, info.note)
    family, member = _lookup(name)
    return family.build(member, options)
