"""Shapes as signed distances, and the phase field phi = tanh(-d/(sqrt(2) eps)) (+1 inside).

The profile tanh(s/(sqrt(2) eps)) is the 1D minimiser of the area functional (5); with it, (4) gives
volume = (|Omega| + A)/2 and (5) gives area = 3 sqrt(2) B / 4 up to O(eps^2) (Section 3.1).
Distances of ellipses, ellipsoids and biconcave disks are first-order approximations f/|grad f|,
exact on the surface, which is all the tanh profile needs to start a solve.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.scene.shape_spec import Shape


def _center(shape: Shape, box) -> np.ndarray:
    if shape.center is not None:
        return np.asarray(shape.center, float)
    return np.array([(a + b) / 2 for a, b in box])


def signed_distance(shape: Shape, points: np.ndarray, box) -> np.ndarray:
    """Signed distance (negative inside) of ``shape`` at ``points`` (N x dim)."""
    x = np.asarray(points, float) - _center(shape, box)
    s = shape.shape
    if s in ("circle", "sphere"):
        return np.linalg.norm(x, axis=1) - shape.radius
    if s in ("ellipse", "ellipsoid"):
        a = np.asarray(shape.semi_axes, float)
        f = np.sum((x / a) ** 2, axis=1) - 1.0
        grad = np.linalg.norm(2 * x / a**2, axis=1)
        return f / np.maximum(grad, 1e-12 / a.min())
    if s == "torus":  # major radius R in the x-y plane, minor radius r
        R, r = shape.radii
        rho = np.hypot(x[:, 0], x[:, 1])
        return np.hypot(rho - R, x[:, 2]) - r
    if s == "disk":  # flat disk: a cylinder of the given radius and thickness with rounded rim
        t = shape.thickness / 2
        rho = np.hypot(x[:, 0], x[:, 1])
        q = np.stack([np.maximum(rho - (shape.radius - t), 0.0), np.abs(x[:, 2])], axis=1)
        inner = np.minimum(np.maximum(rho - (shape.radius - t), np.abs(x[:, 2]) - t), 0.0)
        return np.linalg.norm(q, axis=1) - t + inner
    if s == "biconcave":  # red-blood-cell profile (Evans-Fung), half-thickness h(rho)
        R = shape.radius
        u = np.minimum(np.hypot(x[:, 0], x[:, 1]) / R, 1.0)
        h = 0.5 * R * np.sqrt(1 - u**2) * (0.207 + 2.003 * u**2 - 1.123 * u**4)
        rho = np.hypot(x[:, 0], x[:, 1])
        outside_rim = np.maximum(rho - R, 0.0)
        d = np.where(rho < R, np.abs(x[:, 2]) - h, np.hypot(outside_rim, x[:, 2]))
        return d * 0.5  # |grad| of |z| - h exceeds 1 near the rim; halve for a smooth start
    raise ValueError(f"unknown shape {s!r}")


def phase_field(shape: Shape, points: np.ndarray, box, epsilon: float) -> np.ndarray:
    """phi = tanh(-d / (sqrt(2) eps)): +1 inside the shape, -1 outside.

    Two starts that are no shape, for stress tests: "constant" (phi = value) and "noise"
    (phi uniform in (-1, 1) from a seeded generator, reproducible).
    """
    if shape.shape == "constant":
        return np.full(len(points), shape.value)
    if shape.shape == "noise":
        return np.random.default_rng(shape.seed).uniform(-1.0, 1.0, len(points))
    return np.tanh(-signed_distance(shape, points, box) / (np.sqrt(2.0) * epsilon))
