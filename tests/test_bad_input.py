"""Seeded generators of bad input (slow).

Bad scenario documents: each bundled scenario with one to three of its keys given a wrong type, a
value out of range, NaN or inf, a huge size, removed, or joined by an unknown key.
``validate``'s checker (``check_document``, what ``mpcform validate`` runs on the parsed TOML)
must answer every case with problems or a valid scenario within 10 s, never with an exception
escaping it (a traceback on the command line) and never using more than 1 GiB.

Bad files on disk (issue 58): a scenario path, a saved run's file or ``--out`` that is a file of
1 GiB virtual size (sparse), a device, a FIFO, a dangling or looping symbolic link or a directory;
a saved run with a NaN or an infinity in one of its arrays (or one cut to a wrong shape); a user's
file, directory, symbolic link or FIFO at a name that ``run``, ``plot``, ``export`` or ``view``
writes. The command (``main(argv)``) must answer each with one error line naming the path, exit
status 2, within 20 s and 1 GiB, and leave the user's files as they were."""

from __future__ import annotations

import copy
import os
import resource
import shutil
import signal
import tomllib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mpcform.outputs.outdir import RUN_LAYOUT

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


# ---- bad files on disk: giants, devices, symlinks, output names taken, NaN-laden saved runs ----
FILE_SEED, FILE_CASES, FILE_TIME_LIMIT_S = 5858, 600, 20
WORKED = Path(__file__).resolve().parents[1] / "scenarios" / "worked_example.toml"
DEVICES = ("/dev/zero", "/dev/urandom", "/dev/null")
RUN_ARRAYS = {
    "trajectory.npz": ("t", "p", "u", "p_ref", "t_true", "p_true", "v_true", "p_ref_true"),
    "formation.npz": ("offsets", "scale_ref", "obstacles"),
}
WRITTEN = {"run": None, "plot": "plots", "export": "export", "view": "viewer.html"}
"""The commands writing into a run directory, and the name each writes (``run``: all of them)."""
COMMANDS = {
    "plot": ["plot"],
    "view": ["view"],
    "export": ["export", "--allow-untracked", "--no-flight-check"],
    "compare": ["compare", "--no-figure"],
}


def make_full_run(root: Path) -> Path:
    """A short run with everything mpcform writes into its directory (data, figures, viewer, export)."""
    from mpcform.cli.main import main

    root.mkdir(parents=True, exist_ok=True)
    scenario = root / "scenario.toml"
    scenario.write_text(WORKED.read_text().replace("duration = 10.0", "duration = 0.4"))
    argv = ["run", str(scenario), "--out", str(root / "run"), "--plot", "--html", "--export"]
    assert main([*argv, "--allow-untracked", "--no-flight-check"]) == 0
    return root / "run"


def _bad_thing(path: Path, rng: np.random.Generator) -> str:
    """Put something bad at ``path`` (a file of 1 GiB virtual size, a device, a FIFO, a symbolic
    link dangling, looping or to a device, a directory); its class."""
    kind = ["sparse", "device", "fifo", "dangling", "loop", "directory"][int(rng.integers(6))]
    if kind == "sparse":
        with open(path, "wb") as f:
            f.truncate(2**30)
    elif kind == "device":
        path.symlink_to(DEVICES[int(rng.integers(len(DEVICES)))])
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "dangling":
        path.symlink_to(path.parent / "gone")
    elif kind == "loop":
        path.symlink_to(path)
    else:
        path.mkdir()
        (path / "mine.txt").write_text("the user's")
    return kind


def _nan_laden(run: Path, rng: np.random.Generator) -> tuple[Path, str]:
    """One array of the saved run given a NaN or an infinity (or cut to a wrong shape)."""
    name = ["trajectory.npz", "formation.npz"][int(rng.integers(2))]
    with np.load(run / name) as npz:
        arrays = {k: np.array(npz[k]) for k in npz.files}
    keys = [k for k in RUN_ARRAYS[name] if k in arrays and arrays[k].size]
    key = keys[int(rng.integers(len(keys)))]
    value = arrays[key].astype(float)
    if rng.random() < 0.2 and value.ndim >= 2:
        arrays[key] = value[..., :1]
        what = f"{name}: {key} cut to {arrays[key].shape}"
    else:
        flat = value.reshape(-1) if key != "obstacles" else value[:, :-1].reshape(-1)  # NaN clearance: unset
        flat[int(rng.integers(flat.size))] = [np.nan, np.inf, -np.inf][int(rng.integers(3))]
        if key == "obstacles":
            value[:, :-1] = flat.reshape(value.shape[0], -1)
        arrays[key] = value
        what = f"{name}: a non-finite value in {key}"
    np.savez(run / name, **arrays)
    return run / name, what


