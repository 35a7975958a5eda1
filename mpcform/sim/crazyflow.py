"""crazyflow as a plant: the planner's setpoints flown by the Crazyflie firmware's Mellinger controller.

crazyflow (utiasDSL/learnsyslab, ``pip install -e ".[crazyflow]"``) simulates Crazyflie 2.x drones
with the first-principles dynamics of drone-models at ``physics_hz`` (500 Hz) and the firmware's
Mellinger state controller at ``control_hz`` (100 Hz). Every interval, each drone gets the
full-state setpoints of :func:`mpcform.control.setpoints.interval_setpoints` from where it is at
the interval's start: the same setpoints :class:`mpcform.online.loop.OnlineLoop` gives a real
swarm, but for held drones. The true path is every physics step (dense samples: position,
velocity, attitude).

A **held** drone (a command within :data:`HOLD_MPS` of zero: every step fell back, planning
stopped for it, or its controller commands nothing) keeps its setpoints anchored instead: the
path starts where the last interval's ended, not at the measurement, so the firmware's position
loop sees the error of the Mellinger loop's steady sag and corrects it (restarted at the
measurement every 0.1 s, a held cf2x_L250 sank 8.4 cm/s). The anchor is kept within
:data:`~mpcform.world.limits.PLATFORM_TRACKING_M` of the measurement (the planner's tracking
allowance for a Crazyflie), and is dropped when the drone moves again.

crazyflow runs in a worker process (:mod:`mpcform.sim.crazyflow_worker`: it needs
``SCIPY_ARRAY_API=1`` before scipy loads); its simulator is built and compiled once per run, at
:meth:`~mpcform.sim.plants.Plant.reset` (``setup_s`` records how long that took).

The scenario's origin is ``altitude_m`` above crazyflow's floor: planar flights fly at that
height, spatial ones are lifted by it (every drone must start at least two body radii up). The
plant watches what a planner must never cause, on the dense 3-D path: **contacts** between two
drones (centres closer than twice the body radius, the rotor tips' ``sqrt(2) L + prop_radius``
of the drone-models parameters: 0.070 m for cf2x_L250),
**floor contacts** (a centre below the body radius) and **flips** (the body's z axis pointing
down). A drone that touched the floor or flipped is reported in :attr:`CrazyflowPlant.events`
and is lost (:attr:`CrazyflowPlant.lost_drones`): the simulation stops planning for it (its
setpoints then hold it, anchored where planning stopped, as a ground station would until the
operator cuts its motors).

Wind (``[plant.wind]``, :mod:`mpcform.sim.wind`: the plant's seeded field, sampled at
``physics_hz``, per drone) acts as the quadrotor plant's does, through drag: before every physics
step each drone's ``states.force`` (crazyflow's external force on the centre of mass, held over
the step) is ``-R D R^T w``, the wind's share of the drag ``R D R^T (v - w)`` with the quadrotor
plant's drag matrix ``D`` of the platform (so_rpy_rotor_drag) and the attitude ``R`` at the step's
start (:func:`mpcform.sim.crazyflow_worker.wind_force_N`); crazyflow's own drag acts on the
velocity. The same wind and seed give the same gusts as on the quadrotor plant at the same rate.

The planner models a crazyflow drone by the quadrotor plant's hover linearisation of the same
platform (:class:`mpcform.sim.plant_spec.CrazyflowPlantSpec`), and plans for it with a Crazyflie's
tracking allowance and, in space, climb rate (:func:`mpcform.scenario.plant.planned_for_its_plant`).
"""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
import tempfile
import tomllib
import weakref
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.control.setpoints import FullState, interval_setpoints, ticks_per_interval
from mpcform.errors import MPCFormError, ValidationError
from mpcform.sim import so_rpy
from mpcform.sim.plants import Plant
from mpcform.sim.so_rpy import package_file
from mpcform.world.limits import PLATFORM_TRACKING_M

