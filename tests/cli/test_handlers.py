"""`run --plot/--animate/--export`, `plot`, `compare`, `export`, `validate`: files, exit codes, messages."""

from __future__ import annotations

import json
import re
import shutil
import time
from importlib.util import find_spec
from pathlib import Path

import numpy as np
import pytest
import yaml
from saved_runs import SCENARIOS, short_run

from mpcform.cli import handlers as cli_runner
from mpcform.cli.main import main
from mpcform.outputs import rundata
from mpcform.outputs.outdir import EXPORT_DIR, PLOTS_DIR, RUN_LAYOUT, VIEWER_FILE
from mpcform.outputs.rundata import load_run
from mpcform.world.limits import PLATFORM_TRACKING_M

ROOT = Path(__file__).resolve().parents[2]
WORKED = ROOT / "scenarios" / "worked_example.toml"
HAS_PLOT = find_spec("matplotlib") is not None and find_spec("PIL") is not None
needs_plot = pytest.mark.skipif(not HAS_PLOT, reason="matplotlib is not installed")
OWN = (".mpcform-manifest.json", ".mpcform.lock")  # mpcform's bookkeeping in its output directory


def short_copy(
    tmp_path: Path, source: Path = WORKED, steps_text: tuple[str, str] = ("duration = 10.0", "duration = 0.4")
) -> str:
    path = tmp_path / source.name
    path.write_text(source.read_text().replace(*steps_text))
    return str(path)


def error_lines(capsys: pytest.CaptureFixture[str], status: int, *fragments: str) -> list[str]:
    """Exit status 2, no traceback; every stderr line is an error, the fragments in the first."""
    err = capsys.readouterr().err
    assert status == 2 and "Traceback" not in err
    lines = err.strip().splitlines()
    assert lines and lines[0].startswith("mpcform: error: ")
    for fragment in fragments:
        assert fragment in lines[0], err
    return lines


