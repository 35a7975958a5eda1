"""Independent truth for the shapes' tests: dense samples of a core's surface written from its
definition (not from the library's projection) and central finite differences."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def box_surface(center: np.ndarray, size: np.ndarray, step_m: float = 0.01) -> np.ndarray:
    """Points (N, d) on the faces of the axis-aligned box ``center +- size / 2``, ``step_m`` apart."""
    dim, half = len(center), 0.5 * np.asarray(size, float)
    axes = [np.linspace(-h, h, max(2, int(np.ceil(2 * h / step_m)) + 1)) for h in half]
    faces = []
    for j in range(dim):
        grid = np.meshgrid(*[axes[i] if i != j else np.array([-half[j], half[j]]) for i in range(dim)])
        faces.append(np.stack([g.ravel() for g in grid], axis=1))
    return center + np.concatenate(faces)


def cylinder_surface(
    center: np.ndarray, radius_m: float, height_m: float, step_m: float = 0.01
) -> np.ndarray:
    """Points (N, 3) on a vertical cylinder's side and caps (a finite ``height_m``), ``step_m`` apart."""
    ang = np.linspace(0.0, 2 * np.pi, int(np.ceil(2 * np.pi * radius_m / step_m)), endpoint=False)
    z = np.linspace(-height_m / 2, height_m / 2, int(np.ceil(height_m / step_m)) + 1)
    a, zz = np.meshgrid(ang, z)
    side = np.stack([radius_m * np.cos(a).ravel(), radius_m * np.sin(a).ravel(), zz.ravel()], axis=1)
    rr, aa = np.meshgrid(np.linspace(0.0, radius_m, int(np.ceil(radius_m / step_m)) + 1), ang)
    disc = np.stack([(rr * np.cos(aa)).ravel(), (rr * np.sin(aa)).ravel()], axis=1)
    caps = [np.column_stack([disc, np.full(len(disc), s * height_m / 2)]) for s in (-1, 1)]
    return center + np.concatenate([side, *caps])


def nearest(points: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """The least distance (k,) from each point (k, d) to the samples (N, d)."""
    return np.sqrt(((points[:, None, :] - samples[None]) ** 2).sum(-1).min(axis=1))


def fd_gradient(f: Callable[[np.ndarray], np.ndarray], points: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences (k, d) of ``f``: points (k, d) -> values (k,)."""
    out = np.empty_like(points)
    for j in range(points.shape[1]):
        e = np.zeros(points.shape[1])
        e[j] = h
        out[:, j] = (f(points + e) - f(points - e)) / (2 * h)
    return out


def outside(rng: np.random.Generator, center: np.ndarray, spread_m: float, count: int) -> np.ndarray:
    """Random points (count, d) about ``center``."""
    return center + rng.uniform(-spread_m, spread_m, size=(count, len(center)))
