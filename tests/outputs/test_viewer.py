"""The HTML viewer: checked, compact payload; one self-contained file; drawn by headless Chromium.

The browser tests need Chromium (Debian: ``apt-get install chromium``); without it they skip,
unless ``MPCFORM_REQUIRE_BROWSER=1`` (set by ``.ci/run``), where they fail.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import tomllib
from fnmatch import fnmatch
from pathlib import Path

import numpy as np
import pytest
from saved_runs import short_run

from mpcform.cli.handlers import write_view
from mpcform.errors import ValidationError
from mpcform.outputs import viewer
from mpcform.outputs.rundata import RunData, load_run
from mpcform.sim.trajectory import TrueTrajectory
from mpcform.world.shapes import Sphere

ROOT = Path(__file__).resolve().parents[2]
MAX_BYTES = 8 * 2**20  # the 20-drone swap's page must stay below this (it is ~0.1 MB)
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
WINDOW = (1200, 800)
SHOTS = Path(os.environ.get("MPCFORM_VIEWER_SHOTS", "")) if os.environ.get("MPCFORM_VIEWER_SHOTS") else None


def synthetic() -> dict:
    """A planar run of 4 drones: drones 0 and 1 pass 0.3 m apart at t = 2 s (d_min = 0.5 m)."""
    t = np.round(np.arange(41) * 0.1, 10)
    p = np.zeros((41, 4, 2))
    p[:, 0] = np.column_stack([-2.0 + t, np.full_like(t, 0.15)])
    p[:, 1] = np.column_stack([2.0 - t, np.full_like(t, -0.15)])
    p[:, 2] = [0.0, -1.5]
    p[:, 3] = [1.5, 1.0]
    ref = p + 0.05 * np.exp(-2.0 * t)[:, None, None]
    return {
        "t_s": t,
        "positions_m": p,
        "d_min_m": 0.5,
        "v_max_mps": 1.2,
        "edges": [(0, 2), (1, 2), (1, 3)],
        "obstacles": (Sphere([0.0, 2.0], 0.4),),  # clearance d_min / 2
        "geofence": ([-3.0, -np.inf], [3.0, 2.8]),
        "reference_m": ref,
        "title": "synthetic </script> crossing & pass",
        "curves": viewer.viewer_curves(t, p, reference_m=ref),
    }


# ---- payload and page, no browser -----------------------------------------------------------
def test_payload_is_rounded_and_marks_pairs_closer_than_d_min() -> None:
    run = synthetic()
    data = viewer.viewer_payload(**run)
    assert data["n"] == 4 and data["dim"] == 2 and len(data["t_s"]) == 41
    assert data["p_mm"][:2] == [-2000, 150] and all(isinstance(v, int) for v in data["p_mm"])
    assert set(data["below"]) == {"19", "20", "21"} and data["below"]["20"] == [0, 1]  # 0.5 m at 18, 22
    assert data["obstacles"] == [{"kind": "sphere", "clear": 0.25, "c": [0.0, 2.0], "r": 0.4}]
    assert data["closest"]["pair"] == [0, 1] and data["closest"]["m"] < 0.5  # its sample's distance
    assert data["fence"] == {"min_m": [-3.0, None], "max_m": [3.0, 2.8]}
    curves = {c["key"]: c for c in data["curves"]}
    assert curves["min_separation_m"]["limit"]["value"] == 0.5 and curves["min_separation_m"]["unit"] == "m"
    assert curves["max_speed_mps"]["limit"]["label"] == "v_max = 1.2 m/s"
    assert curves["max_speed_mps"]["y"][-1] is None and not curves["max_speed_mps"]["log"]
    assert curves["max_tracking_error_m"]["log"] and curves["max_tracking_error_m"]["limit"] is None
    assert min(curves["max_tracking_error_m"]["y"]) >= viewer.TRACKING_FLOOR_M  # not 1e-13 at an exact start


def test_viewer_curves() -> None:
    run = synthetic()
    curves = viewer.viewer_curves(run["t_s"], run["positions_m"], reference_m=run["reference_m"])
    assert curves["min_separation_m"][20] == pytest.approx(0.3)
    assert np.allclose(curves["max_speed_mps"][:-1], 1.0) and np.isnan(curves["max_speed_mps"][-1])
    assert curves["max_tracking_error_m"][0] == pytest.approx(0.05 * np.sqrt(2))
    u = np.full((40, 4, 2), 0.6)
    held = viewer.viewer_curves(run["t_s"], run["positions_m"], commands_mps=u)
    assert np.allclose(held["max_speed_mps"][:-1], 0.6 * np.sqrt(2)) and "max_tracking_error_m" not in held
    single = viewer.viewer_curves(run["t_s"], run["positions_m"][:, :1])
    assert set(single) == {"max_speed_mps"}


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"t_s": np.zeros(41)}, "t_s"),
        ({"positions_m": np.zeros((41, 4, 4))}, "positions_m"),
        ({"reference_m": np.zeros((41, 3, 2))}, "reference_m"),
        ({"edges": [(0, 4)]}, "edges"),
        ({"obstacles": (Sphere([0.0, 0.0, 0.0], 1.0),)}, "obstacles[0].center"),
        ({"obstacles": (np.zeros(3),)}, "obstacles[0]"),
        ({"geofence": ([0.0, 0.0], [1.0, -1.0])}, "geofence"),
        ({"d_min_m": 0.0}, "d_min_m"),
        ({"v_max_mps": "fast"}, "v_max_mps"),
        ({"curves": {"x_m": np.zeros(40)}}, "curves['x_m']"),
    ],
)
def test_bad_input_names_the_field(change: dict, field: str) -> None:
    with pytest.raises(ValidationError) as info:
        viewer.viewer_payload(**{**synthetic(), **change})
    assert info.value.field == field


def test_page_is_one_file_that_needs_no_network(tmp_path: Path) -> None:
    path = viewer.write_viewer_html(tmp_path / "sub" / "view.html", **synthetic())
    page = path.read_text(encoding="utf-8")
    assert not re.search(r"https?://|<link|\ssrc=|import\s*\(|fetch\(", page)
    assert "</script> crossing" not in page and "synthetic &lt;/script&gt; crossing &amp; pass" in page
    data = re.search(r'<script type="application/json" id="mpcform-data">(.*?)</script>', page, re.S)
    assert data is not None and json.loads(data.group(1))["title"] == "synthetic </script> crossing & pass"
    assert "/*@" not in page and "@TITLE@" not in page


def test_static_files_are_package_data() -> None:
    """Every static file matches pyproject's package-data (so a wheel carries it; building one
    needs setuptools' wheel support from the registry, which tests do not download)."""
    static = sorted(p.name for p in (ROOT / "mpcform" / "outputs" / "static").iterdir())
    assert {"viewer.html", "viewer.js", "viewer.css"} <= set(static)
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert all(any(fnmatch(f"static/{name}", g) for g in globs["mpcform.outputs"]) for name in static)


