r"""The fitted ``so_rpy`` quadrotor models of drone-models (utiasDSL, MIT), vectorised in numpy.

drone-models ships, per Crazyflie platform, identified closed attitude loops driven by the
firmware's ``[roll, pitch, yaw, thrust]`` command. Its ``so_rpy/model.py`` (v0.1.0) reads

.. math::
    \dot p = v,\qquad
    m \dot v = m g + (c_{acc} + c_f F)\, R(q) e_z + R D R^\top v + f_{dist},\qquad
    \ddot\psi = c_\psi \psi + c_{\dot\psi} \dot\psi + c_u u_{rpy},

with :math:`\psi = (\phi, \theta, \psi)` the extrinsic ``xyz`` Euler angles of :math:`q`
(:math:`R = R_z(\psi) R_y(\theta) R_x(\phi)`). ``so_rpy`` applies the command ``F = F_cmd`` at
once and has no drag (``D = 0``); ``so_rpy_rotor_drag`` lags the thrust,
``\dot F = (F_cmd - F) / \tau_T`` (its ``thrust_time_coef`` is that time constant in seconds,
although its docstring says 1/s), and has the body-frame linear drag ``D`` (``drag_matrix``,
kg/s, negative). Its quaternion form turns :math:`\ddot\psi` into :math:`\dot\omega` through
the Euler-rate maps; :func:`quat_dynamics` reproduces that form (the tests check it against the
package), while the plant integrates the equivalent Euler form (:func:`euler_derivatives`),
which is the package's own ``symbolic_dynamics_euler`` and needs no quaternion renormalisation.

The parameters are read from the package's ``params.toml`` files through
``importlib.metadata``, without importing ``drone_models`` (its ``__init__`` raises when scipy
was imported before without ``SCIPY_ARRAY_API=1``, and sets that variable process-wide).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import metadata

import numpy as np

from mpcform._validate import Array
from mpcform.errors import MPCFormError, ValidationError

PLATFORMS = ("cf2x_L250", "cf2x_P250", "cf2x_T350", "cf21B_500")
MODELS = ("so_rpy", "so_rpy_rotor_drag")
DISTRIBUTION = "drone-models"


@dataclass(frozen=True, eq=False)
class QuadrotorParams:
    """One platform's parameters for one model (SI units; drag matrix in the body frame, kg/s)."""

    platform: str
    model: str
    version: str
    mass_kg: float
    gravity_mps2: float  # magnitude of gravity_vec
    acc_coef_N: float
    cmd_f_coef: float  # force = acc_coef + cmd_f_coef * thrust (dimensionless)
    rpy_coef: Array  # (3,) 1/s^2
    rpy_rates_coef: Array  # (3,) 1/s
    cmd_rpy_coef: Array  # (3,) 1/s^2
    thrust_time_s: float | None  # first-order thrust lag (so_rpy_rotor_drag), None = instant
    drag_matrix: Array  # (3, 3) diagonal, kg/s, <= 0
    thrust_min_N: float  # collective command limits: 4 x the per-motor values
    thrust_max_N: float

    @property
    def hover_command_N(self) -> float:
        """Thrust command that holds hover: ``(m g - acc_coef) / cmd_f_coef`` (not ``m g``)."""
        return (self.mass_kg * self.gravity_mps2 - self.acc_coef_N) / self.cmd_f_coef

    @property
    def attitude_gain(self) -> Array:
        """Steady-state angle per commanded angle, ``-cmd_rpy_coef / rpy_coef`` (3,)."""
        return -self.cmd_rpy_coef / self.rpy_coef

    @property
    def drag_per_s(self) -> Array:
        """Linear drag per unit mass ``-diag(D) / m`` (3,) [1/s]: the wind coupling ``k_drag / m``."""
        return -np.diag(self.drag_matrix) / self.mass_kg


def package_file(relative: str) -> str:
    """Path of a file inside the installed drone-models package (the package is not imported)."""
    try:
        dist = metadata.distribution(DISTRIBUTION)
    except metadata.PackageNotFoundError as exc:
        raise MPCFormError("the quadrotor plant needs drone-models: pip install 'mpcform[flight]'") from exc
    return str(dist.locate_file(f"drone_models/{relative}"))


