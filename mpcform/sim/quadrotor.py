"""Quadrotor plant: a drone-models fitted attitude loop flown by a Crazyflie-style PID cascade.

The airframe is the ``so_rpy`` family of :mod:`mpcform.sim.so_rpy` (default ``so_rpy_rotor_drag``
on ``cf2x_L250``: fitted attitude loop, first-order thrust lag and body-frame linear drag). At the
inner rate ``rate_hz`` (default 500 Hz, as the Crazyflie's stabiliser) a controller like the
firmware's ``position_controller_pid`` computes, for every drone at once:

- velocity setpoint ``v_sp = u + kp (p_ref - p)``, with ``p_ref = planned + u (t - t_k)`` when the
  planner passes its planned positions (no position term otherwise), and an altitude hold at
  ``altitude_m`` for planar (d = 2) flights, which return the horizontal position only (a
  full-state setpoint, :meth:`QuadrotorPlant.follow`, adds its acceleration ``a_ff``: ``u + a_ff
  (t - t_k)``, ``p_ref + a_ff (t - t_k)^2 / 2`` and ``a_ff`` in the desired acceleration);
- desired acceleration ``a = kv (v_sp - v) + ki I`` with ``I' = v_sp - v`` (``|ki I|`` clamped at
  ``i_limit_mps2``), vertical part within ``[-g/2, thrust limit]`` and horizontal part scaled so the
  tilt stays within ``max_tilt_rad``;
- thrust force ``m (a + g e_z) . z_body`` converted to the command ``(F - acc_coef) / cmd_f_coef``
  and clipped to the platform's ``[4 thrust_min, 4 thrust_max]``; roll and pitch from the direction
  of ``a + g e_z`` in the yaw frame, divided by the fitted loop's static gain
  ``-cmd_rpy_coef / rpy_coef`` (0.80 for cf2x_L250) so the attitude settles where asked; yaw 0.
  The tilt limit binds the setpoint: the fitted loop's transient may pass it by up to the L1 norm
  of its impulse response, ``(1 + M_p) / (1 - M_p)`` (1.28 for cf2x_L250, on a full reversal).

The command is held over each inner step and the state is integrated with classical RK4 at the
inner rate (the models are smooth; their fastest poles are about 16 rad/s, so ``h |lambda|`` is
0.03 at 500 Hz). Wind acts through drag: the world force ``R D R^T (v - w)`` (``D`` the
platform's drag matrix, kg/s), passed as the model's disturbance force (for ``so_rpy_rotor_drag``
the model itself supplies ``R D R^T v``, and the extra ``-R D R^T w`` is folded into that term by
giving it the airspeed: the same force, one evaluation). Position noise,
when set, only affects ``p_measured_m``; the inner loop uses the true state (an ideal onboard
estimator). A rate too coarse for RK4 (``h |lambda_max| > 0.5`` on the linearised loop), or
gains and rate whose linearised sampled loop is unstable, are refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError
from mpcform.sim import so_rpy
from mpcform.sim.plants import Loop, Plant, PlantSamples
from mpcform.sim.so_rpy import RPY, STATE, F, P, QuadrotorParams, V

RK4_STEP = 0.5
"""Largest ``h |lambda|`` accepted at the inner rate (RK4's local relative error ~ (h lambda)^5 / 120)."""


@dataclass(frozen=True)
class QuadrotorGains:
    """PID gains of the position/velocity cascade (horizontal ``xy``, vertical ``z``)."""

    kp_xy_per_s: float = 2.0
    kv_xy_per_s: float = 4.0
    ki_xy_per_s2: float = 2.0
    kp_z_per_s: float = 2.0
    kv_z_per_s: float = 5.0
    ki_z_per_s2: float = 3.0
    i_limit_mps2: float = 3.0

    def __post_init__(self) -> None:
        for name in ("kp_xy_per_s", "kv_xy_per_s", "ki_xy_per_s2", "kp_z_per_s", "kv_z_per_s", "ki_z_per_s2"):
            positive(f"quadrotor.gains.{name}", getattr(self, name), allow_zero=True)
        positive("quadrotor.gains.i_limit_mps2", self.i_limit_mps2)


@dataclass(frozen=True)
class QuadrotorSpec:
    """Platform, model, inner rate [Hz], tilt limit [rad], planar altitude [m] and gains."""

    platform: str = "cf2x_L250"
    model: str = "so_rpy_rotor_drag"
    rate_hz: float = 500.0
    max_tilt_rad: float = float(np.radians(20.0))
    altitude_m: float = 1.0
    gains: QuadrotorGains = field(default_factory=QuadrotorGains)

    def __post_init__(self) -> None:
        positive("quadrotor.rate_hz", self.rate_hz)
        if not 0.0 < self.max_tilt_rad < np.pi / 3:
            raise ValidationError(
                "quadrotor.max_tilt", f"expected a tilt in (0, pi/3) rad, got {self.max_tilt_rad!r}"
            )
        if not np.isfinite(self.altitude_m):
            raise ValidationError("quadrotor.altitude", f"expected a finite height, got {self.altitude_m!r}")


class QuadrotorPlant(Plant):
    """n drones of one platform, integrated together (no per-drone Python loop)."""

    kind = "quadrotor"

    def __init__(self, n: int, dim: int, spec: QuadrotorSpec | None = None, **kwargs: object) -> None:
        super().__init__(n, dim, **kwargs)  # type: ignore[arg-type]
        self.spec = spec or QuadrotorSpec()
        self.params: QuadrotorParams = so_rpy.load_params(self.spec.platform, self.spec.model)
        g = self.spec.gains
        self._kp = np.array([g.kp_xy_per_s, g.kp_xy_per_s, g.kp_z_per_s])
        self._kv = np.array([g.kv_xy_per_s, g.kv_xy_per_s, g.kv_z_per_s])
        self._ki = np.array([g.ki_xy_per_s2, g.ki_xy_per_s2, g.ki_z_per_s2])
        self._i_max = np.where(self._ki > 0, g.i_limit_mps2 / np.maximum(self._ki, 1e-300), 0.0)
        self._h = 1.0 / self.spec.rate_hz
        fastest = max(
            float(
                np.abs(np.linalg.eigvals(closed_loop(self.params, self.spec, axis, position=True)[0])).max()
            )
            for axis in ("xy", "z")
        )
        if self._h * fastest > RK4_STEP:
            raise ValidationError(
                "quadrotor.rate_hz",
                f"{self.spec.rate_hz:g} Hz is too coarse for RK4 on this loop (fastest pole {fastest:.4g} "
                f"rad/s needs h |lambda| <= {RK4_STEP:g}, i.e. >= {fastest / RK4_STEP:.4g} Hz)",
            )
        radius = max(inner_loop_radius(self.params, self.spec, axis) for axis in ("xy", "z"))
        if not radius < 1.0:
            raise ValidationError(
                "quadrotor.rate_hz",
                f"{self.spec.rate_hz:g} Hz gives an unstable sampled inner loop (spectral radius "
                f"{radius:.4g} >= 1 for {self.params.platform}); raise the rate or lower the gains",
            )

    # -- state -------------------------------------------------------------------------------

    def _reset(self, p: Array, v: Array) -> None:
        self._x = np.zeros((self.n, STATE))
        self._x[:, P][:, : self.dim] = p
        self._x[:, V][:, : self.dim] = v
        if self.dim == 2:
            self._x[:, 2] = self.spec.altitude_m
        self._x[:, F] = self.params.hover_command_N  # level hover thrust
        self._i = np.zeros((self.n, 3))
        self._acc_ff: Array | None = None  # a full-state setpoint's acceleration (:meth:`follow`)
        self._no_force = np.zeros((self.n, 3))
        self._cmd = np.zeros((self.n, 4))
        self._cmd[:, 3] = self.params.hover_command_N

    def _displace(self, delta: Array) -> None:
        self._x[:, P][:, : self.dim] += delta

    @property
    def positions_3d_m(self) -> Array:
        """True positions (n, 3), altitude included for planar flights."""
        return self._x[:, P].copy()

    def rise_time_90_s(self, axis: str = "xy") -> float:
        """Time for the hover-linearised velocity loop to reach 90 % of a commanded step."""
        a, b, _, c = closed_loop(self.params, self.spec, axis, position=False)
        h = 1e-3
        m = np.zeros((a.shape[0] + 1, a.shape[0] + 1))
        m[:-1, :-1], m[:-1, -1] = a, b
        step = expm(m * h)
        x = np.zeros(a.shape[0] + 1)
        x[-1] = 1.0
        for k in range(1, 100_000):
            x = step @ x
            if c @ x[:-1] >= 0.9:
                return k * h
        raise ValidationError("quadrotor.gains", "the velocity loop does not reach 90 % of a step")

    # -- one control interval ----------------------------------------------------------------

    def steps_per_interval(self, dt_s: float) -> int:
        """Inner steps in one control interval: a multiple of ``1 / dt_s`` (to 1e-9 relative) and at
        least ``samples_per_step``."""
        ratio = self.spec.rate_hz * dt_s
        steps = int(round(ratio))
        if steps < 1 or abs(ratio - steps) > 1e-9 * ratio:
            raise ValidationError(
                "quadrotor.rate_hz",
                f"expected a multiple of the control rate 1/dt = {1.0 / dt_s:g} Hz, "
                f"got {self.spec.rate_hz:g} Hz",
            )
        if steps < self.samples_per_step:
            raise ValidationError(
                "quadrotor.rate_hz",
                f"{self.spec.rate_hz:g} Hz gives {steps} inner steps per {dt_s:g} s interval, fewer than the "
                f"{self.samples_per_step} dense samples asked for",
            )
        return steps

    def follow(
        self, positions_m: Array, velocities_mps: Array, accelerations_mps2: Array, dt_s: float
    ) -> PlantSamples:
        """Hold a full-state setpoint (n, d) each over ``dt_s``, as a Crazyflie's ``cmdFullState``
        gives one to its controller: the position reference ``p + v tau + a tau^2 / 2``, the
        velocity ``v + a tau`` fed forward and the acceleration ``a`` added to the cascade's (not
        to its integral). An export's flight check flies its pieces this way
        (:mod:`mpcform.outputs.flight.check`)."""
        self._acc_ff = np.zeros((self.n, 3))
        self._acc_ff[:, : self.dim] = finite_array(
            "plant.accelerations", accelerations_mps2, (self.n, self.dim)
        )
        try:
            return self.advance(velocities_mps, dt_s, positions_m)
        finally:
            self._acc_ff = None

    def _advance(self, u: Array, dt: float, planned: Array | None) -> tuple[Array, Array, Array, dict]:
        steps = self.steps_per_interval(dt)
        stride = max(1, steps // self.samples_per_step)
        while steps % stride:
            stride -= 1
        h, d, n = dt / steps, self.dim, self.n
        u3 = np.zeros((n, 3))
        u3[:, :d] = u
        ref0 = np.full((n, 3), np.nan)  # position reference at the interval start; nan = none
        if planned is not None:
            ref0[:, :d] = planned
        if d == 2:
            ref0[:, 2] = self.spec.altitude_m
        has_ref = ~np.isnan(ref0)
        ref0 = np.where(has_ref, ref0, 0.0)
        kp = np.where(has_ref, self._kp, 0.0)
        wind = self._wind(h, steps)
        w3 = np.zeros((n, 3))
        k = steps // stride + 1
        xs, forces, winds = np.empty((k, n, STATE)), np.empty((k, n)), np.empty((k, n, 3))
        xs[0], forces[0], winds[0] = self._x, self._force(self._x), w3
        for i in range(steps):
            if wind is not None:
                w3[:, :d] = wind[i]
            x, tau, acc = self._x, i * h, self._acc_ff
            if acc is None:  # a velocity command
                self._control(x, u3 + kp * (ref0 + u3 * tau - x[:, P]), h)
            else:  # a full-state setpoint
                ref = ref0 + u3 * tau + (0.5 * tau * tau) * acc
                self._control(x, u3 + tau * acc + kp * (ref - x[:, P]), h)
            k1 = self._rhs(x, w3)
            k2 = self._rhs(x + 0.5 * h * k1, w3)
            k3 = self._rhs(x + 0.5 * h * k2, w3)
            k4 = self._rhs(x + h * k3, w3)
            self._x = x + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
            if i == 0:
                winds[0] = w3
            if (i + 1) % stride == 0:
                j = (i + 1) // stride
                xs[j], forces[j], winds[j] = self._x, self._force(self._x), w3
        extra: dict = {"quat_xyzw": so_rpy.rpy_to_quat(xs[..., RPY]), "thrust_N": forces}
        if wind is not None:
            extra["wind_mps"] = winds[..., :d]
        t = self.t_s + h * stride * np.arange(k)
        t[-1] = self.t_s + dt
        return t, xs[..., :d].copy(), xs[..., 6 : 6 + d].copy(), extra

    def _force(self, x: Array) -> Array:
        """Collective thrust force [N] along the body z axis."""
        thrust = self._cmd[:, 3] if self.params.thrust_time_s is None else x[:, F]
        return self.params.acc_coef_N + self.params.cmd_f_coef * thrust

    def _control(self, x: Array, v_sp: Array, h: float) -> None:
        """One PID update at the inner rate: sets the held command ``[roll, pitch, yaw, thrust]``."""
        pr, g, lim = self.params, self.params.gravity_mps2, self.spec
        e = v_sp - x[:, V]
        self._i = np.minimum(np.maximum(self._i + h * e, -self._i_max), self._i_max)
        a = self._kv * e + self._ki * self._i
        if self._acc_ff is not None:
            a = a + self._acc_ff
        az_max = (pr.cmd_f_coef * pr.thrust_max_N + pr.acc_coef_N) / pr.mass_kg - g
        fz = g + np.minimum(np.maximum(a[:, 2], -0.5 * g), az_max)
        axy = a[:, :2]
        norm = np.hypot(axy[:, 0], axy[:, 1])
        cap = fz * np.tan(lim.max_tilt_rad)
        axy = axy * np.minimum(1.0, cap / np.maximum(norm, 1e-300))[:, None]
        yaw = x[:, 5]
        cy, sy = np.cos(yaw), np.sin(yaw)
        fx, fy = cy * axy[:, 0] + sy * axy[:, 1], -sy * axy[:, 0] + cy * axy[:, 1]
        length = np.sqrt(fx * fx + fy * fy + fz * fz)
        gain = pr.attitude_gain
        self._cmd[:, 0] = np.arcsin(-fy / length) / gain[0]
        self._cmd[:, 1] = np.arctan2(fx, fz) / gain[1]
        z = so_rpy.body_z(x[:, RPY])
        along = pr.mass_kg * (z[:, 0] * axy[:, 0] + z[:, 1] * axy[:, 1] + z[:, 2] * fz)
        thrust = np.maximum((along - pr.acc_coef_N) / pr.cmd_f_coef, pr.thrust_min_N)
        self._cmd[:, 3] = np.minimum(thrust, pr.thrust_max_N)

    def _rhs(self, x: Array, w3: Array) -> Array:
        """Model derivatives with the held command; drag on the airspeed ``v - w``."""
        z = so_rpy.body_z(x[:, RPY])
        air = x[:, V] - w3
        if self.params.thrust_time_s is None:  # so_rpy: no drag of its own
            return so_rpy.euler_derivatives(
                self.params, x, self._cmd, so_rpy.drag_force(self.params, z, air), z
            )
        return so_rpy.euler_derivatives(self.params, x, self._cmd, self._no_force, z, drag_air_mps=air)

    # -- linearisation ---------------------------------------------------------------------

    def velocity_loops(self) -> list[Loop]:
        """Hover linearisation of the velocity loops (no position reference)."""
        loops: list[Loop] = []
        for axis, axes in (("xy", (0, 1)), ("z", (2,))):
            if self.dim == 2 and axis == "z":
                continue
            a, b, e, c = closed_loop(self.params, self.spec, axis, position=False)
            loops.append((a[1:, 1:], b[1:], e[1:], c[1:], axes))  # p feeds nothing back here
        return loops


def _airframe(params: QuadrotorParams, axis: str) -> tuple[Array, Array, Array, Array]:
    """Linearised airframe about hover: ``x' = A x + B a_des + E w``, states ``(p, v, ...)``."""
    g, m = params.gravity_mps2, params.mass_kg
    if axis == "xy":  # (p, v, theta, theta'); a_des -> commanded angle a / (g gain)
        r, rr, cr = params.rpy_coef[1], params.rpy_rates_coef[1], params.cmd_rpy_coef[1]
        dxy = params.drag_matrix[0, 0] / m
        a = np.array([[0, 1, 0, 0], [0, dxy, g, 0], [0, 0, 0, 1], [0, 0, r, rr]], dtype=float)
        b = np.array([0, 0, 0, cr / (g * params.attitude_gain[1])])
        return a, b, np.array([0, -dxy, 0, 0]), np.array([0, 1.0, 0, 0])
    dz = params.drag_matrix[2, 2] / m
    if params.thrust_time_s is None:  # (p, v)
        return (
            np.array([[0, 1], [0, dz]], dtype=float),
            np.array([0, 1.0]),
            np.array([0, -dz]),
            np.array([0, 1.0]),
        )
    tau = params.thrust_time_s  # (p, v, force offset / m)
    a = np.array([[0, 1, 0], [0, dz, 1], [0, 0, -1 / tau]], dtype=float)
    return a, np.array([0, 0, 1 / tau]), np.array([0, -dz, 0]), np.array([0, 1.0, 0])


def closed_loop(
    params: QuadrotorParams, spec: QuadrotorSpec, axis: str, *, position: bool
) -> tuple[Array, Array, Array, Array]:
    """Continuous closed loop ``(A, B, E, C)`` of one axis: input the velocity command, output v.

    States: the airframe's then the integral. With ``position`` the position reference is held
    at 0 (for stability only).
    """
    ap, bp, ep, cv = _airframe(params, axis)
    g = spec.gains
    kp, kv, ki = (
        (g.kp_xy_per_s, g.kv_xy_per_s, g.ki_xy_per_s2)
        if axis == "xy"
        else (g.kp_z_per_s, g.kv_z_per_s, g.ki_z_per_s2)
    )
    ce = -cv - (kp if position else 0.0) * np.eye(ap.shape[0])[0]  # velocity error row (refs 0)
    s = ap.shape[0]
    a = np.zeros((s + 1, s + 1))
    a[:s, :s] = ap + kv * np.outer(bp, ce)
    a[:s, s] = ki * bp
    a[s, :s] = ce
    b = np.append(kv * bp, 1.0)
    return a, b, np.append(ep, 0.0), np.append(cv, 0.0)


def inner_loop_radius(params: QuadrotorParams, spec: QuadrotorSpec, axis: str) -> float:
    """Spectral radius of the linearised sampled loop: RK4 airframe step, PID held over the step."""
    ap, bp, _, cv = _airframe(params, axis)
    g = spec.gains
    kp, kv, ki = (
        (g.kp_xy_per_s, g.kv_xy_per_s, g.ki_xy_per_s2)
        if axis == "xy"
        else (g.kp_z_per_s, g.kv_z_per_s, g.ki_z_per_s2)
    )
    h = 1.0 / spec.rate_hz
    s = ap.shape[0]
    z, eye = h * ap, np.eye(s)
    phi = eye + z @ (eye + z @ (eye / 2 + z @ (eye / 6 + z / 24)))
    gam = h * (eye + z @ (eye / 2 + z @ (eye / 6 + z / 24))) @ bp
    ce = -cv - kp * eye[0]
    m = np.zeros((s + 1, s + 1))  # I+ = I + h ce x ; a = kv ce x + ki I+
    m[:s, :s] = phi + np.outer(gam, (kv + ki * h) * ce)
    m[:s, s] = ki * gam
    m[s, :s] = h * ce
    m[s, s] = 1.0
    return float(np.max(np.abs(np.linalg.eigvals(m))))
