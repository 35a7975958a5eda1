"""The crazyflow side of :class:`mpcform.sim.crazyflow.CrazyflowPlant`, run in its own process.

crazyflow needs ``SCIPY_ARRAY_API=1`` before scipy is first imported, and mpcform imports scipy:
so crazyflow lives in a worker process whose environment sets it, and the planner's
process never sees it (its outputs are those of every other plant). :func:`serve` answers three
requests on its pipe:

- ``("reset", positions (n, 3), drone, physics_hz, control_hz)``: build the simulator (one world,
  n drones of the first-principles model of ``drone``) and compile its step (the JIT), unless the
  last reset built the same; place the drones at those positions, level, at rest, rotors at hover
  speed; answers the time it took [s];
- ``("fly", setpoints (k, n, 16))``: send setpoint row j at control tick j (``Sim.state_control``,
  the firmware's Mellinger controller) and step the physics ``physics_hz / control_hz`` times per
  tick, recording every physics step; answers positions, velocities (k m + 1, n, 3) and
  attitudes ``quat_xyzw`` (k m + 1, n, 4), the first sample the state before the interval;
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
            )
        )
        self.sim.reset()
        hold = np.zeros((1, positions.shape[0], 16))
        hold[0, :, :3] = positions
        hold[0, :, 12] = 1.0  # quaternion (x, y, z, w): yaw 0
        self.sim.state_control(hold)

    def fly(self, setpoints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k, n = setpoints.shape[:2]
        m = self.per_tick
        pos, vel, quat = np.empty((k * m + 1, n, 3)), np.empty((k * m + 1, n, 3)), np.empty((k * m + 1, n, 4))
        pos[0], vel[0], quat[0] = self._state()
        for j in range(k):
            self.sim.state_control(setpoints[j][None])
            for s in range(m):
                self.sim.step(1)
                pos[j * m + s + 1], vel[j * m + s + 1], quat[j * m + s + 1] = self._state()
        return pos, vel, quat

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
                conn.send(("ok",) + flight.fly(request[1]))
            else:
                raise RuntimeError(f"unknown request {request[0]!r}")
        except Exception as exc:  # answered, so the planner's process reports it
            conn.send(("error", f"{type(exc).__name__}: {exc}"))


if __name__ == "__main__":  # python -m mpcform.sim.crazyflow_worker: requests on stdin, answers on stdout
    answers_fd = os.dup(1)
    os.dup2(2, 1)  # what crazyflow and JAX print goes to stderr, not into the answers
    serve(Connection(0, writable=False), Connection(answers_fd, readable=False))
