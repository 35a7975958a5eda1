"""crazyflies.yaml and fly.py: parsed, and fly.py run against a fake of the crazyflie_py calls it uses."""

from __future__ import annotations

import ast
import runpy
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from mpcform.outputs.flight.crazyswarm import CRAZYFLIE_MAX_PIECES, FLY_PY, crazyflies_yaml, write_files
from mpcform.outputs.flight.files import POLY_HEADER


def _poly_file(path: Path, pieces: int, start: list[float]) -> None:
    rows = []
    for _ in range(pieces):
        row = [0.5] + [0.0] * 32
        row[1], row[9], row[17] = start
        rows.append(",".join(map(str, row)))
    path.write_text(",".join(POLY_HEADER) + "\n" + "\n".join(rows) + "\n")


def _fake_crazyflie_py(calls: list[tuple]) -> dict[str, types.ModuleType]:
    """Crazyswarm(), .allcfs (crazyfliesByName, takeoff, startTrajectory, land), .timeHelper.sleep,
    Crazyflie.uploadTrajectory / goTo, and uav_trajectory.Trajectory (loadcsv, n_pieces)."""

    class Trajectory:
        def loadcsv(self, filename):
            self.rows = np.loadtxt(filename, delimiter=",", skiprows=1, usecols=range(33), ndmin=2)

        def n_pieces(self):
            return len(self.rows)

    class Crazyflie:
        def __init__(self, name):
            self.name = name

        def uploadTrajectory(self, trajectoryId, pieceOffset, trajectory):  # noqa: N802, N803
            calls.append(("upload", self.name, trajectoryId, pieceOffset, trajectory.n_pieces()))

        def goTo(self, goal, yaw, duration, relative=False, groupMask=0):  # noqa: N802, N803
            calls.append(("goTo", self.name, list(goal), yaw, duration, relative))

    class Server:
        def __init__(self):
            self.crazyfliesByName = {f"cf{i}": Crazyflie(f"cf{i}") for i in (1, 2)}  # noqa: N815

        def takeoff(self, targetHeight, duration, groupMask=0):  # noqa: N803
            calls.append(("takeoff", targetHeight, duration))

        def startTrajectory(self, trajectoryId, timescale=1.0, reverse=False, relative=True, groupMask=0):  # noqa: N802, N803
            calls.append(("startTrajectory", trajectoryId, timescale, reverse, relative))

        def land(self, targetHeight, duration, groupMask=0):  # noqa: N803
            calls.append(("land", targetHeight, duration))

    class TimeHelper:
        def sleep(self, duration):
            calls.append(("sleep", duration))

    class Crazyswarm:
        def __init__(self):
            self.allcfs, self.timeHelper = Server(), TimeHelper()  # noqa: N815

    package = types.ModuleType("crazyflie_py")
    package.Crazyswarm = Crazyswarm  # type: ignore[attr-defined]
    uav = types.ModuleType("crazyflie_py.uav_trajectory")
    uav.Trajectory = Trajectory  # type: ignore[attr-defined]
    return {"crazyflie_py": package, "crazyflie_py.uav_trajectory": uav}


def _export(tmp_path: Path, pieces: int) -> Path:
    start = np.array([[0.0, 0.0, 1.0], [1.0, 0.5, 1.5]])
    for i in range(2):
        _poly_file(tmp_path / f"drone{i:03d}_poly7.csv", pieces, start[i].tolist())
    write_files(tmp_path, ["drone000", "drone001"], start, 12.5)
    return tmp_path / FLY_PY


def test_fly_script_parses_and_flies_the_sequence(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fly = _export(tmp_path, 3)
    tree = ast.parse(fly.read_text())
    names = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
    assert {"uploadTrajectory", "startTrajectory", "takeoff", "goTo", "land", "loadcsv"} <= names
    calls: list[tuple] = []
    for name, module in _fake_crazyflie_py(calls).items():
        monkeypatch.setitem(sys.modules, name, module)
    runpy.run_path(str(fly), run_name="__main__")
    kinds = [c[0] for c in calls if c[0] != "sleep"]
    assert kinds == ["upload", "upload", "takeoff", "goTo", "goTo", "startTrajectory", "land"]
    assert calls[0] == ("upload", "cf1", 0, 0, 3)
    assert ("takeoff", 1.0, 2.5) in calls
    assert ("goTo", "cf2", [1.0, 0.5, 1.5], 0.0, 3.0, False) in calls
    assert ("startTrajectory", 0, 1.0, False, False) in calls  # absolute positions
    assert any(c[0] == "sleep" and c[1] >= 12.5 for c in calls)


def test_fly_script_refuses_more_than_31_pieces(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fly = _export(tmp_path, CRAZYFLIE_MAX_PIECES + 1)
    calls: list[tuple] = []
    for name, module in _fake_crazyflie_py(calls).items():
        monkeypatch.setitem(sys.modules, name, module)
    with pytest.raises(SystemExit, match="drone000_poly7.csv has 32 pieces; the Crazyflie holds 31"):
        runpy.run_path(str(fly), run_name="__main__")
    assert calls == []  # nothing flew


def test_crazyflies_yaml_snippet() -> None:
    text = crazyflies_yaml(np.array([[0.5, -1.0, 1.2], [2.0, 0.0, 1.0]]))
    lines = text.splitlines()
    assert "robots:" in lines and "  cf1:" in lines and "  cf2:" in lines
    assert "    enabled: true" in lines and "    type: cf21" in lines
    assert "    initial_position: [0.5000, -1.0000, 0.0]" in lines  # on the floor below the start
    assert sum(line.strip().startswith("uri: radio://") for line in lines) == 2


def test_fly_script_refuses_a_split_export(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fly = _export(tmp_path, 3)
    for i in range(2):  # what export writes above 31 pieces: parts, no whole file
        whole = tmp_path / f"drone{i:03d}_poly7.csv"
        for part in (1, 2):
            (tmp_path / f"drone{i:03d}_poly7_part{part}.csv").write_text(whole.read_text())
        whole.unlink()
    calls: list[tuple] = []
    for name, module in _fake_crazyflie_py(calls).items():
        monkeypatch.setitem(sys.modules, name, module)
    message = (
        r"drone000_poly7.csv is split into 2 files \(drone000_poly7_part1.csv, drone000_poly7_part2.csv\)"
    )
    with pytest.raises(SystemExit, match=message):
        runpy.run_path(str(fly), run_name="__main__")
    assert calls == []  # nothing flew


def test_crazyflies_yaml_prints_no_negative_zero() -> None:
    text = crazyflies_yaml(np.array([[-0.0, -0.00001, 1.0], [-1e-9, 2.0, 1.0]]))
    assert "-0.0000" not in text and "    initial_position: [0.0000, 0.0000, 0.0]" in text