DRONES = ("cf2x_L250", "cf2x_P250", "cf2x_T350", "cf21B_500")
"""The Crazyflie 2.x models crazyflow simulates."""

HOLD_MPS = 1e-3
"""A command this close to zero [m/s] holds the drone: its setpoints stay anchored (module docstring)."""


def body_radius_m(drone: str) -> float:
    """The rotor tips' distance from the centre [m]: ``sqrt(2) L + prop_radius`` (drone-models'
    ``data/params.toml``, read without importing drone-models)."""
    with open(package_file("data/params.toml"), "rb") as fh:
        params = tomllib.load(fh)[drone]
    return math.sqrt(2.0) * float(params["L"]) + float(params["prop_radius"])


def check_settings(drone: str, physics_hz: int, control_hz: int, altitude_m: float) -> None:
    """The crazyflow plant's settings (errors name the scenario's ``[plant]`` keys)."""
    if drone not in DRONES:
        raise ValidationError("plant.drone", f"expected one of {', '.join(DRONES)}, got {drone!r}")
    for key, rate in (("physics_rate", physics_hz), ("control_rate", control_hz)):
        if isinstance(rate, bool) or not isinstance(rate, int) or rate < 1:
            raise ValidationError(f"plant.{key}", f"expected an integer >= 1 [Hz], got {rate!r}")
    if physics_hz % control_hz:
        raise ValidationError(
            "plant.physics_rate",
            f"expected a multiple of plant.control_rate ({control_hz} Hz), got {physics_hz}",
        )
    if not 0.0 < altitude_m < math.inf:
        raise ValidationError("plant.altitude", f"expected a finite height > 0 [m], got {altitude_m!r}")


