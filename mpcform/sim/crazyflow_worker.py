"""The crazyflow side of :class:`mpcform.sim.crazyflow.CrazyflowPlant`, run in its own process.

crazyflow needs ``SCIPY_ARRAY_API=1`` before scipy is first imported, and mpcform imports scipy:
so crazyflow lives in a worker process whose environment sets it, and the planner's
process never sees it (its outputs are those of every other plant). :func:`serve` answers three
requests on its pipe:

- ``("reset", positions (n, 3), drone, physics_hz, control_hz)``: build the simulator (one world,
  n drones of the first-principles model of ``drone``) and compile its step (the JIT), unless the
  last reset built the same; place the drones at those positions, level, at rest, rotors at hover
  speed; answers the time it took [s];
- ``("fly", setpoints (k, n, 16), wind)``: send setpoint row j at control tick j
  (``Sim.state_control``, the firmware's Mellinger controller) and step the physics
  ``physics_hz / control_hz`` times per tick, recording every physics step; answers positions,
  velocities (k m + 1, n, 3) and attitudes ``quat_xyzw`` (k m + 1, n, 4), the first sample the
  state before the interval. ``wind`` is None (calm) or ``(wind_mps (k m, n, 3), drag (3, 3))``:
  before physics step s every drone's ``states.force`` is set to :func:`wind_force_N` of its
  attitude then and ``wind_mps[s]``, held over the step;
- ``("stop",)``: end the process (as does the end of the requests).

Run as ``python -m mpcform.sim.crazyflow_worker`` with ``SCIPY_ARRAY_API=1``: requests come on
stdin, answers go on stdout (pickled, :class:`multiprocessing.connection.Connection` frames).

An exception is answered as ``("error", text)``.
"""

from __future__ import annotations

import os
import time
from multiprocessing.connection import Connection
from typing import Any

import numpy as np


def wind_force_N(drag: np.ndarray, quat_xyzw: np.ndarray, wind_mps: np.ndarray) -> np.ndarray:
    """The wind's share of the body-frame linear drag ``R D (R^T (v - w))`` in the world frame,
    ``-R D R^T w`` (n, 3) [N], for the drag matrix ``drag`` (3, 3) [kg/s, <= 0], attitudes
    ``quat_xyzw`` (n, 4) and winds ``wind_mps`` (n, 3): the force the quadrotor plant's drag on
    the airspeed adds to its drag on the velocity (:mod:`mpcform.sim.quadrotor`)."""
    x, y, z, w = (quat_xyzw[:, i] for i in range(4))
    rot = np.empty((quat_xyzw.shape[0], 3, 3))  # body to world
    rot[:, 0] = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1)
    rot[:, 1] = np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1)
    rot[:, 2] = np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1)
    return -np.einsum("nij,jk,nlk,nl->ni", rot, drag, rot, wind_mps)


class _Flight:
    """One crazyflow simulation of n drones, built and compiled once, placed at every reset."""

    def __init__(self, n: int, drone: str, physics_hz: int, control_hz: int) -> None:
        from crazyflow.control import Control
        from crazyflow.sim import Sim
        from drone_models.core import load_params

        self.key = (n, drone, physics_hz, control_hz)
        self.sim = Sim(
            n_worlds=1,
            n_drones=n,
            drone=drone,
            dynamics="first_principles",
            control=Control.state,
            freq=physics_hz,
            state_freq=control_hz,
        )
        self.per_tick = physics_hz // control_hz
        params = load_params("first_principles", drone)
        _, k1, k2 = (float(c) for c in params["rpm2thrust"])
        weight = float(params["mass"]) * 9.81 / 4.0  # per rotor
        self.hover_rpm = (-k1 + np.sqrt(k1 * k1 + 4.0 * k2 * weight)) / (2.0 * k2)
        self.place(np.column_stack([np.arange(n), np.zeros(n), np.ones(n)]))
        self.sim.step(1)  # compile the step as fly calls it (n_steps is static)

    def place(self, positions: np.ndarray) -> None:
        """Every drone level and at rest at ``positions`` (n, 3), rotors at hover speed, holding."""
        import jax.numpy as jnp

        states = self.sim.data.states
        self.sim.default_data = self.sim.default_data.replace(
            states=states.replace(
                pos=jnp.asarray(positions[None], dtype=states.pos.dtype),
                vel=jnp.zeros_like(states.vel),
                quat=jnp.zeros_like(states.quat).at[..., 3].set(1.0),
                ang_vel=jnp.zeros_like(states.ang_vel),
                rotor_vel=jnp.full(states.rotor_vel.shape, self.hover_rpm),
                force=jnp.zeros_like(states.force),  # calm until a windy interval sets it
            )
        )
        self.sim.reset()
        hold = np.zeros((1, positions.shape[0], 16))
        hold[0, :, :3] = positions
        hold[0, :, 12] = 1.0  # quaternion (x, y, z, w): yaw 0
        self.sim.state_control(hold)

    def fly(
        self, setpoints: np.ndarray, wind: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k, n = setpoints.shape[:2]
        m = self.per_tick
        pos, vel, quat = np.empty((k * m + 1, n, 3)), np.empty((k * m + 1, n, 3)), np.empty((k * m + 1, n, 4))
        pos[0], vel[0], quat[0] = self._state()
        for j in range(k):
            self.sim.state_control(setpoints[j][None])
            for s in range(m):
                i = j * m + s
                if wind is not None:
                    self._push(wind_force_N(wind[1], quat[i], wind[0][i]))
                self.sim.step(1)
                pos[i + 1], vel[i + 1], quat[i + 1] = self._state()
        return pos, vel, quat

    def _push(self, force_N: np.ndarray) -> None:
        """Every drone's external force (n, 3) [N, world frame] until the next push."""
        import jax.numpy as jnp

        states = self.sim.data.states
        force = jnp.asarray(force_N[None], dtype=states.force.dtype)
        self.sim.data = self.sim.data.replace(states=states.replace(force=force))

    def _state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        st = self.sim.data.states  # whole arrays to numpy, then the world (no JAX op per index)
        return np.asarray(st.pos)[0], np.asarray(st.vel)[0], np.asarray(st.quat)[0]


def serve(requests: Connection, answers: Connection) -> None:
    """Answer ``requests`` on ``answers`` until ``("stop",)`` (module docstring)."""
    flight: _Flight | None = None
    conn = answers
    while True:
        try:
            request: tuple[Any, ...] = requests.recv()
        except EOFError:  # the planner's process has gone
            return
        try:
            if request[0] == "stop":
                return
            if request[0] == "reset":
                start = time.perf_counter()
                positions, key = request[1], (request[1].shape[0], *request[2:])
                if flight is None or flight.key != key:  # the same swarm is placed again
                    flight = _Flight(*key)
                flight.place(positions)
                conn.send(("ok", time.perf_counter() - start))
            elif request[0] == "fly":
                if flight is None:
                    raise RuntimeError("fly before reset")
                conn.send(("ok",) + flight.fly(*request[1:]))
            else:
                raise RuntimeError(f"unknown request {request[0]!r}")
        except Exception as exc:  # answered, so the planner's process reports it
            conn.send(("error", f"{type(exc).__name__}: {exc}"))


if __name__ == "__main__":  # python -m mpcform.sim.crazyflow_worker: requests on stdin, answers on stdout
    answers_fd = os.dup(1)
    os.dup2(2, 1)  # what crazyflow and JAX print goes to stderr, not into the answers
    serve(Connection(0, writable=False), Connection(answers_fd, readable=False))