# ---- run ----------------------------------------------------------------------------------
@needs_plot
def test_run_with_plot_animate_export(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert (
        main(
            [
                "run",
                short_copy(tmp_path),
                "--out",
                str(out),
                "--plot",
                "--animate",
                "--export",
                "--altitude",
                "1.5",
                "--no-flight-check",
                "--allow-untracked",  # the worked example flies eq. 14: no tracking allowance
            ]
        )
        == 0
    )
    captured = capsys.readouterr()
    from mpcform.outputs.animation import animation_file  # needs matplotlib

    video = animation_file()  # flight.mp4 with ffmpeg, else flight.gif
    assert "final tracking error" in captured.out and "wrote 5 figures" in captured.out
    assert video in captured.out and "exported 3 drones" in captured.out
    assert captured.err == ""  # not a terminal: no progress bar
    assert {"trajectory.npz", "trajectory.csv", "summary.json", "formation.npz"} <= {
        p.name for p in out.iterdir()
    }
    plots = {p.name for p in (out / "plots").iterdir()}
    assert plots == {
        "top_view.png",
        "tracking_error.png",
        "speed.png",
        "separation.png",
        "scale.png",
        video,
    }
    export = {p.name for p in (out / "export").iterdir()}
    assert {"drone000_setpoints.csv", "drone002_poly7.csv", "provenance.json"} <= export
    assert json.loads((out / "export" / "provenance.json").read_text())["altitude_m"] == 1.5


@needs_plot
def test_run_draws_and_exports_from_memory(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """`run --plot --export` reads none of the run's files back, and draws and exports exactly
    what `plot DIR` and `export DIR` make of the files it wrote."""
    out = tmp_path / "out"
    scenario = ROOT / "scenarios" / "obstacles_planar.toml"
    path = short_copy(tmp_path, scenario, ("duration = ", "duration = 1.5 #"))

    def no_read_back(*args: object, **kwargs: object) -> None:
        raise AssertionError(f"read back: {args}")

    with monkeypatch.context() as patch:
        for module, name in ((cli_runner, "load_run"), (rundata, "load_run"), (np, "load")):
            patch.setattr(module, name, no_read_back)
        assert main(["run", path, "--out", str(out), "--plot", "--export", "--flyable"]) == 0
    assert "wrote 6 figures" in capsys.readouterr().out  # clearance.png: the scenario has obstacles
    assert main(["plot", str(out), "--out", str(tmp_path / "plots")]) == 0
    assert main(["export", str(out), "--out", str(tmp_path / "export")]) == 0
    for name in ("plots", "export"):
        memory = sorted((out / name).iterdir())  # listed in out's manifest; the --out ones in their own
        assert [p.name for p in memory] == sorted(
            p.name for p in (tmp_path / name).iterdir() if p.name not in OWN
        )
        for file in memory:
            assert file.read_bytes() == (tmp_path / name / file.name).read_bytes(), file.name


def test_run_export_without_plotting(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["run", short_copy(tmp_path), "--out", str(out), "--export", "--allow-untracked"]) == 0
    assert (out / "export" / "drone000_poly7.csv").exists() and not (out / "plots").exists()


def test_run_export_without_a_tracking_allowance_is_refused_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = short_copy(tmp_path, SCENARIOS / "swap_planar_8.toml", ("duration = ", "duration = 0.3 #"))
    status = main(["run", path, "--out", str(tmp_path / "o"), "--export", "--no-flight-check"])
    error_lines(capsys, status, "tracking: the run was planned without a tracking allowance", "--flyable")
    assert not (tmp_path / "o").exists()
    argv = ["run", path, "--out", str(tmp_path / "o"), "--export", "--no-flight-check", "--flyable"]
    assert main(argv) == 0
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["limits"]["tracking"] == PLATFORM_TRACKING_M
    assert json.loads((tmp_path / "o" / "export" / "provenance.json").read_text())["tracking_m"] == 0.05


def test_plain_run_writes_only_the_contract_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["run", short_copy(tmp_path), "--out", str(out)]) == 0
    assert {p.name for p in out.iterdir()} == {"trajectory.npz", "trajectory.csv", "summary.json", *OWN}


def test_plot_without_matplotlib_fails_before_running(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(cli_runner, "find_spec", lambda name: None)
    status = main(["run", short_copy(tmp_path), "--out", str(tmp_path / "o"), "--plot"])
    error_lines(capsys, status, "matplotlib", "pip install 'mpcform[plot]'")
    assert not (tmp_path / "o").exists()
    short_run("worked_example", tmp_path / "saved", steps=5)
    error_lines(capsys, main(["plot", str(tmp_path / "saved")]), "matplotlib")


@pytest.mark.parametrize(
    ("scenario", "argv", "fragments"),
    [
        ("worked_example", ["--altitude", "2"], ("--altitude", "only with --export")),
        ("swap_spatial_12", ["--export", "--altitude", "2"], ("--altitude", "only to planar")),
        ("worked_example", ["--export", "--altitude", "-1"], ("altitude",)),
        ("worked_example", ["--export", "--tolerance", "0"], ("tolerance", "> 0")),
    ],
)
def test_bad_run_options(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    scenario: str,
    argv: list[str],
    fragments: tuple[str, ...],
) -> None:
    source = ROOT / "scenarios" / f"{scenario}.toml"
    path = short_copy(tmp_path, source, ("duration = ", "duration = 0.2 #"))
    error_lines(capsys, main(["run", path, "--out", str(tmp_path / "o"), *argv]), *fragments)


# ---- plot, compare, export ----------------------------------------------------------------
@needs_plot
def test_plot_a_saved_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    short_run("swap_spatial_12", tmp_path, steps=8)
    assert main(["plot", str(tmp_path), "--out", str(tmp_path / "figs")]) == 0
    assert "wrote 6 figures" in capsys.readouterr().out
    assert (tmp_path / "figs" / "view_3d.png").stat().st_size > 0


@needs_plot
def test_plot_a_saved_run_with_its_animation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from mpcform.outputs.animation import animation_file  # needs matplotlib

    short_run("worked_example", tmp_path, steps=10)
    assert main(["plot", str(tmp_path), "--animate", "--speed", "4"]) == 0
    video = tmp_path / "plots" / animation_file()
    assert f"wrote {video}" in capsys.readouterr().out and video.stat().st_size > 1000


@pytest.mark.parametrize("command", ["plot", "export"])
def test_bad_run_directories(tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str) -> None:
    if command == "plot" and not HAS_PLOT:
        pytest.skip("matplotlib is not installed")
    error_lines(capsys, main([command, str(tmp_path / "missing")]), "missing", "no such run directory")
    error_lines(capsys, main([command, str(tmp_path)]), "trajectory.npz", "missing")
    short_run("worked_example", tmp_path, steps=5)
    (tmp_path / "summary.json").write_text("[")
    error_lines(capsys, main([command, str(tmp_path)]), "summary.json", "cannot read it as JSON")
    (tmp_path / "trajectory.npz").write_bytes(b"not an archive")
    error_lines(capsys, main([command, str(tmp_path)]), "trajectory.npz", "cannot read it")


@needs_plot
def test_compare(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = short_copy(tmp_path)
    for kind in ("tracking", "proportional", "mpc"):
        assert main(["run", path, "--out", str(tmp_path / kind), "--controller", kind]) == 0
    capsys.readouterr()
    dirs = [str(tmp_path / k) for k in ("tracking", "proportional", "mpc")]
    figure, records = tmp_path / "c.png", tmp_path / "c.json"
    assert main(["compare", *dirs, "--figure", str(figure), "--json", str(records)]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].startswith("| run | controller | solver | final error [m]")
    assert len([line for line in table if line.startswith("| worked_example")]) == 3
    assert figure.stat().st_size > 5_000
    rows = json.loads(records.read_text())
    run = load_run(tmp_path / "tracking").trajectory
    err2 = np.sum((run.positions_m - run.reference_m) ** 2, axis=(1, 2))  # trapezoid by hand
    steps = zip(err2[:-1], err2[1:], run.t_s[:-1], run.t_s[1:], strict=True)
    want = sum(0.5 * (a + b) * (t1 - t0) for a, b, t0, t1 in steps)
    assert rows[0]["tracking_cost"] == pytest.approx(want, rel=1e-12) and want > 0
    assert [r["controller"] for r in rows] == ["tracking", "proportional", "mpc"]
    assert rows[2]["solver"] and rows[0]["solver"] is None


def test_compare_table_only_and_bad_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    short_run("worked_example", tmp_path / "a", steps=5)
    short_run("worked_example", tmp_path / "b", steps=5)
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b"), "--no-figure"]) == 0
    out = capsys.readouterr().out
    assert "[a]" in out and "[b]" in out  # same label: the directory tells them apart
    error_lines(capsys, main(["compare", str(tmp_path / "a"), str(tmp_path / "zz"), "--no-figure"]), "zz")


def test_compare_draws_its_figure_beside_the_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("matplotlib")
    short_run("worked_example", tmp_path / "runs" / "a", steps=5)
    short_run("worked_example", tmp_path / "runs" / "b", steps=5)
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    assert main(["compare", "../runs/a", str(tmp_path / "runs" / "b")]) == 0
    assert (tmp_path / "runs" / "compare.png").stat().st_size > 5_000
    assert list((tmp_path / "elsewhere").iterdir()) == []  # nothing dropped in the current directory


def test_export_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    short_run("swap_planar_8", tmp_path, steps=40, flyable=True)
    argv = ["export", str(tmp_path), "--altitude", "1.2", "--tolerance", "0.01", "--rate", "50"]
    argv.append("--no-flight-check")
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "exported 8 drones" in out and "tolerance 0.01 m" in out and "ground to ground in" in out
    setpoints = np.loadtxt(tmp_path / "export" / "drone007_setpoints.csv", delimiter=",", skiprows=1)
    assert setpoints.shape[1] == 14 and np.allclose(setpoints[:, 3], 1.2, atol=1e-5)
    assert np.allclose(np.diff(setpoints[:-1, 0]), 0.02)
    assert (tmp_path / "export" / "fly.py").exists() and (tmp_path / "export" / "crazyflies.yaml").exists()


def test_export_takes_off_from_the_pads_of_a_crazyflies_yaml(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    short_run("swap_planar_8", tmp_path / "run", steps=40, flyable=True)
    pads = [(1.0 * (k % 4), -4.0 - (k // 4), 0.0) for k in range(8)]
    robots = "".join(
        f"  lab{k}:\n    uri: radio://0/{k}/2M/E7E7E7E7{k:02X}\n    initial_position: [{x}, {y}, {z}]\n"
        for k, (x, y, z) in enumerate(pads)
    )
    (tmp_path / "pads.yaml").write_text("robots:\n" + robots)
    argv = ["export", str(tmp_path / "run"), "--ground", str(tmp_path / "pads.yaml"), "--no-flight-check"]
    assert main(argv) == 0
    placed = yaml.safe_load((tmp_path / "run" / "export" / "crazyflies.yaml").read_text())["robots"]
    for k, (x, y, _) in enumerate(pads):  # every pad used, by the robot standing on it
        assert placed[f"lab{k}"]["uri"] == f"radio://0/{k}/2M/E7E7E7E7{k:02X}"
        assert placed[f"lab{k}"]["initial_position"] == [x, y, 0.0]
    fly = (tmp_path / "run" / "export" / "fly.py").read_text()
    assert all(f"'lab{k}': (" in fly for k in range(8)) and "'cf1'" not in fly
    (tmp_path / "pads.yaml").write_text("robots:\n" + robots.split("  lab7:")[0])
    assert main(argv) == 2
    assert (
        capsys.readouterr()
        .err.strip()
        .endswith("--ground: 7 pads on the floor for 8 drones: expected at least 8")
    )


def test_export_refuses_the_floor_and_limits(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    short_run("swap_spatial_12", tmp_path, steps=10, flyable=True)
    assert main(["export", str(tmp_path), "--no-flight-check"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "below the floor 0 m" in err[0] and "drone" in err[0]
    argv = ["export", str(tmp_path), "--offset", "0,0,3", "--no-flight-check", "--max-body-rate", "0.001"]
    assert main(argv) != 0
    assert "body rate" in capsys.readouterr().err
    assert main([*argv, "--allow-limits"]) == 0
    assert "mpcform: warning: drone" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv",
    [
        ["plot"],
        ["export"],
        ["compare"],
        ["export", "d", "--tolerance", "x"],
        ["export", "d", "--offset", "1,2"],
    ],
)
def test_usage_errors(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    status = main(argv)
    err = capsys.readouterr().err
    assert status == 2 and err.strip().splitlines()[-1].startswith("mpcform: error: ")


# ---- validate -----------------------------------------------------------------------------
def test_validate_lists_every_problem(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = WORKED.read_text().replace("gain = 2.0", "gian = 2.0").replace("[limits]", "[limit]")
    text = text.replace("scale = 2.0", "scale = -2.0").replace("seed = 0", "sed = 0")
    path = tmp_path / "bad.toml"
    path.write_text(text)
    lines = error_lines(capsys, main(["validate", str(path)]))
    assert len(lines) == 5 and lines[-1] == f"mpcform: 4 problems in {path}"
    expected = ["sed", "reference.scale", "limit", "controller.gian"]
    for line, field in zip(lines, expected, strict=False):
        assert line.startswith(f"mpcform: error: {path}:") and f": {field}: " in line
    assert "did you mean 'limits'" in lines[2] and "did you mean 'gain'" in lines[3]
    numbers = [int(line.split(f"{path}:")[1].split(":")[0]) for line in lines[:4]]
    assert [text.splitlines()[k - 1].split("=")[0].strip(" []") for k in numbers] == [
        "sed",
        "scale",
        "limit",
        "gian",
    ]


def test_validate_ok(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(ROOT / "scenarios" / "formation_flight_100.toml")]) == 0
    assert capsys.readouterr().out.startswith("OK formation_flight_100: 100 drones")


def test_run_html_and_view_write_the_viewer(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = short_copy(
        tmp_path, ROOT / "scenarios" / "obstacles_planar.toml", ("duration = 30.0", "duration = 1.2")
    )
    out = tmp_path / "run"
    assert main(["run", str(scenario), "--out", str(out), "--html"]) == 0
    page = (out / "viewer.html").read_text()
    assert "viewer-ready" in page and "http" not in page.split("<body", 1)[1].lower().replace(
        "http-equiv", ""
    )
    assert main(["view", str(out), "--out", str(tmp_path / "again.html")]) == 0
    assert (tmp_path / "again.html").stat().st_size > 10_000
    assert "wrote" in capsys.readouterr().out
    shown, again = _payload(out / "viewer.html"), _payload(tmp_path / "again.html")
    assert shown == again and shown["fence"] == {"min_m": [-20.0, -4.0], "max_m": [20.0, 4.0]}


def _payload(page: Path) -> dict:
    found = re.search(
        r'<script type="application/json" id="mpcform-data">(.*?)</script>', page.read_text(), re.S
    )
    assert found is not None
    return json.loads(found.group(1))


@pytest.mark.parametrize(
    ("flags", "fragment"),
    [(["--speed", "2"], "applies only with --animate"), (["--speed", "0", "--animate"], "positive")],
)
def test_speed_is_checked_before_running(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flags, fragment
) -> None:
    status = main(["run", str(WORKED), "--out", str(tmp_path / "o"), *flags])
    error_lines(capsys, status, "--speed", fragment)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("option", "says"),
    [
        (["--max-speed", "1e-6"], "--max-speed: at this limit the retimed flight would last"),
        (["--rate", "1e7"], "--rate: the export would take "),
        (["--floor", "nan"], "--floor: expected a finite height [m], got nan"),
        (["--max-acc", "inf"], "--max-acc: expected a finite number > 0, got inf"),
    ],
)
def test_export_options_are_one_error_naming_the_flag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], option: list[str], says: str
) -> None:
    short_run("swap_planar_8", tmp_path, steps=40, flyable=True)
    lines = error_lines(capsys, main(["export", str(tmp_path), "--no-flight-check", *option]), says)
    assert len(lines) == 1 and not (tmp_path / "export").exists()


def test_run_export_checks_its_options_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "run",
        str(SCENARIOS / "swap_planar_8.toml"),
        "--out",
        str(tmp_path / "o"),
        "--export",
        "--rate",
        "nan",
    ]
    lines = error_lines(capsys, main(argv), "--rate: expected a finite number > 0, got nan")
    assert len(lines) == 1 and not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["view", "plot", "export", "compare"])
def test_a_truncated_trajectory_is_one_error_naming_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    short_run("swap_planar_8", tmp_path / "run", steps=40, formation=False)
    cut = tmp_path / "cut"
    cut.mkdir()
    for name in ("summary.json", "trajectory.csv"):
        (cut / name).write_bytes((tmp_path / "run" / name).read_bytes())
    (cut / "trajectory.npz").write_bytes((tmp_path / "run" / "trajectory.npz").read_bytes()[:5000])
    extra = ["--no-figure"] if command == "compare" else []
    lines = error_lines(
        capsys, main([command, str(cut), *extra]), f"{cut / 'trajectory.npz'}: cannot read it"
    )
    assert len(lines) == 1


def test_figures_as_pdf_svg_or_png_at_a_dpi_and_a_gif_on_request(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pil = pytest.importorskip("PIL.Image")
    out = tmp_path / "run"
    assert main(["run", short_copy(tmp_path), "--out", str(out), "--plot", "--dpi", "200"]) == 0
    with pil.open(out / "plots" / "top_view.png") as im:
        assert round(im.info["dpi"][0]) == 200
    magic = {"pdf": b"%PDF", "svg": b"<?xml"}
    for fmt, head in magic.items():
        assert main(["plot", str(out), "--format", fmt, "--out", str(tmp_path / fmt)]) == 0
        files = sorted(p for p in (tmp_path / fmt).iterdir() if p.name not in OWN)
        assert files and all(f.suffix == f".{fmt}" and f.read_bytes().startswith(head) for f in files)
    assert main(["plot", str(out), "--animate", "gif", "--out", str(tmp_path / "video")]) == 0
    assert (tmp_path / "video" / "flight.gif").read_bytes().startswith(b"GIF8")
    capsys.readouterr()


@pytest.mark.parametrize(
    ("flags", "fragment"),
    [
        (["--plot", "--dpi", "5"], "--dpi: expected an integer in 20..1200, got 5"),
        (["--format", "pdf"], "--format: applies only with --plot"),
        (["--animate", "avi"], "invalid choice"),
    ],
)
def test_bad_figure_options_are_refused_before_running(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flags: list[str], fragment: str
) -> None:
    assert main(["run", short_copy(tmp_path), "--out", str(tmp_path / "r"), *flags]) == 2
    assert fragment in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize(
    "argv", [["plot"], ["export", "--allow-untracked"], ["view"], ["compare", "--no-figure"]]
)
def test_a_nan_in_a_saved_trajectory_is_one_error_naming_the_file_and_the_array(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str]
) -> None:
    """Issue 58, item 4: a NaN in ``p`` reached the figures and the export (a traceback, exit 1)."""
    short_run("worked_example", tmp_path, steps=5)
    with np.load(tmp_path / "trajectory.npz") as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["p"][3, 0, 1] = np.nan
    np.savez(tmp_path / "trajectory.npz", **arrays)
    lines = error_lines(capsys, main([argv[0], str(tmp_path), *argv[1:]]))
    assert lines == [
        f"mpcform: error: {tmp_path / 'trajectory.npz'}: array 'p' holds nan at index (3, 0, 1); "
        "expected finite numbers"
    ]
    assert not (tmp_path / "plots").exists() and not (tmp_path / "export").exists()


# ---- output directories that cannot destroy data (issue 58) ------------------------------------
WRITES = {
    "run": tuple(RUN_LAYOUT),
    "plot": (PLOTS_DIR,),
    "export": (EXPORT_DIR,),
    "view": (VIEWER_FILE,),
}
USER_NAMES = (*RUN_LAYOUT, "plots/top_view.png", "plots/mine.png", "export/fly.py", "export/mine.csv")


@pytest.fixture(scope="module")
def full_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run with everything mpcform writes into its directory: data, figures, viewer, export."""
    root = tmp_path_factory.mktemp("full")
    argv = ["run", short_copy(root), "--out", str(root / "run"), "--plot", "--html", "--export"]
    assert main([*argv, "--allow-untracked", "--no-flight-check"]) == 0
    return root / "run"


def _tree(root: Path) -> dict[str, bytes | None]:
    return {
        str(p.relative_to(root)): p.read_bytes() if p.is_file() else None
        for p in sorted(root.rglob("*"))
        if p.name not in (".mpcform.lock", ".mpcform-manifest.json")
    }


@pytest.mark.parametrize("form", ["file", "dir"])
@pytest.mark.parametrize(
    ("command", "name"),
    [(c, n) for c, names in WRITES.items() for n in USER_NAMES if n.split("/")[0] in names],
)
def test_a_users_file_or_directory_at_any_output_name_survives(
    full_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, name: str, form: str
) -> None:
    """A user's file or directory where mpcform writes (in place of its own, or beside it in
    plots/ and export/): the command refuses, naming it, and it is left as it was."""
    shutil.copytree(full_run, tmp_path / "run", symlinks=True)
    root, mine = tmp_path / "run", tmp_path / "run" / name
    if mine.is_dir():
        shutil.rmtree(mine)
    else:
        mine.unlink(missing_ok=True)
    if form == "dir":
        mine.mkdir()
        (mine / "mine.txt").write_text("the user's")
    else:
        mine.write_text("the user's own file")
    before = _tree(root)
    argv = [command, short_copy(tmp_path), "--out", str(root)] if command == "run" else [command, str(root)]
    lines = error_lines(capsys, main([*argv, *(["--allow-untracked"] if command == "export" else [])]))
    assert len(lines) == 1 and (f"{mine}: " in lines[0] or f"{mine}/mine.txt: " in lines[0]), lines
    assert _tree(root) == before


def test_export_into_a_file_named_export_is_refused_at_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 58, item 5: after 6 s of work, "[Errno 17] File exists: 'g/export'"."""
    short_run("worked_example", tmp_path, steps=5)
    (tmp_path / "export").write_text("x\n")
    start = time.perf_counter()
    lines = error_lines(capsys, main(["export", str(tmp_path), "--allow-untracked"]))
    assert time.perf_counter() - start < 3.0 and "Errno" not in lines[0]
    assert lines == [
        f"mpcform: error: {tmp_path / 'export'}: a file that mpcform did not write (not in a manifest: "
        f"{tmp_path} has none); expected only mpcform's own outputs where it writes: move it away, or "
        "write elsewhere (--out)"
    ]
    assert (tmp_path / "export").read_text() == "x\n"


def test_view_refuses_a_directory_named_viewer_html(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 58, item 15: a raw "[Errno 21] Is a directory"."""
    short_run("worked_example", tmp_path, steps=5)
    (tmp_path / "viewer.html").mkdir()
    lines = error_lines(capsys, main(["view", str(tmp_path)]), f"{tmp_path / 'viewer.html'}: a directory")
    assert len(lines) == 1 and "Errno" not in lines[0]
    (tmp_path / "v.html").write_text("an older page the user names")
    assert main(["view", str(tmp_path), "--out", str(tmp_path / "v.html")]) == 0  # a file named: replaced
    assert "viewer-ready" in (tmp_path / "v.html").read_text()


@pytest.mark.parametrize("command", ["plot", "export"])
def test_plot_and_export_out_take_a_directory_of_their_own(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    short_run("worked_example", tmp_path / "run", steps=5)
    extra = ["--allow-untracked", "--no-flight-check"] if command == "export" else []
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    error_lines(
        capsys, main([command, str(tmp_path / "run"), "--out", str(out), *extra]), "--out: ", "is not empty"
    )
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    out = tmp_path / "new"
    for _ in range(2):  # the second time, its own files are replaced
        assert main([command, str(tmp_path / "run"), "--out", str(out), *extra]) == 0
    listed = json.loads((out / ".mpcform-manifest.json").read_text())
    assert listed["kind"] == ("plots" if command == "plot" else "export")
    assert sorted(listed["entries"]) == sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    error_lines(
        capsys, main([command, str(tmp_path / "run"), "--out", str(tmp_path / "run"), *extra]), "--out: "
    )


def test_export_replaces_its_own_earlier_export_split_or_not(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A split export's parts never sit beside a later export's files; a refused export keeps the
    earlier one whole (it is replaced only once every check passed)."""
    short_run("obstacles_planar", tmp_path, steps=80, flyable=True)
    argv = ["export", str(tmp_path), "--no-flight-check"]
    assert main([*argv, "--tolerance", "0.0002"]) == 0
    parts = sorted((tmp_path / "export").glob("drone000_poly7_part*.csv"))
    assert len(parts) >= 2
    capsys.readouterr()
    error_lines(capsys, main([*argv, "--max-speed", "1e-6"]), "--max-speed")
    assert sorted((tmp_path / "export").glob("drone000_poly7_part*.csv")) == parts
    assert main([*argv, "--tolerance", "0.05"]) == 0
    assert not list((tmp_path / "export").glob("drone*_part*.csv"))
    listed = json.loads((tmp_path / ".mpcform-manifest.json").read_text())["entries"]
    assert sorted(listed) == ["export", *sorted(f"export/{p.name}" for p in (tmp_path / "export").iterdir())]


def test_a_bad_mplbackend_is_one_line(tmp_path: Path) -> None:
    """matplotlib refuses an unknown MPLBACKEND as it loads: named before any work, exit 2."""
    import os
    import subprocess
    import sys

    code = "import sys; from mpcform.cli.main import main; sys.exit(main(sys.argv[1:]))"
    scenario = str(ROOT / "scenarios" / "worked_example.toml")
    env = os.environ | {"MPLBACKEND": "bogus"}
    proc = subprocess.run(
        [sys.executable, "-c", code, "run", scenario, "--out", str(tmp_path / "o"), "--plot"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    said = "MPLBACKEND: 'bogus' is not a matplotlib backend; expected one it knows (Agg), or unset it"
    assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [f"mpcform: error: {said}"]
    assert not (tmp_path / "o" / "trajectory.npz").exists()