# ---- the 20-drone swap ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def swap20(tmp_path_factory: pytest.TempPathFactory) -> RunData:
    out = tmp_path_factory.mktemp("swap_spatial_20")
    short_run("swap_spatial_20", out, steps=30)  # to t = 3 s, past its closest pair (2.7 s)
    return load_run(out)


def swap20_page(run: RunData, path: Path) -> Path:
    """The page as the CLI writes it for a saved run (``mpcform view DIR``)."""
    return write_view(run, path)


def test_swap20_page_is_small(swap20: RunData, tmp_path: Path) -> None:
    path = swap20_page(swap20, tmp_path / "swap20.html")
    assert swap20.n == 20 and swap20.dim == 3
    assert path.stat().st_size <= MAX_BYTES, f"{path.stat().st_size} bytes"


@pytest.mark.slow
def test_a_100_drone_plant_runs_page_stays_within_5_mb(tmp_path: Path) -> None:
    """formation_flight_100 on the lag plant (25 s, a 100 Hz true path): the flown path drawn at 5
    samples per interval, its extremes from the whole path."""
    from mpcform.run.runner import run_scenario
    from mpcform.scenario.load import load_scenario
    from mpcform.scenario.plant import with_plant_kind

    sc = with_plant_kind(load_scenario(ROOT / "scenarios" / "formation_flight_100.toml"), "lag")
    run_scenario(sc, tmp_path / "run")
    data = load_run(tmp_path / "run")
    assert data.flown is not None and data.flown.t_s.shape[0] > 9 * data.trajectory.t_s.shape[0]
    path = write_view(data, tmp_path / "ff100.html")
    assert path.stat().st_size <= 5 * 2**20, f"{path.stat().st_size} bytes"
    payload = json.loads(re.search(r'id="mpcform-data">(.*?)</script>', path.read_text(), re.S).group(1))
    assert len(payload["flown"]["t_s"]) <= viewer.FLOWN_PER_STEP * (data.trajectory.t_s.shape[0] - 1) + 1
    speeds = next(c for c in payload["curves"] if c["key"] == viewer.FLOWN_SPEED_KEY)["y"]
    true_peak = np.linalg.norm(data.flown.velocities_mps, axis=-1).max()
    assert max(v for v in speeds if v is not None) == pytest.approx(true_peak, rel=1e-3)  # the whole path's


