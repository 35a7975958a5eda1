"""crazyflies.yaml and fly.py: parsed, and fly.py run against a fake of the crazyflie_py calls it uses."""

from __future__ import annotations

import ast
import runpy
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.outputs.flight.crazyswarm import (
    CRAZYFLIE_MAX_PIECES,
    FLY_PY,
    crazyflies_yaml,
    read_pads,
    write_files,
)
from mpcform.outputs.flight.files import POLY_HEADER
from mpcform.outputs.flight.phases import Flight


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
    """Two drones taking off from (0, 0) and (1, 0.5) on a floor at z = 0.1 to 0.4 m, then an
    ascent of 3 s and a mission of 12.5 s."""
    ground = np.array([[0.0, 0.0], [1.0, 0.5]])
    start = np.column_stack([ground, [0.4, 0.4]])
    for i in range(2):
        for tag in ("_ascent", ""):
            _poly_file(tmp_path / f"drone{i:03d}{tag}_poly7.csv", pieces, start[i].tolist())
    phases = (("ascent", slice(0, 1)), ("mission", slice(0, 1)))
    flight = Flight(start[None], 0.1, phases, ground, ground + 1.0, 0.1, 0.4, 1.7, 1.9)
    write_files(tmp_path, ["drone000", "drone001"], flight, [("ascent", 3.0), ("mission", 12.5)])
    return tmp_path / FLY_PY


