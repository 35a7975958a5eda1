"""The completion family: seeded random runs on every plant that must all complete, safely.

Parts, cycled: planar swaps (antipodal rings and random permutations) and spatial swaps of 2-21
drones, formations moving to a new centroid, rotation and scale, fields of 1-4 spheres between
start and goal, missions (translate, turn, scale), and close starts (1-3 pairs at 0.2-0.9 d_min).
Each run draws the coupling (joint, decoupled), the velocity set (polytope, box), dt (0.05-0.1 s),
the horizon (6-10) and the plant, cycled: ideal, lag (0.1-0.3 s), second order, quadrotor in
gusts (mean wind up to 1 m/s, gusts up to 0.5 m/s, shared or per drone; v_max below the valid
speed of its margin). Targets are at least ``d_min + 4 delta + 0.1 m`` apart (``delta`` the plant's
margin: the README's limit for settling in gusts); the duration is twice the longest straight-line
travel at the velocity set's slowest speed (v_max, ``v_max / sqrt(d)`` for the box), plus the time
to speed up and brake at the default a_max, plus the reference's own time, plus 10 s.

``python tests/completion_family.py [COUNT] [--seed S]`` runs a campaign on two processes and
prints the counts per plant and coupling, the completion-time distribution and every failure.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from families import close_pairs
from scipy.spatial.distance import pdist

PARTS = ("swap_planar", "swap_spatial", "formation", "spheres", "mission", "close_start")
PLANTS = ("ideal", "lag", "second_order", "quadrotor")
SEED = 20261204
PLANT_EVENTS = ("drone_contacts", "floor_contacts", "flipped")  # crazyflow's (mpcform.sim.crazyflow)
A_MAX_MPS2 = 1.7851  # the planner's default, for the duration's ramps


def spread(rng: np.random.Generator, n: int, dim: int, gap_m: float) -> np.ndarray:
    """n centred random offsets at least ``gap_m`` apart (rejection sampling in a growing box)."""
    side = max(1.0, 1.1 * gap_m * n ** (1.0 / dim))
    while True:
        pts = rng.uniform(-side, side, (n, dim))
        if n < 2 or pdist(pts).min() >= gap_m:
            return pts - pts.mean(axis=0)
        side *= 1.05


def draw_plant(rng: np.random.Generator, kind: str, dim: int) -> dict[str, Any] | None:
    if kind == "lag":
        return {"kind": "lag", "time_constant": float(rng.choice([0.1, 0.2, 0.3]))}
    if kind == "second_order":
        return {"kind": "second_order", "damping": float(rng.uniform(0.6, 1.0))}
    if kind == "quadrotor":
        mean = rng.normal(size=dim)
        mean[2:] = 0.0
        mean *= rng.uniform(0.0, 1.0) / max(np.linalg.norm(mean), 1e-9)
        wind = {
            "mean": mean.tolist(),
            "gust_std": float(rng.uniform(0.0, 0.5)),
            "gust_time": float(rng.uniform(0.5, 2.0)),
            "gust_field": str(rng.choice(["shared", "per_drone"])),
        }
        return {"kind": "quadrotor", "wind": wind}
    return None


def _zero(dim: int) -> float | list[float]:
    return 0.0 if dim == 2 else [0.0, 0.0, 0.0]


def _shape(rng: np.random.Generator, part: str, dim: int, n: int, gap: float, d_min: float) -> dict[str, Any]:
    """The part's template, start and reference (and obstacles), with targets ``gap`` apart."""
    offsets = spread(rng, n, dim, gap)
    if part in ("swap_planar", "swap_spatial"):
        if part == "swap_planar" and rng.random() < 0.5:  # antipodal ring: every path crosses the centre
            radius = max(1.5, 0.55 * gap * n / np.pi + 0.1, 0.5 * gap / np.sin(np.pi / max(n, 2)))
            angle = 2 * np.pi * np.arange(n) / n
            offsets = radius * np.column_stack([np.cos(angle), np.sin(angle)])
        start = -offsets if rng.random() < 0.5 else offsets[rng.permutation(n)]
        ref = {"kind": "constant", "centroid": [0.0] * dim, "rotation": _zero(dim), "scale": 1.0}
        return {"offsets": offsets, "initial": {"positions": start.tolist()}, "reference": ref}
    if part == "formation":
        turn = float(rng.uniform(-np.pi, np.pi))
        rotation: Any = turn if dim == 2 else (turn * np.array([0.0, 0.0, 1.0])).tolist()
        start_scale = float(rng.uniform(1.0, 1.5))
        initial = {"centroid": rng.uniform(-3, 3, dim).tolist(), "rotation": _zero(dim), "scale": start_scale}
        ref = {"kind": "constant", "centroid": rng.uniform(-4, 4, dim).tolist(), "rotation": rotation}
        ref["scale"] = float(rng.uniform(1.0, 1.5))
        return {"offsets": offsets, "initial": initial, "reference": ref}
    if part == "mission":
        frames = [{"centroid": rng.uniform(-6, 6, dim).tolist()}]
        turn = float(rng.uniform(-np.pi / 2, np.pi / 2))
        frames.append({"rotation": turn if dim == 2 else [0.0, 0.0, turn]})
        frames.append({"scale": float(rng.uniform(1.0, 1.6)), "hold": 1.0})
        initial = {"centroid": [0.0] * dim, "rotation": _zero(dim), "scale": 1.0}
        return {"offsets": offsets, "initial": initial, "reference": {"kind": "mission", "keyframes": frames}}
    if part == "close_start":
        start = close_pairs(rng, offsets, d_min)
        shift = rng.uniform(-3.0, 3.0, dim)
        ref = {"kind": "constant", "centroid": shift.tolist(), "rotation": _zero(dim), "scale": 1.0}
        return {"offsets": offsets, "initial": {"positions": start.tolist()}, "reference": ref}
    # spheres: the formation flies 8-16 m through 1-4 spheres, each clear of every start and goal
    direction = rng.normal(size=dim)
    direction /= np.linalg.norm(direction)
    length = float(rng.uniform(8.0, 16.0))
    start, goal = offsets - 0.5 * length * direction, offsets + 0.5 * length * direction
    obstacles = []
    for _ in range(int(rng.integers(1, 5))):
        center = rng.uniform(-0.35, 0.35) * length * direction + rng.uniform(-2.0, 2.0, dim)
        radius, clearance = float(rng.uniform(0.3, 1.0)), float(rng.uniform(0.1, 0.3))
        ends = np.concatenate([start, goal])
        if np.linalg.norm(ends - center, axis=1).min() >= radius + clearance + gap:
            obstacles.append({"center": center.tolist(), "radius": radius, "clearance": clearance})
    ref = {"kind": "constant", "centroid": (0.5 * length * direction).tolist(), "rotation": _zero(dim)}
    ref["scale"] = 1.0
    out = {"offsets": offsets, "initial": {"positions": start.tolist()}, "reference": ref}
    return out | {"obstacles": obstacles}


