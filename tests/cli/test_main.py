"""The ``mpcform`` command, called through ``main(argv)``: exit codes and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from importlib import metadata, resources
from pathlib import Path

import pytest

from mpcform.cli import main as main_module
from mpcform.cli.main import main
from mpcform.scenario.keys import key_reference_markdown

ROOT = Path(__file__).resolve().parents[2]
WORKED = str(ROOT / "scenarios" / "worked_example.toml")
OWN = (".mpcform-manifest.json", ".mpcform.lock")  # mpcform's bookkeeping in its output directory


def short_copy(tmp_path: Path, replace: tuple[str, str] = ("duration = 10.0", "duration = 0.2")) -> str:
    path = tmp_path / "scenario.toml"
    path.write_text(Path(WORKED).read_text().replace(*replace))
    return str(path)


def assert_one_line_error(capsys: pytest.CaptureFixture[str], status: int, *fragments: str) -> str:
    """Exit status 2, no traceback, and one error line."""
    err = capsys.readouterr().err
    assert status == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    last = lines[-1]
    assert last.startswith("mpcform: error: ")
    for fragment in fragments:
        assert fragment in last
    return last


def test_run_writes_the_outputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["run", WORKED, "--out", str(out)]) == 0
    stdout = capsys.readouterr().out
    assert "final tracking error" in stdout and str(out) in stdout
    assert {p.name for p in out.iterdir()} == {"trajectory.npz", "trajectory.csv", "summary.json", *OWN}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 500 and summary["metrics"]["final_tracking_error"] < 1e-3


def test_a_run_into_an_earlier_runs_directory_replaces_its_outputs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A stale viewer never sits beside the new run's data (the manifest lists it); other files stay."""
    out, path = tmp_path / "r", short_copy(tmp_path)
    assert main(["run", path, "--out", str(out), "--html"]) == 0
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(["run", path, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert (
        f"{out}: replaced the earlier run's trajectory.npz, trajectory.csv, summary.json, "
        "formation.npz, viewer.html" in err
    )
    assert sorted(p.name for p in out.iterdir()) == [
        ".mpcform-manifest.json",
        ".mpcform.lock",
        "notes.txt",
        "summary.json",
        "trajectory.csv",
        "trajectory.npz",
    ]
    assert (out / "notes.txt").read_text() == "mine"


def _never(*args: object, **kwargs: object) -> None:
    raise AssertionError("the simulation ran")


@pytest.mark.parametrize("where", ["root", "home", "project", "project-git"])
def test_out_at_the_root_the_home_or_a_project_root_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    """Issue 58, item 1: ``--out /`` wrote (and would have removed) files in the filesystem root."""
    monkeypatch.setattr(main_module, "run_scenario", _never)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    (tmp_path / "home").mkdir()
    (tmp_path / "project" / ".git").mkdir(parents=True)
    (tmp_path / "project-git").mkdir()
    (tmp_path / "project-git" / "pyproject.toml").write_text("[project]\n")
    out = {"root": "/", "home": str(tmp_path / "home")}.get(where, str(tmp_path / where))
    what = {"root": "the filesystem root", "home": "your home directory"}.get(where, "a project root")
    assert_one_line_error(capsys, main(["run", WORKED, "--out", out]), f"--out: {out!r} is {what}")
    assert sorted(p.name for p in (tmp_path / "home").iterdir()) == []


@pytest.mark.parametrize(
    ("make", "survivor"),
    [
        (lambda o: (o / "trajectory.npz" / "x").mkdir(parents=True), "trajectory.npz/x"),
        (lambda o: ((o / "plots").mkdir(), (o / "plots" / "mine.png").write_text("mine")), "plots/mine.png"),
        (lambda o: ((o / "export").mkdir(), (o / "export" / "fly.py").write_text("mine")), "export/fly.py"),
        (lambda o: (o / "summary.json").write_text("my notes, not JSON"), "summary.json"),
        (lambda o: (o / "plots").write_text("a file named plots"), "plots"),
    ],
)
def test_a_users_files_in_out_are_never_removed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, make, survivor: str
) -> None:
    """Issue 58, item 2: these were removed as "the earlier run's" outputs; now the run is refused."""
    monkeypatch.setattr(main_module, "run_scenario", _never)
    out = tmp_path / "o"
    out.mkdir()
    make(out)
    before = {str(p): p.read_bytes() if p.is_file() else None for p in out.rglob("*")}
    line = assert_one_line_error(
        capsys, main(["run", WORKED, "--out", str(out)]), f"--out: {str(out)!r} is not empty"
    )
    assert "has no .mpcform-manifest.json" in line and (out / survivor).exists()
    assert {
        str(p): p.read_bytes() if p.is_file() else None for p in out.rglob("*") if p.name != ".mpcform.lock"
    } == before


def test_out_at_a_dangling_symbolic_link_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 58, item 12: it read "cannot create 'o': File exists"."""
    monkeypatch.setattr(main_module, "run_scenario", _never)
    (tmp_path / "o").symlink_to(tmp_path / "gone")
    status = main(["run", WORKED, "--out", str(tmp_path / "o")])
    assert_one_line_error(capsys, status, "is a symbolic link to", "which does not exist")
    assert not (tmp_path / "gone").exists()


def test_a_second_run_into_the_same_directory_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 58, item 16: two runs into one --out both went ahead; the lock refuses the second."""
    from mpcform.outputs.outdir import RUN_LAYOUT, claim_dir

    monkeypatch.setattr(main_module, "run_scenario", _never)
    with claim_dir(tmp_path / "o", "run", tuple(RUN_LAYOUT)):  # a run in progress (held as one would)
        status = main(["run", WORKED, "--out", str(tmp_path / "o")])
    assert_one_line_error(
        capsys, status, f"--out: {str(tmp_path / 'o')!r} is being written by another mpcform command (pid"
    )


@pytest.mark.parametrize(
    ("solver", "why"),
    [("qpsolvers:quadprog", "unsupported: needs a positive-definite P"), ("qpsolvers:scs", "")],
)
def test_a_solver_that_cannot_run_is_refused_before_the_run(
    solver: str, why: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One line naming --solver (it came without the flag, from inside the run); scs: whichever of
    'not installed' or nothing applies here."""
    from mpcform.solvers.registry import solver_info

    if solver_info(solver).usable:
        pytest.skip(f"{solver} is usable here")
    assert main(["run", WORKED, "--out", str(tmp_path / "o"), "--solver", solver]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f"mpcform: error: --solver: '{solver}': ") and why in line
    assert not (tmp_path / "o" / "summary.json").exists()


def test_run_default_out_dir_is_relative_to_the_working_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    path = short_copy(tmp_path)
    monkeypatch.chdir(tmp_path)
    assert main(["run", path, "--controller", "proportional"]) == 0
    summary = json.loads((tmp_path / "results" / "worked_example" / "summary.json").read_text())
    assert summary["controller"] == "proportional" and summary["steps"] == 10


def test_run_mpc_with_solver(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("mpcform.mpc.planner")
    path = short_copy(tmp_path)
    assert main(["run", path, "--out", str(tmp_path / "o"), "--controller", "mpc", "--solver", "osqp"]) == 0
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["controller"] == "mpc" and summary["solver"] == "osqp"


def test_validate(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", WORKED]) == 0
    out = capsys.readouterr().out.strip()
    assert out.startswith("OK worked_example: 3 drones") and "\n" not in out


def test_validate_warns_when_the_plant_margin_exceeds_the_final_spacing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """OK and exit 0, plus one warning line naming the spacing, the kept distance and the remedies."""
    flight = Path(WORKED).parent / "formation_flight_100.toml"
    path = tmp_path / "slow.toml"
    text = flight.read_text().replace('kind = "mpc"', 'kind = "mpc"\nplant_model = false')
    path.write_text(text + '\n[plant]\nkind = "lag"\ntime_constant = 0.3\n')
    assert main(["validate", str(path)]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("OK formation_flight_100")
    (line,) = captured.err.strip().splitlines()
    assert line.startswith(f"mpcform: warning: {path}: plant:") and "0.6 m apart" in line


@pytest.mark.parametrize(
    ("replace", "fragments"),
    [
        (("gain = 2.0", "gian = 2.0"), ("controller.gian", "did you mean 'gain'")),
        (("gain = 2.0", "gain = 200.0"), ("controller.gain", "gain * dt")),
        (("gain = 2.0", "gain = nan"), ("controller.gain", "finite")),
        (("scale = 2.0", "scale = 0"), ("reference.scale", "> 0")),
        (("[limits]", "[limit]"), ("limit", "did you mean 'limits'")),
        (("dim = 2", 'dim = "two"'), ("dim", "'two'")),
        (("rate = 1.0", "rate = "), ("TOML syntax error", "line 24")),
    ],
)
@pytest.mark.parametrize("command", ["run", "validate"])
def test_bad_scenario_exits_2_with_one_line(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    replace: tuple[str, str],
    fragments: tuple[str, ...],
) -> None:
    path = short_copy(tmp_path, replace)
    status = main([command, path, *(["--out", str(tmp_path / "o")] if command == "run" else [])])
    assert_one_line_error(capsys, status, *fragments)
    assert not (tmp_path / "o").exists()


def test_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    status = main(["run", str(tmp_path / "missing.toml")])
    assert_one_line_error(capsys, status, "missing.toml", "no such scenario file")


@pytest.mark.parametrize(
    ("argv", "fragments"),
    [
        (["run", WORKED, "--controller", "trackin"], ("--controller", "did you mean 'tracking'")),
        (["run", WORKED, "--solver", "osqp"], ("only to the mpc controller",)),
        (["run", WORKED, "--controller", "mpc", "--solver", "nope"], ("solver", "unknown solver")),
        (
            ["run", str(ROOT / "scenarios" / "formation_flight_100.toml"), "--solver", "osqp"],
            ("solver: 'osqp' solves the sparse QP", "set kind = 'sparse'"),
        ),  # decoupled, per drone
    ],
)
def test_bad_overrides(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], fragments: tuple[str, ...]
) -> None:
    assert_one_line_error(capsys, main([*argv, "--out", str(tmp_path)]), *fragments)


@pytest.mark.parametrize(
    "argv", [[], ["run"], ["frobnicate"], ["run", WORKED, "--bogus"], ["validate", "a", "b"]]
)
def test_usage_errors_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    """One line naming what is wrong and where the help is: no usage block."""
    assert_one_line_error(capsys, main(argv), "--help`)")


def test_solvers_lists_backends(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solvers"]) == 0
    lines = capsys.readouterr().out.splitlines()
    names = {line.split()[0]: line.split()[1] for line in lines[1:]}
    assert names["osqp"] == "yes"
    for name in ("piqp", "casadi:osqp", "casadi:qpoases", "casadi:hpipm", "casadi:ipopt"):
        assert names[name] in ("yes", "no")
    assert all(state in ("yes", "no") for state in names.values())


def test_keys_prints_the_key_reference(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["keys"]) == 0
    assert capsys.readouterr().out == key_reference_markdown()


# ---- version, help, key schema -------------------------------------------------------------------
def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"mpcform {metadata.version('mpcform')}"


def test_run_help_lists_the_controllers_solvers_and_plants(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "override controller.kind: proportional, tracking, mpc, consensus, nullspace" in text
    assert "osqp, piqp (default), qpsolvers:<name>, casadi:<plugin>" in text
    assert "--plant KIND override plant.kind: ideal, lag, second_order, quadrotor" in text


def test_keys_json_schema(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["keys", "--json-schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert "template" in schema["$defs"]


def test_the_package_ships_its_type_marker() -> None:
    assert (resources.files("mpcform") / "py.typed").is_file()


# ---- runs too large, bad output paths ------------------------------------------------------------
MPC = ('kind = "tracking"', 'kind = "mpc"')
HUGE = [
    ([("duration = 10.0", "duration = 1e9")], "simulation.duration", "50,000,000,001 samples x 3 drones"),
    ([MPC, ("gain = 2.0", "gain = 2.0\nhorizon = 1000000")], "controller.horizon", "horizon of 1,000,000"),
    ([MPC, ("n = 3", "n = 5000"), ("radius = 1.0", "radius = 1.5")], "template.n", "pairs within reach"),
]


@pytest.mark.parametrize(("changes", "key", "fragment"), HUGE, ids=["duration", "horizon", "drones"])
@pytest.mark.parametrize("command", ["run", "validate"])
def test_a_run_too_large_is_refused_fast(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    changes: list[tuple[str, str]],
    key: str,
    fragment: str,
) -> None:
    text = Path(WORKED).read_text()
    for old, new in changes:
        text = text.replace(old, new)
    path = tmp_path / "huge.toml"
    path.write_text(text)
    start = time.perf_counter()
    status = main([command, str(path), *(["--out", str(tmp_path / "o")] if command == "run" else [])])
    assert time.perf_counter() - start < 5.0
    line = assert_one_line_error(capsys, status, f"{path}:", f": {key}: the run would need about ", fragment)
    assert "above the limit of 4 GiB" in line and "--max-memory GIB" in line
    assert not (tmp_path / "o").exists()


def test_max_memory_raises_the_limit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = short_copy(tmp_path, ("duration = 10.0", "duration = 1e4"))  # 500,000 steps: ~0.8 GiB
    assert_one_line_error(capsys, main(["validate", path, "--max-memory", "0.5"]), "simulation.duration")
    assert main(["validate", path, "--max-memory", "2"]) == 0


def test_out_naming_a_file_fails_before_the_simulation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("the simulation ran")

    monkeypatch.setattr(main_module, "run_scenario", never)
    (tmp_path / "file").write_text("x")
    status = main(["run", WORKED, "--out", str(tmp_path / "file")])
    assert_one_line_error(capsys, status, "--out: ", "existing file")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "results").write_text("x")  # the default results/<name>/ cannot be made
    assert_one_line_error(capsys, main(["run", WORKED]), "--out: cannot create", "is a file")


@pytest.mark.parametrize(
    ("argv", "flag"),
    [
        (["sweep", WORKED, "--json", "{missing}/rows.json"], "--json"),
        (["sweep", WORKED, "--json", "{dir}"], "--json"),
        (["bench", "closed-loop", WORKED, "--report", "{missing}/r.md"], "--report"),
        (["problems", "export", WORKED, "--out", "{file}"], "--out"),
        (["compare", "{dir}", "--json", "{missing}/c.json"], "--json"),
    ],
)
def test_output_paths_are_checked_before_the_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], flag: str
) -> None:
    (tmp_path / "file").write_text("x")
    names = {"missing": str(tmp_path / "missing"), "dir": str(tmp_path), "file": str(tmp_path / "file")}
    start = time.perf_counter()
    status = main([a.format(**names) for a in argv])
    assert time.perf_counter() - start < 5.0
    assert_one_line_error(capsys, status, f"mpcform: error: {flag}: ")


# ---- validate's lines, run's located errors, a closed pipe ---------------------------------------
def test_validate_lines_are_file_line_key_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = Path(WORKED).read_text().replace('kind = "tracking"', 'kind = "mpc"\nhroizon = 5')
    path = tmp_path / "s.toml"
    path.write_text(text.replace("v_max = 3.0\n", ""))  # the MPC needs v_max with d_min
    assert main(["validate", str(path)]) == 2
    lines = capsys.readouterr().err.splitlines()
    line = next(k for k, row in enumerate(path.read_text().splitlines(), 1) if row.startswith("hroizon"))
    assert lines[0].startswith(f"mpcform: error: {path}:{line}: controller.hroizon: unknown key")
    assert lines[1].startswith(f"mpcform: error: {path}: limits.v_max: the MPC needs v_max")  # no line
    assert lines[2] == f"mpcform: 2 problems in {path}"


def test_run_errors_name_the_file_and_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = short_copy(tmp_path, ("gain = 2.0", "gain = 200.0"))
    line = next(k for k, row in enumerate(Path(path).read_text().splitlines(), 1) if row.startswith("gain"))
    assert_one_line_error(
        capsys,
        main(["run", path, "--out", str(tmp_path / "o")]),
        f"mpcform: error: {path}:{line}: controller.gain: ",
    )


def test_a_closed_pipe_ends_quietly_with_status_141() -> None:
    code = "import sys; from mpcform.cli.main import main; sys.exit(main(['keys']))"
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the reader is gone before the first line is written
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141 and err == ""


def test_run_with_a_plant_override_reports_the_true_motion(tmp_path, capsys):
    swap = str(ROOT / "scenarios" / "swap_planar_8.toml")
    status = main(["run", swap, "--plant", "lag", "--out", str(tmp_path)])
    assert status == 0
    out = capsys.readouterr().out
    assert "true motion" in out and "lag plant" in out
    plant = json.loads((tmp_path / "summary.json").read_text())["plant"]
    assert plant["kind"] == "lag" and plant["velocity_loop_modelled"] is True


def test_unknown_plant_kind_is_a_usage_error(capsys):
    assert main(["run", str(ROOT / "scenarios" / "swap_planar_8.toml"), "--plant", "rocket"]) == 2
    assert "--plant" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("controller", "table", "key"),
    [
        ('coupling = "decoupled"\neps_abs = 1e-6', "", "controller.eps_abs"),
        ('coupling = "decoupled"', 'kind = "per_drone"\neps_abs = 1e-6', "controller.solve.eps_abs"),
        ("", 'kind = "per_drone"', "controller.solve.kind"),
        ("per_drone = true", "", "controller.per_drone"),
    ],
)
def test_an_ignored_solve_setting_is_one_error_line_in_either_spelling(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], controller: str, table: str, key: str
) -> None:
    path = tmp_path / "s.toml"
    text = Path(WORKED).read_text().replace('kind = "tracking"', f'kind = "mpc"\n{controller}')
    path.write_text(text + (f"\n[controller.solve]\n{table}\n" if table else ""))
    assert main(["validate", str(path)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f"mpcform: error: {path}:") and f": {key}: " in line


def test_an_old_solve_key_loads_with_one_deprecation_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "s.toml"
    path.write_text(Path(WORKED).read_text().replace('kind = "tracking"', 'kind = "mpc"\nmax_iter = 100'))
    assert main(["validate", str(path)]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("OK worked_example")
    (line,) = captured.err.strip().splitlines()
    assert line.endswith(
        f"{path}: controller.max_iter is deprecated: write [controller.solve] max_iter = 100"
    )


def test_solvers_lists_the_per_drone_backends(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solvers", "--per-drone"]) == 0
    lines = capsys.readouterr().out.splitlines()
    names = {line.split()[0]: line.split()[2] for line in lines[1:]}
    assert names["daqp"] == "yes" and "qpsolvers:quadprog" in names and "osqp" not in names


def test_ctrl_c_during_a_run_is_one_line_and_status_130(tmp_path: Path) -> None:
    """SIGINT while the planner runs: no traceback, one line, the shell's status for Ctrl-C."""
    import signal

    swap, out = str(ROOT / "scenarios" / "swap_spatial_20.toml"), str(tmp_path)
    run = f"sys.exit(main(['run', {swap!r}, '--out', {out!r}]))"
    code = f"import sys; from mpcform.cli.main import main; print('ready', flush=True); {run}"
    code = f"import signal; signal.signal(signal.SIGINT, signal.default_int_handler); {code}"  # not ignored
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stdout.readline() == b"ready\n"  # imported
    time.sleep(1.0)  # inside the run (it plans for a minute)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.decode().strip().splitlines() == ["mpcform: interrupted"]


def test_an_empty_out_is_refused_before_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    status = main(["run", WORKED, "--out", ""])
    assert_one_line_error(capsys, status, "--out: expected a path, got ''")
    assert list(tmp_path.iterdir()) == []  # nothing written into the current directory


@pytest.mark.parametrize("command", ["run", "validate"])
@pytest.mark.parametrize(
    ("scenario", "change", "says"),
    [
        ("swap_planar_8", ("\nn = 8\n", "\nn = 1000000000\n"), "template.n: 1,000,000,000 drones would need"),
        (
            "formation_flight_100",
            ("\nrows = 10\ncols = 10\n", "\nrows = 100000\ncols = 100000\n"),
            "template.rows: 10,000,000,000 drones would need",
        ),
        ("swap_spatial_12_quadrotor_wind", ("\nrate = 500\n", "\nrate = 1000000\n"), "plant.rate: the plant"),
    ],
    ids=["n", "grid", "plant-rate"],
)
def test_too_many_drones_or_plant_steps_are_one_line_before_any_work(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    scenario: str,
    change: tuple[str, str],
    says: str,
) -> None:
    text = (ROOT / "scenarios" / f"{scenario}.toml").read_text()
    assert change[0] in text
    path = tmp_path / "big.toml"
    path.write_text(text.replace(*change))
    status = main([command, str(path), *(["--out", str(tmp_path / "o")] if command == "run" else [])])
    line = assert_one_line_error(capsys, status, f"{path}:", says)
    assert "--max-memory GIB" in line or "--max-work N" in line
    assert not (tmp_path / "o").exists()


def test_max_work_raises_the_plant_limit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = (ROOT / "scenarios" / "swap_spatial_12_quadrotor_wind.toml").read_text()
    path = tmp_path / "fast.toml"
    path.write_text(text.replace("\nrate = 500\n", "\nrate = 1000000\n"))
    assert main(["validate", str(path), "--max-work", "2e8"]) == 0
    capsys.readouterr()  # its OK line and the scenario's own warning
    assert_one_line_error(capsys, main(["validate", str(path), "--max-work", "1e8"]), "plant.rate")


def test_a_run_that_ends_incomplete_says_which_drones_and_how_far(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The 8-drone swap cut to 2 s: drones are still on their way; the summary, the table and one
    warning say which and how far."""
    text = (ROOT / "scenarios" / "swap_planar_8.toml").read_text()
    path = tmp_path / "short.toml"
    path.write_text(text.replace("duration = ", "duration = 2.0 #", 1))
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 0
    out, err = capsys.readouterr()
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    m = summary["metrics"]
    assert m["completion"] < 1.0 and len(m["incomplete_drones"]) == round(8 * (1 - m["completion"]))
    assert all(d > 0.1 for d in m["incomplete_distances_m"])
    assert "not arrived" in out
    lines = [line for line in err.splitlines() if "incomplete" in line]
    assert len(lines) == 1 and lines[0].startswith("mpcform: warning: the run ended incomplete: ")
    assert f"{len(m['incomplete_drones'])} of 8 drones" in lines[0]
