"""Polynomial and setpoint CSVs: the uav_trajectories layout, exact round trips, bad headers refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.outputs.flight.files import (
    POLY_HEADER,
    SETPOINT_COLUMNS,
    read_poly,
    read_setpoints,
    write_poly,
    write_setpoints,
)


def test_poly_round_trip_in_two_parts(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    coef = rng.normal(size=(5, 4, 8))
    durations = rng.uniform(0.5, 2.0, 5)
    write_poly(tmp_path / "a.csv", durations[:3], coef[:3])
    write_poly(tmp_path / "b.csv", durations[3:], coef[3:])
    assert (tmp_path / "a.csv").read_text().splitlines()[0] == ",".join(POLY_HEADER)
    assert len(POLY_HEADER) == 33 and POLY_HEADER[25] == "yaw^0"
    poly = read_poly([tmp_path / "a.csv", tmp_path / "b.csv"])
    assert np.array_equal(poly.durations_s, durations) and np.array_equal(poly.coefficients, coef)
    (tmp_path / "bad.csv").write_text("t,x\n1,2\n")
    with pytest.raises(ValidationError, match="unexpected header"):
        read_poly([tmp_path / "bad.csv"])


def test_setpoint_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 1.0, 11)
    state = {k: rng.normal(size=(11, 2, 3)) for k in ("pos", "vel", "acc", "omega")}
    state |= {"t": t, "yaw": rng.normal(size=(11, 2))}
    write_setpoints(tmp_path / "s.csv", state, 1)
    cols = read_setpoints(tmp_path / "s.csv")
    assert tuple(cols) == SETPOINT_COLUMNS
    assert np.array_equal(cols["t"], t) and np.array_equal(cols["yaw"], state["yaw"][:, 1])
    assert np.array_equal(
        np.column_stack([cols["omega_x"], cols["omega_y"], cols["omega_z"]]), state["omega"][:, 1]
    )
    assert np.array_equal(np.column_stack([cols["vx"], cols["vy"], cols["vz"]]), state["vel"][:, 1])