# ---- headless Chromium ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def browser() -> str:
    found = next((shutil.which(name) for name in BROWSERS if shutil.which(name)), None)
    if found is None:
        reason = f"no headless browser ({', '.join(BROWSERS)}) on PATH: apt-get install chromium"
        if os.environ.get("MPCFORM_REQUIRE_BROWSER") == "1":
            pytest.fail(reason + " (MPCFORM_REQUIRE_BROWSER=1)")
        pytest.skip(reason)
    return found


def chromium(
    browser: str, page: Path, mode: str, profile: Path, hash_: str = "", *extra: str
) -> tuple[str, str]:
    """Run the browser headless on ``page`` with ``--screenshot=...`` or ``--dump-dom``; (stdout, log)."""
    args = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={profile}",
        "--enable-logging=stderr",
        "--v=0",
        "--hide-scrollbars",
        f"--window-size={WINDOW[0]},{WINDOW[1]}",
        *extra,
        mode,
        page.resolve().as_uri() + hash_,
    ]
    out = subprocess.run(args, capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout, out.stderr


def console(log: str) -> list[str]:
    return [line for line in log.splitlines() if "CONSOLE" in line or "Uncaught" in line]


def check_page(browser: str, page: Path, tmp_path: Path, samples: int, hash_: str) -> str:
    """Screenshot (not blank, no console error) and DOM (self-check passed); returns the DOM."""
    png = tmp_path / (page.stem + ".png")
    _, log = chromium(browser, page, f"--screenshot={png}", tmp_path / "profile-shot", hash_)
    lines = console(log)
    assert lines and all("viewer-ready" in line for line in lines), "\n".join(lines)
    image = plt_image(png)
    assert image.shape[:2] == (WINDOW[1], WINDOW[0])
    grey = image[..., :3].mean(axis=-1)
    assert grey.std() > 0.08 and (grey < 0.9).mean() > 0.02, "the screenshot is (nearly) blank"
    if SHOTS is not None:
        SHOTS.mkdir(parents=True, exist_ok=True)
        shutil.copy(png, SHOTS / png.name)
    dom, log = chromium(browser, page, "--dump-dom", tmp_path / "profile-dom", hash_)
    assert f'data-viewer="ok:{samples}"' in dom, re.findall(r"<body[^>]*>", dom) + console(log)
    return dom


def plt_image(png: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(png) as im:
        return np.asarray(im.convert("RGB"), dtype=float) / 255.0


def test_browser_draws_the_synthetic_run(browser: str, tmp_path: Path) -> None:
    page = viewer.write_viewer_html(tmp_path / "synthetic.html", **synthetic())
    dom = check_page(browser, page, tmp_path, 41, "#t=2")
    assert 'data-sample="20"' in dom and 'data-below="1"' in dom  # the pair closer than d_min, red
    assert "1 pair closer than d_min" in dom


def test_browser_draws_the_20_drone_swap(browser: str, swap20: RunData, tmp_path: Path) -> None:
    page = swap20_page(swap20, tmp_path / "swap_spatial_20.html")
    dom = check_page(browser, page, tmp_path, swap20.trajectory.t_s.shape[0], "#t=3")
    assert 'data-sample="30"' in dom and "20 drones · 3-D" in dom
    closest = viewer.viewer_payload(t_s=swap20.trajectory.t_s, positions_m=swap20.trajectory.positions_m)[
        "closest"
    ]
    pair = f"closest {closest['pair'][0]}-{closest['pair'][1]}: {closest['m']} m"  # marked with no violation
    assert "no pair closer than d_min" in dom and pair in dom


def test_browser_frames_a_planar_run_within_10_percent_of_its_data(browser: str, tmp_path: Path) -> None:
    """A wide planar run (16 m by 2.6 m) is not drawn on a square of 16 m: the frame hugs the data."""
    run = synthetic()
    run["positions_m"] = run["positions_m"] * np.array([4.0, 1.0])
    page = viewer.write_viewer_html(tmp_path / "wide.html", **{**run, "obstacles": None, "geofence": None})
    dom, _ = chromium(browser, page, "--dump-dom", tmp_path / "profile", "#t=0")
    found = re.search(r'data-extent="([-\d.,]+)"', dom)
    assert found is not None, re.findall(r"<body[^>]*>", dom)
    x0, x1, y0, y1 = (float(v) for v in found.group(1).split(","))
    points = np.concatenate([run["positions_m"].reshape(-1, 2), run["reference_m"].reshape(-1, 2)])
    span = points.max(axis=0) - points.min(axis=0)
    assert x1 - x0 <= 1.1 * span[0] and y1 - y0 <= 1.1 * span[1]
    assert x0 <= points[:, 0].min() and x1 >= points[:, 0].max()


def test_browser_plays_the_run(browser: str, tmp_path: Path) -> None:
    """``#speed=8&play`` starts playback: after some (virtual) time the page shows a later sample."""
    page = viewer.write_viewer_html(tmp_path / "play.html", **synthetic())
    dom, _ = chromium(
        browser, page, "--dump-dom", tmp_path / "profile", "#t=0&speed=8&play", "--virtual-time-budget=3000"
    )
    sample = re.search(r'<body[^>]*data-sample="(\d+)"', dom)
    assert sample is not None and int(sample.group(1)) > 0, re.findall(r"<body[^>]*>", dom)


def test_flown_curves_keep_the_dense_extremes_of_each_interval() -> None:
    t_true = np.linspace(0.0, 0.2, 21)  # 10 dense samples per control interval of 0.1 s
    p = np.zeros((21, 2, 2))
    p[:, 1, 0] = 1.0
    p[7, 1, 0] = 0.3  # drone 1 dips towards drone 0 inside the first interval
    v = np.zeros((21, 2, 2))
    v[14, 0, 1] = 2.5  # a speed spike inside the second
    true = TrueTrajectory(t_true, p, v, np.zeros_like(p))
    curves = viewer.flown_curves(np.array([0.0, 0.1, 0.2]), true)
    np.testing.assert_allclose(curves[viewer.FLOWN_SEPARATION_KEY], [0.3, 1.0, 1.0])
    np.testing.assert_allclose(curves[viewer.FLOWN_SPEED_KEY], [0.0, 2.5, 0.0])


def flown_synthetic() -> tuple[dict, TrueTrajectory]:
    """The synthetic run with a dense true path at 500 Hz that overshoots drone 0's by 0.2 m in y."""
    run = synthetic()
    t = np.round(np.arange(2001) * 0.002, 10)
    p = np.stack(
        [np.interp(t, run["t_s"], run["positions_m"][:, i, a]) for i in range(4) for a in range(2)], -1
    )
    p = p.reshape(-1, 4, 2)
    p[:, 0, 1] += 0.2 * np.sin(np.pi * t / 4.0)
    v = np.gradient(p, t, axis=0)
    return run, TrueTrajectory(t, p, v, np.zeros_like(p))


def test_a_plant_runs_flown_path_is_downsampled_for_display() -> None:
    run, true = flown_synthetic()
    keep = viewer.flown_samples(true.t_s, 41)
    assert keep[0] == 0 and keep[-1] == 2000 and keep.shape[0] <= viewer.FLOWN_PER_STEP * 40 + 1
    data = viewer.viewer_payload(**run, flown=true)
    assert data["flown"]["t_s"][:3] == [0.0, 0.02, 0.04] and len(data["flown"]["p_mm"]) == keep.shape[0] * 8
    assert data["flown"]["p_mm"][1] == 150 and max(data["flown"]["p_mm"][1::8]) == 350  # drone 0's y
    assert viewer.viewer_payload(**run)["flown"] is None


def test_browser_draws_the_flown_path_and_the_wind(browser: str, tmp_path: Path) -> None:
    run, true = flown_synthetic()
    page = viewer.write_viewer_html(
        tmp_path / "flown.html", **run, flown=true, wind=(np.array([0.0, 1.5]), 0.5)
    )
    dom = check_page(browser, page, tmp_path, 41, "#t=2")
    assert 'data-flown="101"' in dom  # the flown samples up to t = 2 s (every 20 ms)
    assert 'data-wind="0.00,-1.00"' in dom  # +y on the screen is up: the canvas' -y


def test_the_wind_is_in_the_payload() -> None:
    run = synthetic()
    data = viewer.viewer_payload(**run, wind=(np.array([1.0, -0.25]), 0.3))
    assert data["wind"] == {"mean_mps": [1.0, -0.25], "gust_std_mps": 0.3}
    assert viewer.viewer_payload(**run)["wind"] is None
    with pytest.raises(ValidationError, match="wind"):
        viewer.viewer_payload(**run, wind=(np.array([1.0, 0.0, 0.0]), 0.3))


def spatial_synthetic() -> dict:
    """:func:`synthetic` lifted into space: the drones climb 1 m (no obstacle, no geofence)."""
    run = synthetic()
    t, p = run["t_s"], run["positions_m"]
    p = np.concatenate([p, np.broadcast_to(t[:, None, None] / 4, (*p.shape[:2], 1))], axis=-1)
    ref = p + 0.05 * np.exp(-2.0 * t)[:, None, None]
    curves = viewer.viewer_curves(t, p, reference_m=ref)
    return {
        **run,
        "positions_m": p,
        "reference_m": ref,
        "curves": curves,
        "obstacles": None,
        "geofence": None,
    }


TRIAD_RGB = {"x": (0xD6, 0x27, 0x28), "y": (0x2C, 0xA0, 0x2C), "z": (0x1F, 0x77, 0xB4)}


def test_the_3d_view_draws_an_axis_triad(browser: str, tmp_path: Path) -> None:
    """x red, y green, z blue, labelled, in the lower left corner of the 3-D scene (none in 2-D)."""
    page = viewer.write_viewer_html(tmp_path / "spatial.html", **spatial_synthetic())
    html = page.read_text(encoding="utf-8")
    assert "drawTriad" in html and all(f'["{a}", "#{bytes(c).hex()}"]' in html for a, c in TRIAD_RGB.items())
    dom = check_page(browser, page, tmp_path, 41, "#t=1")
    found = re.search(r'data-triad="([-\d.,;]+)"', dom)
    assert found is not None, re.findall(r"<body[^>]*>", dom)
    tips = np.array([[float(v) for v in q.split(",")] for q in found.group(1).split(";")])
    assert tips.shape == (3, 2) and (tips > 10).all() and (tips < 100).all()  # from the lower left [px]
    image = plt_image(tmp_path / "spatial.png")[WINDOW[1] // 2 :, :160]  # the scene's lower left
    for rgb in TRIAD_RGB.values():  # each axis drawn in its colour (a red line only there)
        assert (np.abs(image - np.array(rgb) / 255).max(axis=-1) < 0.1).sum() >= 30
    planar = viewer.write_viewer_html(tmp_path / "planar.html", **synthetic())
    dom, _ = chromium(browser, planar, "--dump-dom", tmp_path / "profile-planar", "#t=1")
    assert "data-triad" not in dom
