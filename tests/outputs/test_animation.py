"""The flight GIF: planar and spatial runs, the number of frames."""

from __future__ import annotations

from pathlib import Path

import pytest
from saved_runs import short_run

pytest.importorskip("matplotlib")
PIL = pytest.importorskip("PIL.Image")

from mpcform.outputs.animation import ANIMATION_FILE, animate_run  # noqa: E402
from mpcform.outputs.rundata import load_run  # noqa: E402


def test_animation(tmp_path: Path) -> None:
    short_run("swap_planar_8", tmp_path, steps=30)
    path = animate_run(load_run(tmp_path), tmp_path / "plots" / ANIMATION_FILE, max_frames=6)
    with PIL.open(path) as im:
        assert im.format == "GIF" and im.n_frames == 6 and im.size[0] > 200


def test_spatial_animation(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path, steps=10)
    path = animate_run(load_run(tmp_path), tmp_path / "a.gif", max_frames=3)
    with PIL.open(path) as im:
        assert im.n_frames == 3


def test_fewer_samples_than_frames(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path, steps=4)
    with PIL.open(animate_run(load_run(tmp_path), tmp_path / "a.gif")) as im:
        assert im.n_frames == 5  # one frame per sample