def load_params(platform: str = "cf2x_L250", model: str = "so_rpy_rotor_drag") -> QuadrotorParams:
    """Read ``data/params.toml`` and ``<model>/params.toml`` (model values take precedence)."""
    if platform not in PLATFORMS:
        raise ValidationError("quadrotor.platform", f"expected one of {PLATFORMS}, got {platform!r}")
    if model not in MODELS:
        raise ValidationError("quadrotor.model", f"expected one of {MODELS}, got {model!r}")
    tables = []
    for rel in ("data/params.toml", f"{model}/params.toml"):
        with open(package_file(rel), "rb") as fh:
            tables.append(tomllib.load(fh)[platform])
    p = tables[0] | tables[1]
    drag = np.array(p["drag_matrix"], dtype=float)  # data/params.toml: "from the so_rpy_rotor_drag model"
    if np.any(drag != np.diag(np.diag(drag))) or drag[0, 0] != drag[1, 1] or np.any(np.diag(drag) > 0):
        raise MPCFormError(f"{platform}: expected a diagonal drag matrix <= 0 with equal x and y, got {drag}")
    return QuadrotorParams(
        platform=platform,
        model=model,
        version=metadata.version(DISTRIBUTION),
        mass_kg=float(p["mass"]),
        gravity_mps2=float(-p["gravity_vec"][2]),
        acc_coef_N=float(p["acc_coef"]),
        cmd_f_coef=float(p["cmd_f_coef"]),
        rpy_coef=np.array(p["rpy_coef"], dtype=float),
        rpy_rates_coef=np.array(p["rpy_rates_coef"], dtype=float),
        cmd_rpy_coef=np.array(p["cmd_rpy_coef"], dtype=float),
        thrust_time_s=float(p["thrust_time_coef"]) if model == "so_rpy_rotor_drag" else None,
        drag_matrix=drag,
        thrust_min_N=4.0 * float(p["thrust_min"]),
        thrust_max_N=4.0 * float(p["thrust_max"]),
    )


# State layout of the Euler form, one row per drone: p(3) rpy(3) v(3) rpy_rates(3) thrust(1) [N].
P, RPY, V, DRPY, F = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), 12
STATE = 13


def body_z(rpy: Array) -> Array:
    """Third column of ``R = Rz Ry Rx`` (n, 3): the thrust direction in the world frame."""
    c, s = np.cos(rpy), np.sin(rpy)
    z = np.empty_like(rpy)
    crsp = c[:, 0] * s[:, 1]
    z[:, 0] = crsp * c[:, 2] + s[:, 0] * s[:, 2]
    z[:, 1] = crsp * s[:, 2] - s[:, 0] * c[:, 2]
    z[:, 2] = c[:, 0] * c[:, 1]
    return z


def drag_force(params: QuadrotorParams, z: Array, air_mps: Array) -> Array:
    """Body-frame linear drag in the world frame, ``R D R^T air`` (n, 3) [N].

    For ``D = diag(a, a, b)`` this is ``a air + (b - a) z (z . air)`` with ``z`` the body z axis.
    """
    a, b = params.drag_matrix[0, 0], params.drag_matrix[2, 2]
    return a * air_mps + ((b - a) * (z * air_mps).sum(axis=1))[:, None] * z


def euler_derivatives(
    params: QuadrotorParams,
    x: Array,
    cmd: Array,
    dist_f: Array,
    z: Array | None = None,
    *,
    drag_air_mps: Array | None = None,
) -> Array:
    """d/dt of the Euler-form state ``x`` (n, 13) under ``cmd`` (n, 4) and world force ``dist_f``.

    The model's own drag term acts for ``so_rpy_rotor_drag`` only (``so_rpy`` has none), on
    ``drag_air_mps`` (n, 3) if given, else on the velocity as in the package (the drag being
    linear, air ``v - w`` is the package's drag plus the disturbance force ``-R D R^T w``);
    ``dist_f`` (n, 3) [N] is the package's disturbance-force input; ``z`` is
    ``body_z(x[:, RPY])`` when the caller has it.
    """
    dx = np.empty_like(x)
    if z is None:
        z = body_z(x[:, RPY])
    if params.thrust_time_s is None:
        thrust = cmd[:, 3]
        dx[:, F] = 0.0
    else:
        thrust = x[:, F]
        dx[:, F] = (cmd[:, 3] - thrust) * (1.0 / params.thrust_time_s)
        dist_f = dist_f + drag_force(params, z, x[:, V] if drag_air_mps is None else drag_air_mps)
    inv_m = 1.0 / params.mass_kg
    dx[:, V] = ((params.acc_coef_N + params.cmd_f_coef * thrust) * inv_m)[:, None] * z + dist_f * inv_m
    dx[:, 8] -= params.gravity_mps2
    dx[:, P] = x[:, V]
    dx[:, RPY] = x[:, DRPY]
    dx[:, DRPY] = (
        params.rpy_coef * x[:, RPY] + params.rpy_rates_coef * x[:, DRPY] + params.cmd_rpy_coef * cmd[:, :3]
    )
    return dx


