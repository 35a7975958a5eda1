"""The flight video: frames at the real-time factor (GIF frame durations read back with PIL, MP4
durations with ffprobe), the frame cap, the progress callback, planar and spatial runs, MP4 only
with ffmpeg.

The MP4 tests need ffmpeg and ffprobe (Debian: ``apt-get install ffmpeg``); without them they skip,
unless ``MPCFORM_REQUIRE_BROWSER=1`` (set by ``.ci/run``), where they fail.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from saved_runs import SCENARIOS, short_run, shortened

pytest.importorskip("matplotlib")
PIL = pytest.importorskip("PIL.Image")

from matplotlib.animation import FFMpegWriter  # noqa: E402

from mpcform.errors import ValidationError  # noqa: E402
from mpcform.outputs.animation import (  # noqa: E402
    ANIMATION_FILE,
    MP4_FILE,
    FlightScene,
    animate_run,
    animation_file,
    frame_times,
)
from mpcform.outputs.drawing import closest_pair  # noqa: E402
from mpcform.outputs.rundata import load_run  # noqa: E402
from mpcform.run.runner import run_scenario  # noqa: E402
from mpcform.scenario.load import load_scenario  # noqa: E402
from mpcform.scenario.plant import with_plant_kind  # noqa: E402


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
    short_run("swap_planar_8", tmp_path, steps=60)  # 6 s of flight
    run = load_run(tmp_path)
    flight_s = float(run.trajectory.t_s[-1] - run.trajectory.t_s[0])
    calls: list[tuple[int, int]] = []
    path = animate_run(
        run,
        tmp_path / "plots" / ANIMATION_FILE,
        speed=speed,
        progress=lambda done, total: calls.append((done, total)),
    )
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


@pytest.fixture(scope="module")
def ffprobe() -> str:
    """ffprobe's path, with ffmpeg beside it; skip (fail under ``MPCFORM_REQUIRE_BROWSER=1``) without."""
    found = shutil.which("ffprobe")
    if found is None or not FFMpegWriter.isAvailable():
        reason = "ffmpeg and ffprobe are not on PATH: apt-get install ffmpeg"
        if os.environ.get("MPCFORM_REQUIRE_BROWSER") == "1":
            pytest.fail(reason + " (MPCFORM_REQUIRE_BROWSER=1)")
        pytest.skip(reason)
    return found


