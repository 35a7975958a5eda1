"""The flight video: frames at the real-time factor (GIF frame durations read back with PIL), the
frame cap, the progress callback, planar and spatial runs, MP4 only with ffmpeg."""

from __future__ import annotations

from pathlib import Path

import pytest
from saved_runs import short_run

pytest.importorskip("matplotlib")
PIL = pytest.importorskip("PIL.Image")

from matplotlib.animation import FFMpegWriter  # noqa: E402

from mpcform.errors import ValidationError  # noqa: E402
from mpcform.outputs.animation import ANIMATION_FILE, animate_run, animation_file, frame_times  # noqa: E402
from mpcform.outputs.rundata import load_run  # noqa: E402


def gif_durations_ms(path: Path) -> list[int]:
    with PIL.open(path) as im:
        assert im.format == "GIF"
        durations = []
        for k in range(im.n_frames):
            im.seek(k)
            durations.append(int(im.info["duration"]))
        return durations


@pytest.mark.parametrize("speed", [1.0, 4.0])
def test_gif_lasts_as_long_as_the_flight_at_the_chosen_speed(tmp_path: Path, speed: float) -> None:
    short_run("swap_planar_8", tmp_path, steps=60)  # 3 s of flight
    run = load_run(tmp_path)
    flight_s = float(run.trajectory.t_s[-1] - run.trajectory.t_s[0])
    calls: list[tuple[int, int]] = []
    path = animate_run(run, tmp_path / "plots" / ANIMATION_FILE, speed=speed,
                       progress=lambda done, total: calls.append((done, total)))  # fmt: skip
    durations = gif_durations_ms(path)
    frame_ms = durations[0]
    assert len(set(durations)) == 1
    assert abs(sum(durations) / 1000 - flight_s / speed) <= frame_ms / 1000 + 1e-9
    assert calls[-1] == (len(durations), len(durations)) and len(calls) == len(durations)


def test_a_long_flight_keeps_its_duration_under_the_frame_cap(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path, steps=100)
    run = load_run(tmp_path)
    flight_s = float(run.trajectory.t_s[-1] - run.trajectory.t_s[0])
    durations = gif_durations_ms(animate_run(run, tmp_path / "a.gif", max_frames=8))
    assert len(durations) <= 8 and durations[0] > 100  # fewer frames per second, not a shorter video
    assert abs(sum(durations) / 1000 - flight_s) <= durations[0] / 1000


def test_frame_times() -> None:
    times, fps = frame_times(0.0, 20.0, speed=1.0, fps=10, max_frames=300)
    assert fps == 10 and len(times) == 201 and times[-1] == pytest.approx(20.0)
    times, fps = frame_times(0.0, 20.0, speed=2.0, fps=10, max_frames=300)
    assert fps == 10 and len(times) == 101 and times[1] == pytest.approx(0.2)
    times, fps = frame_times(0.0, 100.0, speed=1.0, fps=10, max_frames=300)
    assert fps == 2 and len(times) == 201
    with pytest.raises(ValidationError, match="speed"):
        frame_times(0.0, 1.0, speed=0.0)


def test_spatial_animation_in_two_projections(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path, steps=10)
    run = load_run(tmp_path)
    path = animate_run(run, tmp_path / "a.gif")
    with PIL.open(path) as im:  # 10 frames/s; two panels side by side
        assert im.n_frames == round(10 * run.trajectory.t_s[-1]) + 1 and im.size[0] > im.size[1]


def test_mp4_needs_ffmpeg(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path, steps=4)
    if FFMpegWriter.isAvailable():
        assert animation_file() == "flight.mp4"
        assert animate_run(load_run(tmp_path), tmp_path / "a.mp4").stat().st_size > 1000
    else:
        assert animation_file() == ANIMATION_FILE
        with pytest.raises(ValidationError, match="ffmpeg"):
            animate_run(load_run(tmp_path), tmp_path / "a.mp4")