def scenario(rng: np.random.Generator, index: int) -> dict[str, Any]:
    """Run ``index`` of the family (its part and plant cycled by ``index``)."""

    part, plant_kind = PARTS[index % len(PARTS)], PLANTS[(index // len(PARTS)) % len(PLANTS)]
    dim = 2 if part == "swap_planar" else 3 if part == "swap_spatial" else int(rng.choice([2, 3]))
    n = int(np.exp(rng.uniform(np.log(2), np.log(21.99))))
    if part == "close_start":
        n = max(n, 3)
    d_min, dt = float(rng.uniform(0.3, 0.7)), float(rng.choice([0.05, 0.06, 0.08, 0.1]))
    v_max = float(rng.uniform(0.5, 2.0))
    plant = draw_plant(rng, plant_kind, dim)
    sc: dict[str, Any] = {
        "version": 1,
        "name": f"completion_{index}_{part}_{plant_kind}",
        "dim": dim,
        "seed": int(rng.integers(1 << 30)),
        "template": {
            "shape": "explicit",
            "offsets": [[i - (n - 1) / 2] + [0.0] * (dim - 1) for i in range(n)],
        },
        "limits": {"v_max": v_max, "d_min": d_min},
        "controller": {
            "kind": "mpc",
            "gain": float(rng.uniform(1.0, 3.0)),
            "horizon": int(rng.integers(6, 11)),
            "coupling": str(rng.choice(["joint", "decoupled"])),
            "velocity_set": str(rng.choice(["polytope", "box"])),
        },
        "simulation": {"dt": dt, "duration": 10.0},
        "initial": {"centroid": [0.0] * dim, "rotation": _zero(dim), "scale": 1.0},
        "reference": {"kind": "constant"},
    }
    if plant is not None:
        sc["plant"] = plant
    return placed(rng, sc, part, plant_kind)


def placed(
    rng: np.random.Generator,
    sc: dict[str, Any],
    part: str,
    plant_kind: str,
    a_max: float = A_MAX_MPS2,
    fence_room_m: float | None = None,
) -> dict[str, Any]:
    """``sc`` with its part's geometry (targets ``d_min + 4 delta + 0.1 m`` apart at least, ``delta``
    the plant's margin; a quadrotor's v_max below its valid speed), with ``fence_room_m`` a
    geofence that far around the starts and goals, and its duration (module docstring, speeding up
    and braking at ``a_max``)."""
    from mpcform.scenario.load import scenario_from_dict

    dim, n, d_min = sc["dim"], len(sc["template"]["offsets"]), sc["limits"]["d_min"]
    v_max = sc["limits"]["v_max"]
    probe = scenario_from_dict(sc)  # the plant's margin and valid speed, before the geometry
    if plant_kind == "quadrotor":
        sc["limits"]["v_max"] = v_max = min(v_max, 0.95 * probe.robustness.valid_speed_mps)
    gap = d_min + 4.0 * probe.robustness.margin_m + 0.1
    shape = _shape(rng, part, dim, n, gap * float(rng.uniform(1.0, 1.5)), d_min)
    sc["template"]["offsets"] = shape.pop("offsets").tolist()
    sc |= shape
    if not sc.get("obstacles", True):
        del sc["obstacles"]
    built = scenario_from_dict(sc)
    start, goal = built.initial_positions_m, built.reference.targets(np.array([1e9]))[0][0]
    if fence_room_m is not None:  # a box around the starts and goals (a mission may leave it: refused)
        ends = np.concatenate([start, goal])
        sc["limits"]["geofence_min"] = (ends.min(axis=0) - fence_room_m).tolist()
        sc["limits"]["geofence_max"] = (ends.max(axis=0) + fence_room_m).tolist()
    far = float(np.linalg.norm(goal - start, axis=1).max())
    ref_s = getattr(built.reference, "duration_s", 0.0)
    v_set = v_max / float(np.sqrt(dim)) if sc["controller"]["velocity_set"] == "box" else v_max  # its slowest
    sc["simulation"]["duration"] = round(2.0 * far / v_set + 2.0 * v_max / a_max + ref_s + 10.0, 2)
    return sc


def family(count: int, seed: int = SEED) -> Iterator[dict[str, Any]]:
    """The first ``count`` runs (run ``i`` drawn from its own stream, so a prefix is stable)."""
    for index in range(count):
        yield scenario(np.random.default_rng([seed, index]), index)


def outcome(sc: dict[str, Any]) -> dict[str, Any]:
    """Run one scenario dict: its completion on the true motion, the time it completed, what it is
    (part, plant, coupling, n) and its ``violations`` along the dense true path (the plant's, else
    the control samples): (sample, pair) closer than d_min for pairs that start d_min apart, closer
    than they started less twice the plant's margin ``delta`` for pairs that start inside it (the
    plan never brings them closer; wind and tracking move each drone up to ``delta`` off it before
    they separate) and not d_min apart at the end, plus the true obstacle and geofence violations."""
    from mpcform.run.runner import run_scenario
    from mpcform.scenario.load import scenario_from_dict

    start = time.process_time()
    built = scenario_from_dict(sc)
    run = run_scenario(built)
    m, sim = run.summary["metrics"], run.simulation
    true = "_true" if "min_separation_true" in m else ""
    p = sim.positions_m if sim.true is None else sim.true.positions_m
    i, k = np.triu_indices(p.shape[1], 1)
    gap = np.linalg.norm(p[:, i] - p[:, k], axis=2)  # (K, P)
    d_min, tol = sc["limits"]["d_min"], 1e-6
    drift = np.where(gap[0] < d_min, 2.0 * built.robustness.margin_m, 0.0)
    need = np.minimum(d_min, gap[0] - drift) - tol  # a close start: no closer than it started, less 2 delta
    late = (gap[-1] < d_min - tol) & (gap[0] < d_min)
    return {
        "name": sc["name"],
        "plant": sc.get("plant", {}).get("kind", "ideal"),
        "coupling": sc["controller"]["coupling"],
        "n": len(sc["template"]["offsets"]),
        "duration": sc["simulation"]["duration"],
        "dt": sc["simulation"]["dt"],
        "completion": m["completion"],
        "time_to_complete": m["time_to_complete"],
        "incomplete": list(zip(m["incomplete_drones"], m["incomplete_distances_m"], strict=True)),
        "violations": int((gap < need).sum() + late.sum())
        + (m.get(f"obstacle_violations{true}") or 0)
        + (m.get(f"geofence_violations{true}") or 0),
        "min_separation": m[f"min_separation{true}"],
        "slack_steps": m["slack_steps"],
        "growth_slack_steps": m["growth_slack_steps"],
        "growth_exceeded_steps": m["growth_exceeded_steps"],
        "lowered": m["lowered_first_rows"],
        "deadline_misses": m["deadline_misses"],
        "cpu_s": time.process_time() - start,
        "events": {k: v for k, v in run.summary["plant"].items() if k in PLANT_EVENTS and v},
    }


def _run(args: tuple[int, int]) -> dict[str, Any]:
    index, seed = args
    sc = scenario(np.random.default_rng([seed, index]), index)
    return outcome(sc)


def campaign(count: int, seed: int = SEED, workers: int = 2) -> list[dict[str, Any]]:
    """Run the first ``count`` runs on ``workers`` processes."""
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_run, [(i, seed) for i in range(count)]))