def file_case(index: int, base: Path, work: Path) -> tuple[list[str], str, Path | None, str]:
    """Case ``index`` set up under ``work`` (a copy of the saved run ``base`` when it needs one):
    the argv, what the one error line must name, the tree that must survive (None: none), and what
    the case is."""
    rng = np.random.default_rng([FILE_SEED, index])
    family = ["scenario", "saved", "saved", "names", "names", "out"][int(rng.integers(6))]
    if family == "scenario":  # validate or run a scenario path that is not a small regular file
        path = work / "scenario.toml"
        kind = _bad_thing(path, rng)
        command = ["validate"] if rng.random() < 0.5 else ["run", "--out", str(work / "o")]
        return [command[0], str(path), *command[1:]], str(path), None, f"scenario: {kind}"
    run = work / "run"
    shutil.copytree(base, run, symlinks=True)
    if family == "saved":  # a saved run that must be refused as it is read back
        command = list(COMMANDS)[int(rng.integers(len(COMMANDS)))]
        if rng.random() < 0.6:
            path, what = _nan_laden(run, rng)
        else:
            path = run / ["trajectory.npz", "formation.npz", "summary.json"][int(rng.integers(3))]
            path.unlink()
            what = f"{path.name}: {_bad_thing(path, rng)}"
        return [COMMANDS[command][0], str(run), *COMMANDS[command][1:]], str(path), None, f"{command} {what}"
    if family == "names":  # a user's file, directory, link or FIFO where mpcform writes
        command = list(WRITTEN)[int(rng.integers(len(WRITTEN)))]
        names = [n for n in (*RUN_LAYOUT, "plots/top_view.png", "plots/mine.png", "export/fly.py")]
        names = [n for n in names if WRITTEN[command] in (None, n.split("/")[0])]
        name = names[int(rng.integers(len(names)))]
        path = run / name
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)
        kind = ["file", "directory", "symlink", "fifo"][int(rng.integers(4))]
        if kind == "file":
            path.write_text("the user's own, " + "x" * int(rng.integers(100)))
        elif kind == "directory":
            path.mkdir()
            (path / "mine.txt").write_text("the user's")
        elif kind == "symlink":
            (work / "mine").mkdir()
            (work / "mine" / "photo.png").write_text("the user's")
            path.symlink_to(work / "mine")
        else:
            os.mkfifo(path)
        argv = [command, str(run)]
        if command == "run":
            argv = ["run", str(base.parent / "scenario.toml"), "--out", str(run)]
        elif command == "export":
            argv += ["--allow-untracked", "--no-flight-check"]
        return argv, str(path), work, f"{command} over a user's {kind} {name}"
    out = work / "out"  # --out itself bad
    kind = _bad_thing(out, rng)
    if kind == "directory":
        kind = "a user's directory"
    return ["run", str(base.parent / "scenario.toml"), "--out", str(out)], str(out), work, f"--out: {kind}"


def _tree(root: Path) -> dict[str, Any]:
    """What is under ``root`` (not following links; mpcform's lock and manifest aside)."""
    found: dict[str, Any] = {}
    for dirpath, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(dirpath) / name
            if name in (".mpcform.lock", ".mpcform-manifest.json"):
                continue
            info = path.lstat()
            content = (
                path.read_bytes()
                if path.is_file() and not path.is_symlink() and info.st_size < 2**20
                else None
            )
            found[str(path)] = (info.st_mode, info.st_size, content)
    return found


def check_file_case(args: tuple[int, str]) -> str | None:
    """None when the command answers file case ``index`` with one error line naming the path, in
    time and memory, leaving the user's files as they were; else what went wrong."""
    import contextlib
    import io
    import tempfile

    from mpcform.cli.main import main

    index, base = args
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        argv, names, keep, what = file_case(index, Path(base), work)
        before = _tree(keep) if keep is not None else None
        err = io.StringIO()
        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        with open("/proc/self/statm") as statm:
            now = int(statm.read().split()[0]) * resource.getpagesize()
        resource.setrlimit(resource.RLIMIT_AS, (now + MEMORY_LIMIT, hard))
        signal.signal(signal.SIGALRM, _alarm)
        signal.alarm(FILE_TIME_LIMIT_S)
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                status = main(argv)
        except BaseException as exc:  # noqa: BLE001 - every escape is the finding
            return f"case {index} ({what}): {type(exc).__name__}: {str(exc)[:200]}"
        finally:
            signal.alarm(0)
            resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
        lines = err.getvalue().strip().splitlines()
        line = lines[-1] if lines else ""
        if status != 2 or len(lines) != 1 or not line.startswith("mpcform: error: "):
            return f"case {index} ({what}): status {status}, stderr {err.getvalue()[:300]!r}"
        if names not in line or "Errno" in line:
            return f"case {index} ({what}): the line does not name {names}: {line[:300]}"
        if keep is not None and _tree(keep) != before:
            return f"case {index} ({what}): the user's files changed"
    return None


@pytest.mark.alone
def test_bad_files_get_one_line_and_the_users_files_survive(tmp_path: Path) -> None:
    """Scenario paths and saved runs that are giants, devices, FIFOs, links or directories; NaN-laden
    saved runs; a user's files at every name mpcform writes; a bad --out: one line, exit 2."""
    pytest.importorskip("matplotlib")
    base = make_full_run(tmp_path)
    with ProcessPoolExecutor(2) as pool:
        failures = [f for f in pool.map(check_file_case, [(k, str(base)) for k in range(FILE_CASES)]) if f]
    assert not failures, "\n".join(failures)


def test_the_file_generator_covers_every_class(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    base = make_full_run(tmp_path / "base")
    seen = set()
    for k in range(FILE_CASES):
        work = tmp_path / f"case{k}"
        work.mkdir()
        seen.add(file_case(k, base, work)[3].split(":")[0].split(" ")[0])
        shutil.rmtree(work)
    assert seen >= {"scenario", "plot", "view", "export", "compare", "run", "--out"}
