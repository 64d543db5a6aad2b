"""The phi = 0 surface of an axisymmetric field: volume, area and total curvature of revolution.

On the meridian half-plane (``mesh.axisymmetric``: P1 on r >= 0, the weight 2 pi r) the zero level
set of the field is a polyline (``io.meridian``: one segment per triangle whose vertices change sign,
inside phi > 0). Here each segment is oriented with the inside on its left, so the measures of the
surface it sweeps about the z axis are exact sums over segments (a segment sweeps a frustum) and
need no chaining for the volume and the area:

* V_0 = sum pi (z_1 - z_0)(r_0^2 + r_0 r_1 + r_1^2) / 3 (Green: the closed boundary integral of
  pi r^2 dz is int 2 pi r dr dz; the axis segments, r = 0, add nothing, so a meridian from the axis
  to the axis needs no closing; a torus's closed section and a cavity's reversed curve are summed
  with their signs): the volume of revolution of {phi_h > 0};
* S_0 = sum pi (r_0 + r_1) |segment| (the frusta's lateral areas);
* int_Gamma kappa dA (kappa = kappa_1 + kappa_2, positive where convex towards the outside): on a
  frustum the azimuthal curvature is n_r / r and kappa_1 = 0, so it adds 2 pi n_r |segment| =
  2 pi (z_1 - z_0); at a vertex of the polyline the meridian turns by theta (signed, left positive)
  on the circle of length 2 pi r: 2 pi r theta (the Steiner edge sum sum_e |e| theta_e of the 3D
  grids' ``verify.shape``, in the limit of many angles). A sphere of radius R gets 4 pi R + 4 pi R,
  a torus 0 + 4 pi^2 R.

A node where phi = 0 exactly is outside (as in ``io.meridian``); the cuts of its edges are that one
point, which the curve passes once (one key per node). The field is closed only if every curve ends
on the axis or returns to its start: a curve ending on the box's wall r = R or z = z0, z1 gives None
(no closed surface), as a 2D contour leaving the box; so does a node where two inside sectors touch
(the curve is not simple there). Accuracy: the P1 interpolant's zero level is O(h^2) from the
field's (the closed forms of ``tests/verify/test_shape_meridian.py``).
"""

from __future__ import annotations

import math

import numpy as np

AXIS_TOL = 1e-12  # r <= AXIS_TOL x the box radius: on the axis (the cut of an axis edge has r = 0 exactly)


def _oriented_segments(p: np.ndarray, t: np.ndarray, phi: np.ndarray):
    """(start keys, end keys, start points, end points): a segment per crossing triangle, inside on its left."""
    t = np.asarray(t, np.int64)
    inside = phi[t] > 0
    count = inside.sum(axis=0)
    t = t[:, (count == 1) | (count == 2)]
    inside = phi[t] > 0
    # the lone vertex: the one whose side differs from the other two
    lone_row = np.where(inside.sum(axis=0) == 1, np.argmax(inside, axis=0), np.argmin(inside, axis=0))
    cols = np.arange(t.shape[1])
    L = t[lone_row, cols]
    o1, o2 = t[(lone_row + 1) % 3, cols], t[(lone_row + 2) % 3, cols]
    n = len(phi)

    def cut(i, j):  # the key of edge i-j, or of the node where phi = 0 exactly (its cuts are one point)
        s = phi[i] / (phi[i] - phi[j])
        edge = np.minimum(i, j) * n + np.maximum(i, j)
        key = np.where(phi[i] == 0, n * n + i, np.where(phi[j] == 0, n * n + j, edge))
        return key, p[:, i] + (p[:, j] - p[:, i]) * s

    k1, P1 = cut(L, o1)
    k2, P2 = cut(L, o2)
    d, e = P2 - P1, p[:, L] - P1
    left = d[0] * e[1] - d[1] * e[0] > 0  # the lone vertex lies left of P1 -> P2
    keep = left == (phi[L] > 0)  # the inside must be on the left: else reverse
    ks, ke = np.where(keep, k1, k2), np.where(keep, k2, k1)
    A, B = np.where(keep, P1, P2), np.where(keep, P2, P1)
    real = ks != ke  # a triangle with two inside vertices at a phi = 0 node: a segment of one point
    return ks[real], ke[real], A[:, real], B[:, real]


def _turning(ks, ke, A, B, axis_r: float) -> float | None:
    """sum 2 pi r theta over the polyline's vertices (module docstring); None if a curve ends off the axis."""
    nxt = {int(a): i for i, a in enumerate(ks)}
    if len(nxt) != len(ks) or len(np.unique(ke)) != len(ke):
        return None  # a key starting (ending) two segments: not a simple curve
    d = B - A
    length = np.hypot(d[0], d[1])
    angle = np.arctan2(d[1], d[0])
    has_prev = np.isin(ks, ke)
    has_next = np.isin(ke, ks)
    if np.any((~has_prev) & (A[0] > axis_r)) or np.any((~has_next) & (B[0] > axis_r)):
        return None  # a curve ends on the wall r = R or z = z0, z1: not a closed surface
    total, seen = 0.0, np.zeros(len(ks), bool)
    starts = list(np.flatnonzero(~has_prev)) + list(range(len(ks)))
    for s in starts:
        if seen[s]:
            continue
        chain, i = [], s
        while i is not None and not seen[i]:
            seen[i] = True
            chain.append(i)
            i = nxt.get(int(ke[i]))
        closed = i == s
        ok = [c for c in chain if length[c] > 0]  # a node with phi = 0 can make a segment of length 0
        if closed:
            ok = ok + ok[:1]
        for a, b in zip(ok[:-1], ok[1:]):
            theta = math.remainder(float(angle[b] - angle[a]), 2 * math.pi)
            total += 2 * math.pi * float(A[0, b]) * theta  # the turn at the start of b (b's start point)
    return total


def zero_level(disc, phi: np.ndarray) -> tuple[float, float, float] | None:
    """(V_0, S_0, int kappa dA) of the surface swept by the phi = 0 meridian of ``disc`` (module
    docstring), or None when phi does not change sign or a curve is not closed."""
    phi = np.asarray(phi, float)
    if not phi.min() < 0 < phi.max():
        return None
    p = np.asarray(disc.mesh.p, float)
    ks, ke, A, B = _oriented_segments(p, disc.mesh.t, phi)
    if not len(ks):
        return None
    kappa = _turning(ks, ke, A, B, AXIS_TOL * float(p[0].max()))
    if kappa is None:
        return None
    (r0, z0), (r1, z1) = A, B
    volume = float(np.sum(math.pi * (z1 - z0) * (r0 * r0 + r0 * r1 + r1 * r1) / 3))
    area = float(np.sum(math.pi * (r0 + r1) * np.hypot(r1 - r0, z1 - z0)))
    kappa += float(2 * math.pi * np.sum(z1 - z0))
    return volume, area, kappa