def test_fly_script_parses_and_flies_the_sequence(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fly = _export(tmp_path, 3)
    tree = ast.parse(fly.read_text())
    names = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
    assert {"uploadTrajectory", "startTrajectory", "takeoff", "land", "loadcsv"} <= names
    assert "goTo" not in names  # every move is planned: no unchecked goTo
    calls: list[tuple] = []
    for name, module in _fake_crazyflie_py(calls).items():
        monkeypatch.setitem(sys.modules, name, module)
    runpy.run_path(str(fly), run_name="__main__")
    kinds = [c[0] for c in calls if c[0] != "sleep"]
    flown = ["upload", "upload", "takeoff", "startTrajectory", "upload", "upload", "startTrajectory", "land"]
    assert kinds == flown  # each phase uploaded while they hover, then started together
    assert calls[0] == ("upload", "cf1", 0, 0, 3)
    assert ("takeoff", pytest.approx(0.3), 1.7) in calls  # to the hover, 0.3 m above the floor
    assert ("startTrajectory", 0, 1.0, False, False) in calls  # absolute positions
    assert ("land", 0.04, 1.9) in calls
    sleeps = [c[1] for c in calls if c[0] == "sleep"]
    assert sleeps == [pytest.approx(2.2), pytest.approx(3.5), pytest.approx(13.0), pytest.approx(2.4)]


def test_fly_script_refuses_more_than_31_pieces(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fly = _export(tmp_path, CRAZYFLIE_MAX_PIECES + 1)
    calls: list[tuple] = []
    for name, module in _fake_crazyflie_py(calls).items():
        monkeypatch.setitem(sys.modules, name, module)
    with pytest.raises(SystemExit, match="drone000_ascent_poly7.csv has 32 pieces; the Crazyflie holds 31"):
        runpy.run_path(str(fly), run_name="__main__")
    assert calls == []  # nothing flew


def test_crazyflies_yaml_snippet() -> None:
    text = crazyflies_yaml(np.array([[0.5, -1.0, 0.0], [2.0, 0.0, 0.0]]))
    lines = text.splitlines()
    assert "robots:" in lines and "  cf1:" in lines and "  cf2:" in lines
    assert "    enabled: true" in lines and "    type: cf21" in lines
    assert "    initial_position: [0.5000, -1.0000, 0.0000]" in lines  # its place on the floor
    assert sum(line.strip().startswith("uri: radio://") for line in lines) == 2


def test_fly_script_refuses_a_split_export(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fly = _export(tmp_path, 3)
    for i in range(2):  # what export writes above 31 pieces: parts, no whole file
        whole = tmp_path / f"drone{i:03d}_ascent_poly7.csv"
        for part in (1, 2):
            (tmp_path / f"drone{i:03d}_ascent_poly7_part{part}.csv").write_text(whole.read_text())
        whole.unlink()
    calls: list[tuple] = []
    for name, module in _fake_crazyflie_py(calls).items():
        monkeypatch.setitem(sys.modules, name, module)
    message = (
        r"drone000_ascent_poly7.csv is split into 2 files "
        r"\(drone000_ascent_poly7_part1.csv, drone000_ascent_poly7_part2.csv\)"
    )
    with pytest.raises(SystemExit, match=message):
        runpy.run_path(str(fly), run_name="__main__")
    assert calls == []  # nothing flew


def test_crazyflies_yaml_prints_no_negative_zero() -> None:
    text = crazyflies_yaml(np.array([[-0.0, -0.00001, -0.0], [-1e-9, 2.0, 0.0]]))
    assert "-0.0000" not in text and "    initial_position: [0.0000, 0.0000, 0.0000]" in text


def test_pads_are_read_from_a_crazyflies_yaml(tmp_path: Path) -> None:
    path = tmp_path / "crazyflies.yaml"
    path.write_text(crazyflies_yaml(np.array([[0.0, 1.0, 0.0], [2.5, -1.0, 0.0]])))  # our own, read back
    pads, robots = read_pads(path)
    assert pads == ((0.0, 1.0), (2.5, -1.0))
    assert robots == (("cf1", "radio://0/80/2M/E7E7E7E701"), ("cf2", "radio://0/80/2M/E7E7E7E702"))
    path.write_text(
        "robots:\n  cf1:\n    enabled: false\n    initial_position: [0, 0, 0]\n"
        "  cf7:\n    initial_position: [1, 2, 0]\n"
    )
    assert read_pads(path) == (((1.0, 2.0),), (("cf7", ""),))  # a disabled robot has no pad; no uri
    for bad, pattern in (
        ("robots:\n  cf1:\n    initial_position: [0, nope]\n", r"robot cf1: expected initial_position"),
        ("robots:\n  cf 1:\n    initial_position: [0, 0, 0]\n", r"robot 'cf 1': expected a ROS name"),
        (
            "robots:\n  cf1:\n    uri: 'radio: x\\n'\n    initial_position: [0, 0, 0]\n",
            r"cf1: expected a uri",
        ),
        ("robots:\n  cf1:\n    enabled: false\n    initial_position: [0, 0, 0]\n", r"no enabled robot"),
    ):
        path.write_text(bad)
        with pytest.raises(ValidationError, match=r"^ground: .*" + pattern):
            read_pads(path)
    with pytest.raises(ValidationError, match=r"^ground: cannot read"):
        read_pads(tmp_path / "missing.yaml")


@pytest.mark.parametrize(
    ("kind", "says"),
    [
        ("device", "is a character device, not a regular file; expected a crazyflies.yaml"),
        ("sparse", r"is 1 GiB \(1,073,741,824 bytes\); expected a crazyflies.yaml .*at most 1 MiB"),
        ("directory", "is a directory, not a regular file"),
        ("nan", r"robot cf1: expected initial_position \[x, y, z\], got \[nan, 0, 0\]"),
        ("binary", "as YAML"),
    ],
)
def test_a_ground_file_is_size_checked_before_it_is_read(tmp_path: Path, kind: str, says: str) -> None:
    """Issue 58: ``--ground /dev/zero`` read without end; a NaN pad was taken."""
    path = tmp_path / "crazyflies.yaml"
    if kind == "device":
        path.symlink_to("/dev/zero")
    elif kind == "sparse":
        with open(path, "wb") as f:
            f.truncate(2**30)
    elif kind == "directory":
        path.mkdir()
    else:
        path.write_bytes(
            b"\xff\xfe\x00" if kind == "binary" else b"robots:\n  cf1:\n    initial_position: [.nan, 0, 0]\n"
        )
    with pytest.raises(ValidationError, match=r"^ground: .*" + says):
        read_pads(path)