# -- quaternion form (for the comparison with the package and for the plant's output) -----------


def quat_to_rpy(q: Array) -> Array:
    """Extrinsic ``xyz`` Euler angles (n, 3) of unit quaternions ``q`` (n, 4, xyzw)."""
    x, y, z, w = (q[:, i] for i in range(4))
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=1)


def rpy_to_quat(rpy: Array) -> Array:
    """Unit quaternions (..., 4, xyzw) of extrinsic ``xyz`` Euler angles (..., 3)."""
    h = 0.5 * np.asarray(rpy)
    cr, sr = np.cos(h[..., 0]), np.sin(h[..., 0])
    cp, sp = np.cos(h[..., 1]), np.sin(h[..., 1])
    cy, sy = np.cos(h[..., 2]), np.sin(h[..., 2])
    return np.stack(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ],
        axis=-1,
    )


def _rates_maps(rpy: Array, drpy: Array) -> tuple[Array, Array]:
    """``M`` with ``omega = M rpy_rates`` and its time derivative, both (n, 3, 3)."""
    sr, cr = np.sin(rpy[:, 0]), np.cos(rpy[:, 0])
    sp, cp = np.sin(rpy[:, 1]), np.cos(rpy[:, 1])
    dr, dp = drpy[:, 0], drpy[:, 1]
    one, zero = np.ones_like(sr), np.zeros_like(sr)
    m = np.stack(
        [
            np.stack([one, zero, -sp], -1),
            np.stack([zero, cr, sr * cp], -1),
            np.stack([zero, -sr, cr * cp], -1),
        ],
        -2,
    )
    dm = np.stack(
        [
            np.stack([zero, zero, -cp * dp], -1),
            np.stack([zero, -sr * dr, cr * cp * dr - sr * sp * dp], -1),
            np.stack([zero, -cr * dr, -sr * cp * dr - cr * sp * dp], -1),
        ],
        -2,
    )
    return m, dm


def quat_dynamics(
    params: QuadrotorParams,
    pos: Array,
    quat: Array,
    vel: Array,
    ang_vel: Array,
    cmd: Array,
    thrust: Array | None = None,
    dist_f: Array | None = None,
) -> tuple[Array, Array, Array, Array, Array | None]:
    """The package's ``dynamics(pos, quat, vel, ang_vel, cmd, rotor_vel, dist_f)`` for (n, .) arrays.

    Returns ``(pos_dot, quat_dot, vel_dot, ang_vel_dot, thrust_dot)``; ``thrust`` (n, 1) is the
    rotor_drag model's thrust state (the package calls it ``rotor_vel``), ignored by ``so_rpy``.
    """
    n = pos.shape[0]
    rpy = quat_to_rpy(quat)
    m, dm = _rates_maps(rpy, np.zeros_like(rpy))
    drpy = np.linalg.solve(m, ang_vel[..., None])[..., 0]
    x = np.zeros((n, STATE))
    x[:, P], x[:, RPY], x[:, V], x[:, DRPY] = pos, rpy, vel, drpy
    if thrust is not None:
        x[:, F] = thrust[:, 0]
    dx = euler_derivatives(params, x, cmd, np.zeros((n, 3)) if dist_f is None else dist_f)
    m, dm = _rates_maps(rpy, drpy)
    ang_vel_dot = (dm @ drpy[..., None] + m @ dx[:, DRPY, None])[..., 0]
    wx, wy, wz = ang_vel[:, 0], ang_vel[:, 1], ang_vel[:, 2]
    qx, qy, qz, qw = (quat[:, i] for i in range(4))
    quat_dot = 0.5 * np.stack(
        [
            wx * qw + wz * qy - wy * qz,
            wy * qw - wz * qx + wx * qz,
            wz * qw + wy * qx - wx * qy,
            -wx * qx - wy * qy - wz * qz,
        ],
        axis=1,
    )
    thrust_dot = None if params.thrust_time_s is None else dx[:, F, None]
    return dx[:, P], quat_dot, dx[:, V], ang_vel_dot, thrust_dot