def mp4_stream(ffprobe: str, path: Path) -> dict[str, str]:
    """The container's duration [s] and the video stream's codec, frame rate and decoded frames."""
    out = subprocess.run(
        [
            ffprobe,
            "-v",
            "error",
            "-count_frames",
            "-select_streams",
            "v:0",
            "-show_entries",
            "format=format_name,duration:stream=codec_name,r_frame_rate,nb_read_frames",
            "-of",
            "default=noprint_wrappers=1",
            str(path),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    return dict(line.split("=", 1) for line in out.stdout.split())


@pytest.mark.parametrize("speed", [1.0, 4.0])
def test_mp4_lasts_as_long_as_the_flight_at_the_chosen_speed(
    tmp_path: Path, ffprobe: str, speed: float
) -> None:
    short_run("swap_planar_8", tmp_path, steps=40)  # 4 s of flight
    run = load_run(tmp_path)
    t0, t1 = float(run.trajectory.t_s[0]), float(run.trajectory.t_s[-1])
    assert animation_file() == MP4_FILE
    calls: list[tuple[int, int]] = []
    path = animate_run(
        run,
        tmp_path / "plots" / MP4_FILE,
        speed=speed,
        progress=lambda done, total: calls.append((done, total)),
    )
    info = mp4_stream(ffprobe, path)
    times, fps = frame_times(t0, t1, speed)
    assert "mp4" in info["format_name"] and info["codec_name"] == "h264"
    assert info["r_frame_rate"] == f"{fps}/1" and int(info["nb_read_frames"]) == len(times)
    duration_s = float(info["duration"])
    assert duration_s == pytest.approx(len(times) / fps, abs=1e-3)
    assert abs(duration_s - (t1 - t0) / speed) <= 1 / fps + 1e-3  # the flight, plus at most one frame
    assert calls[-1] == (len(times), len(times)) and len(calls) == len(times)


def test_frames_join_pairs_closer_than_d_min_and_name_the_drones(tmp_path: Path) -> None:
    scenario = shortened(load_scenario(SCENARIOS / "swap_planar_8.toml"), 60)
    tracking = dataclasses.replace(
        scenario, controller=dataclasses.replace(scenario.controller, kind="tracking")
    )
    run_scenario(tracking, tmp_path)  # eq. 14 alone: the antipodal drones meet in the centre
    run = load_run(tmp_path)
    scene = FlightScene(run, 1.0, 60)
    k, _, _, dist = closest_pair(run.trajectory.positions_m)
    assert run.d_min_m is not None and dist < run.d_min_m
    scene.update(float(run.trajectory.t_s[k]))
    art = scene.artists[0]
    x, y = art["close"].get_data()
    assert np.isfinite(np.asarray(x)).sum() >= 2  # at least one red segment
    assert [t.get_text() for t in art["ids"]] == [str(i) for i in range(run.n)]
    scene.update(0.0)
    assert not np.isfinite(np.asarray(art["close"].get_data()[0])).any()  # the ring starts apart


def test_a_plant_run_animates_its_flown_path(tmp_path: Path) -> None:
    scenario = with_plant_kind(shortened(load_scenario(SCENARIOS / "swap_planar_8.toml"), 20), "lag")
    run_scenario(scenario, tmp_path)
    run = load_run(tmp_path)
    scene = FlightScene(run, 1.0, 60)
    assert run.flown is not None and scene.path_t is run.flown.t_s
    t = float(run.flown.t_s[7])  # a dense sample between two control samples
    scene.update(t)
    np.testing.assert_allclose(scene.artists[0]["drones"].get_offsets(), run.flown.positions_m[7])


def mp4_size(ffprobe: str, path: Path) -> tuple[int, int]:
    out = subprocess.run(
        [ffprobe, "-v", "error", "-select_streams", "v:0", "-show_entries", "stream=width,height"]
        + ["-of", "csv=p=0", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    width, height = out.stdout.strip().split(",")
    return int(width), int(height)


@pytest.mark.parametrize(("name", "steps"), [("mission_obstacle_gap", 60), ("swap_spatial_12", 8)])
def test_the_gif_has_the_mp4s_frame_size(tmp_path: Path, ffprobe: str, name: str, steps: int) -> None:
    short_run(name, tmp_path, steps=steps)  # a flat, wide flight (a short frame) and a spatial one
    run = load_run(tmp_path)
    gif = animate_run(run, tmp_path / ANIMATION_FILE, max_frames=4)
    with PIL.open(gif) as im:
        size = im.size
    assert size == mp4_size(ffprobe, animate_run(run, tmp_path / MP4_FILE, max_frames=4))
    assert size[0] % 2 == size[1] % 2 == 0 and size[1] >= 288  # no 256-pixel strip


@pytest.mark.parametrize(("name", "steps"), [("mission_obstacle_gap", 60), ("swap_spatial_12", 8)])
def test_the_clock_clears_the_panels_titles(tmp_path: Path, name: str, steps: int) -> None:
    short_run(name, tmp_path, steps=steps)
    scene = FlightScene(load_run(tmp_path), 1.0, 80)
    scene.update(0.5)
    scene.render()
    renderer = scene.fig.canvas.get_renderer()
    clock = scene.clock.get_window_extent(renderer)
    for ax in scene.fig.axes:  # the clock above every panel's title, apart
        assert ax.title.get_text() and ax.title.get_window_extent(renderer).y1 < clock.y0
    assert not scene.titles_overlap()