def report(results: list[dict[str, Any]]) -> str:
    """Counts per plant and coupling, completion times, and every failing run."""
    lines = [f"{len(results)} runs"]
    for plant in PLANTS:
        for coupling in ("joint", "decoupled"):
            group = [r for r in results if r["plant"] == plant and r["coupling"] == coupling]
            done = sum(r["completion"] == 1.0 for r in group)
            lines.append(f"  {plant:13s} {coupling:9s} {len(group):4d} runs, {done:4d} complete")
    times = np.array([r["time_to_complete"] for r in results if r["time_to_complete"] is not None])
    if times.size:
        q = np.percentile(times, [0, 50, 90, 99, 100])
        lines.append(
            "completion time [s]: min {:.1f}, median {:.1f}, p90 {:.1f}, p99 {:.1f}, max {:.1f}".format(*q)
        )
    share = np.array([r["time_to_complete"] / r["duration"] for r in results if r["time_to_complete"]])
    if share.size:
        lines.append(f"completion time / duration: median {np.median(share):.2f}, max {share.max():.2f}")
    cpu = np.array([r["cpu_s"] for r in results])
    spread = f"median {np.median(cpu):.2f}, p90 {np.percentile(cpu, 90):.2f}, max {cpu.max():.1f}"
    lines.append(f"CPU per run [s]: {spread}, total {cpu.sum():.0f}")
    for key in ("slack_steps", "growth_slack_steps", "growth_exceeded_steps", "lowered"):
        hit = [r for r in results if r[key]]
        close = sum("close_start" in r["name"] for r in hit)
        lines.append(f"{key}: {len(hit)} runs ({close} close starts), {sum(r[key] for r in hit)} steps")
    bad = [r for r in results if r["completion"] < 1.0 or r["violations"]]
    lines += [f"FAIL {r}" for r in bad]
    return "\n".join(lines)


if __name__ == "__main__":
    args = sys.argv[1:]
    seed = int(args[args.index("--seed") + 1]) if "--seed" in args else SEED
    count = int(args[0]) if args and not args[0].startswith("--") else 150
    print(report(campaign(count, seed)))
