"""The numpy so_rpy models against drone-models' own functions (run in a subprocess: the package
must be imported with SCIPY_ARRAY_API=1 before scipy, which this test process has imported)."""

import json
import os
import subprocess
import sys
import textwrap
from importlib import metadata

import numpy as np
import pytest

from mpcform.sim import so_rpy

try:  # never import drone_models here: see the module docstring
    metadata.distribution(so_rpy.DISTRIBUTION)
except metadata.PackageNotFoundError:
    pytest.skip("needs drone-models (pip install 'mpcform[flight]')", allow_module_level=True)

PACKAGE_SCRIPT = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    import drone_models  # noqa: F401  (sets SCIPY_ARRAY_API; we set it already)
    from drone_models.core import parametrize
    from drone_models.so_rpy import dynamics as so_rpy
    from drone_models.so_rpy_rotor_drag import dynamics as so_rpy_rotor_drag
    from drone_models.utils.rotation import ang_vel2quat_dot
    args = json.load(sys.stdin)
    out = {}
    for model, fn in (("so_rpy", so_rpy), ("so_rpy_rotor_drag", so_rpy_rotor_drag)):
        f = parametrize(fn, args["platform"])
        a = {k: np.array(v) for k, v in args["state"].items()}
        rotor = a["thrust"] if model == "so_rpy_rotor_drag" else None
        res = f(a["pos"], a["quat"], a["vel"], a["ang_vel"], a["cmd"], rotor, dist_f=a["dist_f"])
        out[model] = [None if r is None else np.asarray(r).tolist() for r in res]
    out["quat_dot_wxyz_formula"] = np.asarray(ang_vel2quat_dot(a["quat"], a["ang_vel"])).tolist()
    json.dump(out, sys.stdout)
    """
)


def random_state(rng, n):
    rpy = rng.uniform([-0.6, -0.6, -np.pi], [0.6, 0.6, np.pi], (n, 3))
    return {
        "pos": rng.normal(size=(n, 3)),
        "quat": so_rpy.rpy_to_quat(rpy),
        "vel": rng.normal(size=(n, 3)),
        "ang_vel": rng.normal(scale=2.0, size=(n, 3)),
        "cmd": np.column_stack([rng.uniform(-0.4, 0.4, (n, 3)), rng.uniform(0.1, 0.5, n)]),
        "thrust": rng.uniform(0.1, 0.5, (n, 1)),
        "dist_f": rng.normal(scale=0.05, size=(n, 3)),
    }


def run_package(platform, state):
    env = dict(os.environ, SCIPY_ARRAY_API="1")
    payload = json.dumps({"platform": platform, "state": {k: v.tolist() for k, v in state.items()}})
    proc = subprocess.run(
        [sys.executable, "-c", PACKAGE_SCRIPT],
        input=payload,
        capture_output=True,
        text=True,
        env=env,
        check=True,
        timeout=120,
    )
    return json.loads(proc.stdout)


@pytest.mark.parametrize("platform", so_rpy.PLATFORMS)
def test_numpy_dynamics_equal_the_package(platform):
    rng = np.random.default_rng(sum(map(ord, platform)))
    state = random_state(rng, 64)
    ref = run_package(platform, state)
    for model in so_rpy.MODELS:
        params = so_rpy.load_params(platform, model)
        thrust = state["thrust"] if model == "so_rpy_rotor_drag" else None
        ours = so_rpy.quat_dynamics(
            params,
            state["pos"],
            state["quat"],
            state["vel"],
            state["ang_vel"],
            state["cmd"],
            thrust,
            state["dist_f"],
        )
        names = ("pos_dot", "quat_dot", "vel_dot", "ang_vel_dot", "thrust_dot")
        for name, mine, theirs in zip(names, ours, ref[model], strict=True):
            if name == "quat_dot":
                continue  # see test_quaternion_rate_is_the_true_derivative
            if theirs is None:
                assert mine is None, (model, name)
            else:
                np.testing.assert_allclose(
                    mine, np.array(theirs), rtol=1e-9, atol=1e-9, err_msg=f"{model} {name}"
                )


def test_quaternion_rate_is_the_true_derivative():
    """Ours is d/dt of q under body rates (finite difference of the rotation); drone-models 0.1.0's
    numeric ``ang_vel2quat_dot`` applies the scalar-first formula to its scalar-last quaternions,
    so we do not use it (the plant integrates the Euler form, which does not need it)."""
    rng = np.random.default_rng(7)
    state = random_state(rng, 16)
    params = so_rpy.load_params()
    _, qdot, _, _, _ = so_rpy.quat_dynamics(
        params, state["pos"], state["quat"], state["vel"], state["ang_vel"], state["cmd"], state["thrust"]
    )
    h = 1e-6
    q, w = state["quat"], state["ang_vel"]
    # q (x) exp(w h / 2) for body rates, in xyzw
    half = 0.5 * h * w
    dq = np.column_stack([half, np.ones(len(q))])
    prod = np.column_stack(
        [
            q[:, 3:4] * dq[:, :3] + dq[:, 3:4] * q[:, :3] + np.cross(q[:, :3], dq[:, :3]),
            q[:, 3] * dq[:, 3] - np.sum(q[:, :3] * dq[:, :3], axis=1),
        ]
    )
    np.testing.assert_allclose(qdot, (prod - q) / h, atol=1e-5)
    theirs = np.array(run_package("cf2x_L250", state)["quat_dot_wxyz_formula"])
    assert np.abs(theirs - qdot).max() > 0.1  # documents the upstream formula (fixed upstream: drop this)


def test_params_come_from_the_package_files():
    p = so_rpy.load_params("cf2x_L250", "so_rpy_rotor_drag")
    assert p.version >= "0.1.0"
    assert p.mass_kg == 0.0319 and p.thrust_time_s == pytest.approx(0.12116392)
    assert p.drag_matrix[0, 0] == -0.01471782
    assert p.hover_command_N != pytest.approx(p.mass_kg * p.gravity_mps2, rel=1e-3)  # cmd_f_coef != 1
    assert so_rpy.load_params("cf2x_L250", "so_rpy").thrust_time_s is None
    assert "drone_models" not in sys.modules  # read from its files, never imported


def test_linear_plants_default_drag_is_the_default_platform():
    from mpcform.sim.plants import DRAG_PER_S

    assert DRAG_PER_S == pytest.approx(so_rpy.load_params().drag_per_s[0], rel=1e-12)


def test_unknown_platform_or_model_is_refused():
    from mpcform.errors import ValidationError

    with pytest.raises(ValidationError, match="quadrotor.platform"):
        so_rpy.load_params("cf3")
    with pytest.raises(ValidationError, match="quadrotor.model"):
        so_rpy.load_params("cf2x_L250", "first_principles")
