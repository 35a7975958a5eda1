"""A seeded generator of bad scenario files (slow): each bundled scenario with one to three of its
keys given a wrong type, a value out of range, NaN or inf, a huge size, removed, or joined by an
unknown key. ``validate``'s checker (``check_document``, what ``mpcform validate`` runs on the
parsed TOML) must answer every case with problems or a valid scenario within 10 s, never with an
exception escaping it (a traceback on the command line) and never using more than 1 GiB."""

from __future__ import annotations

import copy
import resource
import signal
import tomllib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytestmark = pytest.mark.slow
SCENARIOS = sorted((Path(__file__).resolve().parents[1] / "scenarios").glob("*.toml"))
SEED, CASES, TIME_LIMIT_S, MEMORY_LIMIT = 3838, 1000, 10, 2**30
BAD_VALUES: list[Any] = [
    "x",
    True,
    -1,
    0,
    1,
    -1.0e308,
    1.0e308,
    float("nan"),
    float("inf"),
    -float("inf"),
    1_000_000_000,
    2**62,
    [],
    [0.0] * 1000,
    [[1.0e300, 0.0], [-1.0e300, 0.0]],
    {},
    {"x": 1},
]


def leaves(node: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every key path of a TOML document (tables, arrays of tables, values)."""
    out = [path] if path else []
    if isinstance(node, dict):
        for key, value in node.items():
            out += leaves(value, (*path, key))
    elif isinstance(node, list) and node and isinstance(node[0], dict | list):
        for k, value in enumerate(node[:3]):
            out += leaves(value, (*path, k))
    return out


def bad_document(index: int) -> dict[str, Any]:
    """Case ``index``: a bundled scenario with 1-3 mutations (replace, remove, add an unknown key)."""
    rng = np.random.default_rng([SEED, index])
    original = tomllib.loads(SCENARIOS[int(rng.integers(len(SCENARIOS)))].read_text())
    doc, count = copy.deepcopy(original), int(rng.integers(1, 4))
    while count > 0 or doc == original:  # (a value replaced by an equal one is no mutation)
        count -= 1
        paths = leaves(doc)
        path = paths[int(rng.integers(len(paths)))]
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        action = rng.random()
        if action < 0.75 or isinstance(parent, list):
            parent[path[-1]] = copy.deepcopy(BAD_VALUES[int(rng.integers(len(BAD_VALUES)))])
        elif action < 0.9:
            del parent[path[-1]]
        else:
            parent["bogus_key"] = 1.0
    return doc


def _alarm(signum: int, frame: Any) -> None:
    raise TimeoutError(f"no answer within {TIME_LIMIT_S} s")


def check_case(index: int) -> str | None:
    """None when the checker answers case ``index`` in time and memory; else what went wrong."""
    from mpcform.scenario.check import check_document

    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/statm") as statm:
        now = int(statm.read().split()[0]) * resource.getpagesize()
    resource.setrlimit(resource.RLIMIT_AS, (now + MEMORY_LIMIT, hard))
    signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(TIME_LIMIT_S)
    try:
        check_document(bad_document(index), f"bad_{index}")
    except BaseException as exc:  # noqa: BLE001 - every escape is the finding
        return f"case {index}: {type(exc).__name__}: {str(exc)[:200]}"
    finally:
        signal.alarm(0)
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
    return None


@pytest.mark.alone
def test_bad_scenario_files_get_problems_in_time_and_memory() -> None:
    with ProcessPoolExecutor(2) as pool:
        failures = [f for f in pool.map(check_case, range(CASES)) if f is not None]
    assert not failures, "\n".join(failures)


def test_the_generator_mutates_every_case() -> None:
    originals = [tomllib.loads(p.read_text()) for p in SCENARIOS]
    assert all(bad_document(k) not in originals for k in range(50))
