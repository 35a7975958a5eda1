"""A saved run read back from its output directory, plus the formation data the figures need.

``mpcform run`` writes ``trajectory.npz`` and ``summary.json`` (DESIGN.md section 5). The
figures and the exports also need what only the scenario knows: the template offsets (for
the best-fit scale and the formation's edges), the reference's scale and the obstacles.
:func:`write_formation_npz` saves them as ``formation.npz`` beside the contract's files;
without it :func:`load_run` falls back to the reference's start shape (scale then relative to
the start).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.outputs.files import SUMMARY_JSON, TRAJECTORY_NPZ

if TYPE_CHECKING:
    from mpcform.scenario.spec import Scenario

FORMATION_NPZ = "formation.npz"


class RunDirError(ValidationError):
    """A directory that does not hold the output files of a run (names the path)."""


@dataclass(frozen=True, eq=False)
class RunData:
    """The arrays and summary of one saved run.

    ``offsets_m`` (n, d): the template (or, without ``formation.npz``, the reference's start
    shape ``s0 R0 r_i``); ``scale_ref`` (T,): the reference's scale, or None when unknown;
    ``obstacles`` (k, d + 2): centre, radius, clearance (NaN: d_min / 2) of each sphere;
    ``scale_is_relative``: True when the scale is measured relative to the start.
    """

    directory: Path
    t_s: Array  # (T,)
    positions_m: Array  # (T, n, d)
    commands_mps: Array  # (T - 1, n, d)
    reference_m: Array  # (T, n, d)
    summary: dict[str, Any]
    offsets_m: Array
    scale_ref: Array | None
    obstacles: Array
    scale_is_relative: bool

    @property
    def n(self) -> int:
        return int(self.positions_m.shape[1])

    @property
    def dim(self) -> int:
        return int(self.positions_m.shape[2])

    @property
    def name(self) -> str:
        return str(self.summary.get("scenario") or self.directory.name)

    @property
    def d_min_m(self) -> float | None:
        return _limit(self.summary, "d_min")

    @property
    def v_max_mps(self) -> float | None:
        return _limit(self.summary, "v_max")

    @property
    def label(self) -> str:
        """``<scenario> (<controller>[, <solver>])``, for titles and legends."""
        solver = self.summary.get("solver")
        ctrl = str(self.summary.get("controller", "?")) + (f", {solver}" if solver else "")
        return f"{self.name} ({ctrl})"


def formation_arrays(scenario: Scenario, t_s: Array) -> dict[str, Array]:
    """The ``formation.npz`` arrays of ``scenario`` sampled at ``t_s``."""
    k, d = len(scenario.obstacles), scenario.dim
    obstacles = np.full((k, d + 2), np.nan)
    for row, obstacle in zip(obstacles, scenario.obstacles, strict=True):
        row[:d], row[d] = obstacle.center_m, obstacle.radius_m
        if obstacle.clearance_m is not None:
            row[d + 1] = obstacle.clearance_m
    return {
        "offsets": np.array(scenario.template.offsets),
        "scale_ref": np.asarray(scenario.reference.profile(np.asarray(t_s, dtype=float)).scale, dtype=float),
        "obstacles": obstacles,
    }


def write_formation_npz(out_dir: str | Path, scenario: Scenario, t_s: Array) -> Path:
    """Write ``formation.npz`` (offsets (n, d) [m], scale_ref (T,), obstacles (k, d + 2) [m])."""
    path = Path(out_dir) / FORMATION_NPZ
    arrays = formation_arrays(scenario, t_s)
    np.savez_compressed(
        path, offsets=arrays["offsets"], scale_ref=arrays["scale_ref"], obstacles=arrays["obstacles"]
    )
    return path


def load_run(directory: str | Path) -> RunData:
    """Read ``trajectory.npz``, ``summary.json`` and, when present, ``formation.npz``."""
    root = Path(directory)
    if not root.is_dir():
        raise RunDirError(str(root), "no such run directory (write one with `mpcform run --out DIR`)")
    arrays = _npz(root / TRAJECTORY_NPZ, ("t", "p", "u", "p_ref"))
    t, p, u, ref = (arrays[k] for k in ("t", "p", "u", "p_ref"))
    if p.ndim != 3 or p.shape[2] not in (2, 3) or t.shape != (p.shape[0],) or p.shape[0] < 2:
        raise RunDirError(str(root / TRAJECTORY_NPZ), f"expected t (T,) and p (T, n, 2 or 3) with "
                          f"T >= 2, got shapes {t.shape} and {p.shape}")  # fmt: skip
    if u.shape != (p.shape[0] - 1, *p.shape[1:]) or ref.shape != p.shape:
        raise RunDirError(str(root / TRAJECTORY_NPZ), f"expected u (T-1, n, d) and p_ref (T, n, d) for "
                          f"p {p.shape}, got {u.shape} and {ref.shape}")  # fmt: skip
    summary_path = root / SUMMARY_JSON
    try:
        summary = json.loads(summary_path.read_text())
    except FileNotFoundError:
        raise RunDirError(str(summary_path), "missing (write it with `mpcform run --out DIR`)") from None
    except (OSError, ValueError) as exc:
        raise RunDirError(str(summary_path), f"cannot read it as JSON: {exc}") from None
    if not isinstance(summary, dict):
        raise RunDirError(str(summary_path), "expected a JSON object")
    n, d = p.shape[1:]
    formation_path = root / FORMATION_NPZ
    if formation_path.exists():
        extra = _npz(formation_path, ("offsets", "scale_ref", "obstacles"))
        if extra["offsets"].shape != (n, d) or extra["scale_ref"].shape != t.shape:
            raise RunDirError(str(formation_path), f"offsets {extra['offsets'].shape} or scale_ref "
                              f"{extra['scale_ref'].shape} do not match p {p.shape}")  # fmt: skip
        return RunData(root, t, p, u, ref, summary, extra["offsets"], extra["scale_ref"],
                       extra["obstacles"].reshape(-1, d + 2), False)  # fmt: skip
    start_shape = ref[0] - ref[0].mean(axis=0)
    return RunData(root, t, p, u, ref, summary, start_shape, None, np.empty((0, d + 2)), True)


def _npz(path: Path, keys: tuple[str, ...]) -> dict[str, Array]:
    try:
        with np.load(path) as npz:
            missing = [k for k in keys if k not in npz.files]
            if missing:
                raise RunDirError(str(path), f"missing arrays {missing} (has {sorted(npz.files)})")
            return {k: np.asarray(npz[k], dtype=float) for k in keys}
    except FileNotFoundError:
        raise RunDirError(str(path), "missing (write it with `mpcform run --out DIR`)") from None
    except (OSError, ValueError) as exc:
        raise RunDirError(str(path), f"cannot read it as a numpy .npz archive: {exc}") from None


def _limit(summary: dict[str, Any], key: str) -> float | None:
    value = (summary.get("limits") or {}).get(key)
    return None if value is None else float(value)