class CrazyflowPlant(Plant):
    """n Crazyflies in one crazyflow world (module docstring)."""

    kind = "crazyflow"

    def __init__(
        self,
        n: int,
        dim: int,
        *,
        drone: str = "cf2x_L250",
        physics_hz: int = 500,
        control_hz: int = 100,
        altitude_m: float = 1.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(n, dim, **kwargs)
        check_settings(drone, physics_hz, control_hz, altitude_m)
        self.drone, self.altitude_m = drone, altitude_m
        self.physics_hz, self.control_hz = physics_hz, control_hz
        self.radius_m = body_radius_m(drone)
        self._drag = so_rpy.load_params(drone).drag_matrix  # the quadrotor plant's (module docstring)
        self._worker: _Worker | None = None
        self._p = np.zeros((n, 3))
        self._anchor = np.full((n, dim), np.nan)  # a held drone's setpoint path (world frame), else NaN
        self.setup_s = 0.0
        self._events: dict[str, Any] = {}

    # -- the worker --------------------------------------------------------------------------

    def _start(self) -> _Worker:
        if self._worker is None:
            if importlib.util.find_spec("crazyflow") is None:  # fail here, with the fix
                raise MPCFormError('the crazyflow plant needs crazyflow: pip install -e ".[crazyflow]"')
            self._worker = _Worker()
            weakref.finalize(self, self._worker.stop)
        return self._worker

    def _ask(self, *request: Any) -> tuple[Any, ...]:
        return self._start().ask(request)

    # -- the plant ---------------------------------------------------------------------------

    def _reset(self, p: Array, v: Array) -> None:
        if np.any(v != 0.0):
            raise ValidationError("plant.velocities", "the crazyflow plant starts at rest (hover)")
        self._p = self._world(p)
        self._anchor = np.full((self.n, self.dim), np.nan)
        low = int(np.argmin(self._p[:, 2]))
        if self._p[low, 2] < 2.0 * self.radius_m:
            need = 2.0 * self.radius_m - self._p[low, 2] + self.altitude_m
            raise ValidationError(
                "plant.altitude",
                f"drone {low} would start {self._p[low, 2]:.3g} m above the floor; the crazyflow plant "
                f"starts drones hovering at least {2 * self.radius_m:.3g} m up: expected an altitude of at "
                f"least {need:.3g} m, got {self.altitude_m:g}",
            )
        (self.setup_s,) = self._ask("reset", self._p.copy(), self.drone, self.physics_hz, self.control_hz)
        self._events = {"drone_contacts": [], "floor_contacts": [], "flipped": [], "min_altitude_m": math.inf}

    def _world(self, p: Array) -> Array:
        """Scenario positions (n, d) in crazyflow's frame (n, 3): the origin ``altitude_m`` up."""
        out = np.zeros((p.shape[0], 3))
        out[:, : self.dim] = p
        out[:, 2] += self.altitude_m
        return out

    def _displace(self, delta: Array) -> None:
        raise ValidationError("simulation.noise", "the crazyflow plant takes no process noise")

    def _advance(self, u: Array, dt: float, planned: Array | None) -> tuple[Array, Array, Array, dict]:
        ticks_per_interval(dt, self.control_hz, "plant.control_rate")
        sp = interval_setpoints(self._starts(u, dt), u, self.t_s, dt, self.control_hz, self.altitude_m)
        rows = sp.state_control()
        steps = rows.shape[0] * (self.physics_hz // self.control_hz)
        wind = self._wind(1.0 / self.physics_hz, steps)  # (steps, n, d): held over each physics step
        pushed = None
        if wind is not None:
            w3 = np.zeros((steps, self.n, 3))
            w3[..., : self.dim] = wind
            pushed = (w3, self._drag)
        pos, vel, quat = self._ask("fly", rows, pushed)
        self._p = pos[-1].copy()
        self._watch(pos, quat)
        t = self.t_s + np.arange(pos.shape[0]) / self.physics_hz
        pos[:, :, 2] -= self.altitude_m  # back in the scenario's frame
        extra: dict[str, Any] = {"quat_xyzw": quat}
        if wind is not None:  # the wind in force from each sample on (the last: the last step's)
            extra["wind_mps"] = np.concatenate([wind, wind[-1:]])
        return t, pos[:, :, : self.dim], vel[:, :, : self.dim], extra

    def _starts(self, u: Array, dt: float) -> Array:
        """Where each drone's setpoint path starts (n, d) [world frame]: at the measurement, or
        for a held drone at its anchor, which then moves on by ``u dt`` (module docstring)."""
        measured = self._p[:, : self.dim]
        held = (np.linalg.norm(u, axis=1) <= HOLD_MPS)[:, None]
        away = np.where(held & np.isfinite(self._anchor), self._anchor - measured, 0.0)
        far = np.linalg.norm(away, axis=1, keepdims=True)
        away *= np.minimum(1.0, PLATFORM_TRACKING_M / np.maximum(far, 1e-300))
        start = np.where(held, measured + away, measured)
        self._anchor = np.where(held, start + dt * u, np.nan)
        return start

    def _watch(self, pos: Array, quat: Array) -> None:
        """Record contacts, floor contacts and flips of the dense samples (module docstring)."""
        ev = self._events
        i, k = np.triu_indices(self.n, 1)
        close = np.linalg.norm(pos[:, i] - pos[:, k], axis=-1).min(axis=0) < 2.0 * self.radius_m
        for a, b in zip(i[close].tolist(), k[close].tolist(), strict=True):
            if [a, b] not in ev["drone_contacts"]:
                ev["drone_contacts"].append([a, b])
        ev["min_altitude_m"] = min(ev["min_altitude_m"], float(pos[:, :, 2].min()))
        floor = np.flatnonzero((pos[:, :, 2] < self.radius_m).any(axis=0))
        up_z = 1.0 - 2.0 * (quat[..., 0] ** 2 + quat[..., 1] ** 2)  # the body z axis' world z
        flipped = np.flatnonzero((up_z < 0.0).any(axis=0))
        for key, drones in (("floor_contacts", floor), ("flipped", flipped)):
            ev[key] = sorted(set(ev[key]) | set(drones.tolist()))

    def fly_full_state(self, start_m: Array, setpoints: FullState) -> tuple[Array, Array]:
        """Fly world-frame full-state ``setpoints``, a row per control tick, from the drones
        hovering at ``start_m`` (n, 3) [m, world frame] (a spatial plant): the times [s] and true
        positions (K, n, 3) of every physics step (contacts, floor contacts and flips recorded in
        :attr:`events`). An export's pieces are flown this way, open loop."""
        if self.dim != 3:
            raise ValidationError("plant", "full-state setpoints fly a spatial (dim = 3) crazyflow plant")
        self.reset(start_m - np.array([0.0, 0.0, self.altitude_m]))
        pos, _, quat = self._ask("fly", setpoints.state_control(), None)
        self._watch(pos, quat)
        return np.arange(pos.shape[0]) / self.physics_hz, pos

    @property
    def events(self) -> dict[str, Any]:
        """Drone pairs in contact, drones that touched the floor or flipped, the lowest altitude
        [m] and the simulator's build and compile time [s] (module docstring)."""
        return self._events | {"setup_s": self.setup_s}

    @property
    def lost_drones(self) -> Array:
        """Drones that touched the floor or flipped (sorted)."""
        ev = self._events
        return np.array(sorted(set(ev.get("floor_contacts", ())) | set(ev.get("flipped", ()))), dtype=int)

    def velocity_loops(self) -> list:
        return []


class _Worker:
    """The worker process (:mod:`mpcform.sim.crazyflow_worker`), spoken to over its stdin and
    stdout; its stderr (crazyflow's and JAX's messages) goes to a file quoted when it fails."""

    def __init__(self) -> None:
        env = dict(os.environ, SCIPY_ARRAY_API="1")  # the worker's scipy, before it loads
        package = str(Path(__file__).resolve().parents[2])  # mpcform, installed or not
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [package, os.environ.get("PYTHONPATH")]))
        self._log, self._dir = tempfile.TemporaryFile(), tempfile.TemporaryDirectory()
        cmd = [sys.executable, "-m", "mpcform.sim.crazyflow_worker"]
        pipe = subprocess.PIPE  # in a directory of its own: MuJoCo writes MUJOCO_LOG.TXT there
        self._proc = subprocess.Popen(
            cmd, stdin=pipe, stdout=pipe, stderr=self._log, env=env, cwd=self._dir.name
        )
        if self._proc.stdin is None or self._proc.stdout is None:  # PIPE was asked for both
            raise MPCFormError("crazyflow: the worker process started without its pipes")
        self._send = Connection(os.dup(self._proc.stdin.fileno()), readable=False)
        self._recv = Connection(os.dup(self._proc.stdout.fileno()), writable=False)

    def ask(self, request: tuple[Any, ...]) -> tuple[Any, ...]:
        try:
            self._send.send(request)
            answer = self._recv.recv()
        except (OSError, EOFError):
            self._proc.wait(timeout=10.0)
            self._log.seek(0)
            tail = self._log.read().decode(errors="replace").strip().splitlines()[-5:]
            raise MPCFormError(
                f"crazyflow: the worker exited with status {self._proc.returncode}: " + " / ".join(tail)
            ) from None
        if answer[0] == "error":
            raise MPCFormError(f"crazyflow: {answer[1]}")
        return answer[1:]

    def stop(self) -> None:
        try:
            self._send.send(("stop",))
            self._proc.wait(timeout=10.0)
        except (OSError, subprocess.TimeoutExpired):
            self._proc.kill()
        for conn in (self._send, self._recv):
            conn.close()
        for pipe in (self._proc.stdin, self._proc.stdout):
            if pipe is not None:
                pipe.close()
        self._log.close()
        self._dir.cleanup()
