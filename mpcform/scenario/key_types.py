"""The vocabulary of the scenario schema: a key (:class:`Key`) and a table (:class:`Table`), and
the helpers its messages use."""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from mpcform.world.shapes import SHAPES


@dataclass(frozen=True)
class Key:
    """One scenario key.

    ``type``: ``int``, ``float``, ``bool``, ``string``, ``vector`` (d numbers), ``bounds``
    (d numbers, +-inf allowed), ``rotation`` (an angle for d = 2, a rotation vector for
    d = 3), ``points`` (rows of d numbers), ``indices`` (drone indices) or ``pairs`` (pairs
    of drone indices), ``table`` (an inline table, checked by its user) or ``tables`` (an
    array of tables). ``when`` lists the values of the table's
    selector key (``shape`` or ``kind``) the key applies to (empty: always). ``bound`` is a
    lower bound of numbers (``"> 0"``, ``">= 1"``). ``shown_default`` replaces the default in
    the docs.
    """

    name: str
    type: str
    doc: str
    unit: str = ""
    default: Any = None
    required: bool = False
    when: tuple[str, ...] = ()
    choices: tuple[Any, ...] = ()
    bound: str = ""
    shown_default: str | None = None
    inf: bool = False
    """A float key that also takes ``inf`` (meaning: no bound)."""
    names: tuple[str, ...] = ()
    """A float key that also takes one of these names (``limits.downwash = "crazyswarm"``)."""

    @property
    def bound_text(self) -> str:
        """The bound as a suffix of a type's text (``" > 0"``), or ``""``."""
        return f" {self.bound}" if self.bound else ""

    def within_bound(self, x: float) -> bool:
        """Whether the number ``x`` meets ``bound`` (always, when there is none)."""
        if not self.bound:
            return True
        op, low = self.bound.split()
        return x > float(low) if op == ">" else x >= float(low)


@dataclass(frozen=True)
class Table:
    """A scenario table (``""``: the top level); ``selector`` names the key choosing a variant."""

    name: str
    doc: str
    keys: tuple[Key, ...]
    required: bool = True
    selector: str | None = None
    array: bool = False

    def key(self, name: str) -> Key:
        """The key called ``name`` (it must exist)."""
        return next(k for k in self.keys if k.name == name)

    @property
    def title(self) -> str:
        """The table as TOML writes its header (``[limits]``, ``[[obstacles]]``; ``Top level``)."""
        if not self.name:
            return "Top level"
        return f"[[{self.name}]]" if self.array else f"[{self.name}]"


def listing(values: tuple[Any, ...], quote: str = "'") -> str:
    """``values`` as a comma-separated list, each quoted (for messages and the key reference)."""
    return ", ".join(f"{quote}{v}{quote}" for v in values)


def did_you_mean(word: str, choices: Iterable[object]) -> str:
    """``"; did you mean 'x'?"`` for the closest of ``choices`` to a misspelt ``word``, else ``""``."""
    close = difflib.get_close_matches(word, [str(c) for c in choices], n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def obstacle_keys() -> tuple[Key, ...]:
    """The keys of ``[[obstacles]]``: ``shape`` (the kind, ``sphere`` by default), then every kind's
    keys (:data:`mpcform.world.shapes.SHAPES`), each applying to the kinds that have it."""
    kinds = tuple(SHAPES)
    docs = "; ".join(f"`{k}`: {SHAPES[k].summary}" for k in kinds)
    keys = [Key("shape", "string", f"The obstacle's kind ({docs}).", default=kinds[0], choices=kinds)]
    seen: dict[str, list[str]] = {}
    spec: dict[str, Any] = {}
    for kind, cls in SHAPES.items():
        for key in cls.keys:
            seen.setdefault(key.name, []).append(kind)
            spec.setdefault(key.name, key)
    for name, where in seen.items():
        k = spec[name]
        keys.append(
            Key(
                name,
                k.type,
                k.doc,
                k.unit,
                k.default,
                required=k.required,
                when=() if len(where) == len(kinds) else tuple(where),
                bound=k.bound,
                shown_default=k.shown_default,
                inf=k.inf,
            )
        )
    return tuple(keys)
