r"""Robust margin (tube radius) of a plant against the planner's single integrator.

Definition. The planner re-measures the positions every step and predicts ``p_k + s u_k`` over
the next ``steps`` intervals (``p_k + \int u``). The margin is the worst deviation
``|p(t_k + s) - p_k - \int_{t_k}^{t_k+s} u|`` over ``0 < s <= steps dt``, over every command history
whose components change by at most ``a_max dt`` per step (the planner's ``|u_j - u_{j-1}| <=
a_max dt``, counted from the plant at rest), and every wind within its bound.

Formula, for a linear velocity loop with step response ``g(t)`` (``g(inf) = 1``) and
``S(t) = \int_0^t (1 - g)`` (0 for t < 0; ``S(inf)`` is the loop's mean delay): a command step
``Delta`` at ``t_j`` moves the deviation over the window by ``Delta (S(t_k + s - t_j) - S(t_k - t_j))``,
so by superposition and the triangle inequality (attained by choosing each step's sign)

.. math::
    e_{cmd}(s) = a_{max} dt \Big[\sum_{i \ge 0} |S(i dt + s) - S(i dt)|
                 + \sum_{1 \le i < s/dt} S(s - i dt)\Big],

and a wind bounded by ``w_max`` adds at most ``s ||h_w||_1 w_max`` (``h_w`` the impulse response
from wind to velocity). Per axis the margin is ``max_s (e_cmd + e_wind)``; the Euclidean margin is
the norm of the per-axis values. Closed forms for one step (``steps = 1``):

- lag ``tau``: ``S(t) = tau (1 - e^{-t/tau})`` and the sum telescopes to ``a_max dt tau``;
  wind adds ``dt tau c w_max`` (``||h_w||_1 = c tau``);
- second order: no closed form (``S`` overshoots), computed on a grid of ``dt / 50``;
- quadrotor: the same sums on its hover linearisation (velocity mode, RK4-free continuous
  model of the PID cascade and fitted airframe), times :data:`QUADROTOR_SAFETY` for what the
  linearisation leaves out (tilt and thrust coupling, sampling, saturation); the tests check it
  against the simulated plant on random and worst-case command sequences, with and without wind.

An unbounded wind (gust std > 0 with an infinite gust bound) gives an infinite margin. The
quadrotor's bound holds while the commanded speed stays below :attr:`Margin.valid_speed_mps`
(beyond it drag plus ``a_max`` exceed the tilt or thrust authority and the drone falls behind
without bound); it covers velocity tracking (no planned positions passed to the plant). Position
noise is not included: the planner's measured start is off by the noise on top of this margin.

When the planner models the velocity loop (:mod:`mpcform.mpc.velocity_loop`, the default), its rows hold at
the interval ends up to what that model misses, and :func:`modelled_margin` is the margin instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError
from mpcform.sim.plants import Plant
from mpcform.sim.quadrotor import QuadrotorPlant
from mpcform.world.limits import DEFAULT_A_MAX_MPS2

QUADROTOR_SAFETY = 1.25
LINEARISATION_REMAINDER = 0.1
"""When the planner models the quadrotor's hover linearisation (:func:`modelled_margin`), what the
linearisation leaves out at the interval ends, as a fraction of the unmodelled command margin
(measured: at most 0.033 on random and worst-case command sequences, 3-D, no wind; tested)."""
ACCEL_FRACTION = 0.5
"""Default a_max is this fraction of what the airframe can deliver (the rest is kept for feedback)."""
GRID = 50


@dataclass(frozen=True)
class Margin:
    """Per-axis deviation bound (d,), its Euclidean norm, and the command and wind parts [m]."""

    per_axis_m: Array
    norm_m: float
    command_m: Array
    wind_m: Array
    valid_speed_mps: float = float("inf")
    """Quadrotor: the speed up to which the airframe stays unsaturated while it accelerates at
    ``a_max`` against drag in the worst wind (the bound assumes commands below it)."""


def default_a_max(plant: Plant) -> float:
    """Componentwise command-change bound [m/s^2] when the scenario gives none.

    Quadrotor: half of the smaller of ``g tan(max_tilt)`` and the vertical thrust reserve
    ``(acc_coef + cmd_f_coef 4 thrust_max) / m - g`` (d = 3). Other plants: the platform's
    :data:`~mpcform.world.limits.DEFAULT_A_MAX_MPS2` (half of ``g tan(20 deg)``), the airframe a lag
    or second-order loop stands for.
    """
    if isinstance(plant, QuadrotorPlant):
        pr = plant.params
        avail = pr.gravity_mps2 * np.tan(plant.spec.max_tilt_rad)
        if plant.dim == 3:
            avail = min(
                avail, (pr.acc_coef_N + pr.cmd_f_coef * pr.thrust_max_N) / pr.mass_kg - pr.gravity_mps2
            )
        return float(ACCEL_FRACTION * avail)
    return DEFAULT_A_MAX_MPS2


def _loop_series(a: Array, b: Array, e: Array, c: Array, h: float, count: int) -> tuple[Array, Array]:
    """``S`` at ``t = 0, h, ..., count h`` and the wind impulse response ``C e^{At} E`` there."""
    s = a.shape[0]
    m = np.zeros((s + 2, s + 2))  # states x, the integral of (1 - v), and a unit step input
    m[:s, :s], m[:s, s + 1] = a, b
    m[s, :s], m[s, s + 1] = -c, 1.0
    step = expm(m * h)
    z = np.zeros((s + 2, 2))  # column 0: step response from rest; column 1: impulse of the wind
    z[s + 1, 0] = 1.0
    z[:s, 1] = e
    powers = np.empty((GRID, s + 2, s + 2))  # step^k, k < GRID: one Python iteration per block
    powers[0] = np.eye(s + 2)
    for k in range(1, GRID):
        powers[k] = step @ powers[k - 1]
    block = step @ powers[-1]
    blocks = -(-(count + 1) // GRID)
    out = np.empty((blocks, GRID, s + 2, 2))
    for i in range(blocks):
        out[i] = powers @ z
        z = block @ z
    out = out.reshape(blocks * GRID, s + 2, 2)[: count + 1]
    return out[:, s, 0], out[:, :s, 1] @ c


def _settle_time(a: Array) -> float:
    rate = -np.max(np.linalg.eigvals(a).real)
    return 40.0 / rate


def plant_margin(plant: Plant, dt_s: float, a_max_mps2: float | None = None, *, steps: int = 1) -> Margin:
    """Margin of ``plant`` for control interval ``dt_s`` over ``steps`` intervals (module doc).

    ``a_max_mps2`` None takes :func:`default_a_max`.
    """
    dt = positive("margin.dt", dt_s)
    a_max = default_a_max(plant) if a_max_mps2 is None else positive("margin.a_max", a_max_mps2)
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValidationError("margin.steps", f"expected an integer >= 1, got {steps!r}")
    d = plant.dim
    w_max = np.zeros(d) if plant.wind is None else plant.wind.speed_bound_mps()
    cmd, wnd = np.zeros(d), np.zeros(d)
    h = dt / GRID
    for a, b, e, c, axes in plant.velocity_loops():
        past = int(np.ceil(_settle_time(a) / dt))
        count = (past + steps) * GRID
        s_series, imp = _loop_series(a, b, e, c, h, count)
        l1 = float(np.sum(np.abs(imp[:-1]) + np.abs(imp[1:])) * h / 2.0)
        offs = np.arange(1, steps * GRID + 1)  # s = offs h
        base = np.arange(past + 1) * GRID  # i dt
        total = np.abs(s_series[base[:, None] + offs[None, :]] - s_series[base][:, None]).sum(axis=0)
        for i in range(1, steps):
            later = offs > i * GRID
            total[later] += np.abs(s_series[offs[later] - i * GRID])
        ax = list(axes)
        cmd_axis = a_max * dt * total
        wind_axis = offs * h * l1
        for k in ax:
            worst = (
                cmd_axis + wind_axis * w_max[k] if np.isfinite(w_max[k]) else np.full_like(cmd_axis, np.inf)
            )
            j = int(np.argmax(worst))
            cmd[k], wnd[k] = cmd_axis[j], worst[j] - cmd_axis[j] if np.isfinite(worst[j]) else np.inf
    valid = float("inf")
    if isinstance(plant, QuadrotorPlant):
        cmd, wnd = cmd * QUADROTOR_SAFETY, wnd * QUADROTOR_SAFETY
        valid = valid_speed(plant, a_max, w_max)
    per = cmd + wnd
    return Margin(per, float(np.linalg.norm(per)), cmd, wnd, valid)


def chord_margin(plant: Plant, dt_s: float, a_max_mps2: float) -> Array:
    """Per-axis bound (d,) [m] on how far a linear plant's true path strays from the chord between
    its positions at the ends of an interval, for command changes within ``a_max dt``: what is
    left of the margin when the planner models the loop (:mod:`mpcform.mpc.velocity_loop`), whose rows hold
    at the interval ends. A step ``Delta`` at ``t_j`` bends the interval ``[t_k, t_k + dt]`` by
    ``Delta (S(tau + s) - S(tau) - s/dt (S(tau + dt) - S(tau)))``, ``tau = t_k - t_j``; summing the
    worst of each over the past steps bounds it."""
    dt = positive("margin.dt", dt_s)
    out = np.zeros(plant.dim)
    for a, b, e, c, axes in plant.velocity_loops():
        past = int(np.ceil(_settle_time(a) / dt))
        s_series, _ = _loop_series(a, b, e, c, dt / GRID, (past + 1) * GRID)
        base = np.arange(past + 1) * GRID
        window = s_series[base[:, None] + np.arange(GRID + 1)[None, :]] - s_series[base][:, None]
        bend = window - np.linspace(0.0, 1.0, GRID + 1)[None, :] * window[:, -1:]
        out[[k for k in axes if k < plant.dim]] = a_max_mps2 * dt * np.abs(bend).max(axis=1).sum()
    return out


def modelled_margin(plant: Plant, dt_s: float, a_max_mps2: float, margin: Margin | None = None) -> Array:
    """Per-axis margin (d,) [m] left when the planner models the plant's velocity loop with its
    velocity-offset estimate (:mod:`mpcform.mpc.velocity_loop`): the rows then hold at the interval ends up
    to the wind's change since the last interval (:func:`observed_wind`), plus the bend within an
    interval (:func:`chord_margin`) and, for the quadrotor, whose loop is its hover linearisation,
    both times :data:`QUADROTOR_SAFETY` plus :data:`LINEARISATION_REMAINDER` of the command part
    of ``margin`` (:func:`plant_margin`)."""
    per = observed_wind(plant, dt_s) + chord_margin(plant, dt_s, a_max_mps2)
    if isinstance(plant, QuadrotorPlant):
        margin = plant_margin(plant, dt_s, a_max_mps2) if margin is None else margin
        return QUADROTOR_SAFETY * per + LINEARISATION_REMAINDER * margin.command_m
    return per


def observed_wind(plant: Plant, dt_s: float) -> Array:
    r"""Per-axis bound (d,) [m] on the wind's share of ``|p(t_k + s) - p_model(t_k + s)|``,
    ``0 < s <= dt``, when the model's velocity offset is the last interval's mean (deadbeat,
    :meth:`mpcform.mpc.velocity_loop.VelocityLoop.observe`). With ``H(t)`` the wind-to-velocity step
    response and ``I = \int H``, a wind impulse ``u`` before ``t_k`` errs by ``K_s(u) = H(u + s) -
    H(u) - s/dt (H(u) - H(u - dt))``: the gusts (within ``gust_bound``, any history) add
    ``||K_s||_1 gust_bound``; the constant mean (on from ``t = 0``, the drone at rest) adds
    ``|mean| max_k |I(t_k + s) - I(t_k) - s/dt (I(t_k) - I(t_{k-1}))|`` (no estimate at ``k = 0``)."""
    dt = positive("margin.dt", dt_s)
    out = np.zeros(plant.dim)
    if plant.wind is None:
        return out
    wind = plant.wind
    gust = wind.speed_bound_mps() - np.abs(wind.mean_mps)  # the gusts' clip (0 without gusts)
    mean = np.abs(wind.mean_mps)
    h = dt / GRID
    for a, b, e, c, axes in plant.velocity_loops():
        past = int(np.ceil(_settle_time(a) / dt))
        _, imp = _loop_series(a, b, e, c, h, (past + 2) * GRID)
        step = np.concatenate([[0.0], np.cumsum(imp[1:] + imp[:-1]) * h / 2])  # H on the grid
        ramp = np.concatenate([[0.0], np.cumsum(step[1:] + step[:-1]) * h / 2])  # I
        lead = np.concatenate([np.zeros(2 * GRID), step])  # H(u) at lead[u + 2 GRID], 0 for u < 0
        u = np.arange(-GRID, (past + 1) * GRID)
        offs = np.arange(1, GRID + 1)
        now, before = lead[u + 2 * GRID], lead[u + GRID]
        kernel = lead[u[None, :] + offs[:, None] + 2 * GRID] - now - offs[:, None] / GRID * (now - before)
        gusts = np.abs(kernel).sum(axis=1) * h  # (GRID,) per s = offs h
        k = np.arange(past + 1) * GRID
        seen = np.where(k > 0, ramp[k] - ramp[np.maximum(k - GRID, 0)], 0.0)
        means = np.abs(ramp[k[:, None] + offs] - ramp[k][:, None] - offs / GRID * seen[:, None]).max(axis=0)
        for ax in (x for x in axes if x < plant.dim):
            out[ax] = float(np.max(means * mean[ax] + gusts * gust[ax]))
    return out


def wind_growth(plant: Plant, dt_s: float) -> float:
    """How far [m] per control interval the wind's change can move a drone off the plan the
    planner predicted (the norm of :func:`observed_wind`, what the offset's estimate misses over an
    interval; the quadrotor's times :data:`QUADROTOR_SAFETY`): the MPC's rows grow by it along the
    horizon (:func:`mpcform.mpc.constraints.rows.step_growth`). 0 in calm air.

    The planner holds the estimate over its plan (:mod:`mpcform.mpc.velocity_loop`), so a miss
    ``r`` moves the start by ``r`` and the shifted plan's position at step ``e`` by ``(e + 1) r``
    at worst (the estimate moves by ``r / dt``): covering that would take ``1 + ceil(0.2 / dt)``
    misses, three times this at dt 0.1, where the gusts' worst case is far above what they do
    (formation_flight_100 in 1.5 m/s gusts on the quadrotor moved its plan by at most 0.026 m a
    step against 0.027 m, and grown three times as much it completed 94 % instead of all). The
    growth's premise reports the steps the move exceeds it
    (:class:`mpcform.mpc.safety.premise.GrowthPremise`): in a steady wind the first few."""
    if plant.wind is None:
        return 0.0
    grow = float(np.linalg.norm(observed_wind(plant, dt_s)))
    return grow * QUADROTOR_SAFETY if isinstance(plant, QuadrotorPlant) else grow


def valid_speed(plant: QuadrotorPlant, a_max: float, w_max: Array) -> float:
    """Largest speed with ``a_max + c (v + w)`` within the tilt (and, d = 3, thrust) authority."""
    pr = plant.params
    c = pr.drag_per_s
    g = pr.gravity_mps2
    wind_h = float(np.linalg.norm(w_max[:2]))
    speed = (g * np.tan(plant.spec.max_tilt_rad) - a_max) / c[0] - wind_h
    if plant.dim == 3:
        reserve = (pr.acc_coef_N + pr.cmd_f_coef * pr.thrust_max_N) / pr.mass_kg - g
        speed = min(speed, (reserve - a_max) / c[2] - float(w_max[2]))
    return max(float(speed), 0.0)


def worst_case_commands(plant: Plant, dt_s: float, a_max_mps2: float, history: int) -> Array:
    """Command sequence (history,) of one axis that attains the one-step margin at its last interval.

    Signs of ``S(i dt + s*) - S(i dt)`` for the worst window length ``s*``, oldest first, as
    cumulative steps of ``+-a_max dt``; used by the tests to show the bound is tight.
    """
    a, b, e, c, _ = plant.velocity_loops()[0]
    h = dt_s / GRID
    s_series, _ = _loop_series(a, b, e, c, h, (history + 1) * GRID)
    offs = np.arange(1, GRID + 1)
    base = np.arange(history) * GRID
    diff = s_series[base[:, None] + offs[None, :]] - s_series[base][:, None]
    j = int(np.argmax(np.abs(diff).sum(axis=0)))
    signs = np.sign(diff[:, j])[::-1]  # i = history - 1 (oldest) ... 0 (latest)
    signs[signs == 0] = 1.0
    return np.cumsum(signs) * a_max_mps2 * dt_s
