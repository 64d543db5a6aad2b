"""The meridian curve phi = 0 of an axisymmetric field and the surface it sweeps about the z axis.

On the meridian half-plane (``mesh.axisymmetric``) the P1 field is linear on each triangle, so its
zero level set is a polyline: one segment per triangle whose vertices change sign (inside is
phi > 0, as in ``verify.topology``), its ends on the triangle's edges at the linear interpolant's
zero. Segments sharing an edge are joined into curves (``meridian_curves``): an open curve ends on
the box's boundary (a closed vesicle's meridian runs from the axis r = 0 to the axis), a closed one
(a torus's section) returns to its start. ``revolve`` sweeps the curves about the z axis into a
triangulated surface (a point on the axis becomes one pole vertex, so a vesicle's surface is closed),
whose area and enclosed volume (the divergence-theorem sum, as ``io.surface``) are checked against
the phase-field area and volume (``io.surface.report``): both converge to the sharp interface
(position error O(h^2) of the linear interpolant; the revolved polygon's O(1/n_theta^2)).
``meridian.csv`` (curve, r, z) and ``surface.ply`` are written by ``io.output``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vesicle_opt.io.surface import Surface

N_THETA = 128  # angles of the revolved surface: its area is the polyline's to 1 - sin(x)/x ~ 4e-4


def _segments(mesh, phi: np.ndarray):
    """(edge keys (S, 2), crossing points by key): one segment per triangle crossing phi = 0."""
    t = np.asarray(mesh.t, np.int64)  # the edge keys below reach n^2: int32 wraps above 46341 nodes
    inside = phi[t] > 0
    crossing = inside.any(axis=0) & ~inside.all(axis=0)
    t = t[:, crossing]
    pairs = [(0, 1), (1, 2), (2, 0)]
    n = len(phi)
    keys, points = [], {}
    for a, b in pairs:
        i, j = t[a], t[b]
        cut = (phi[i] > 0) != (phi[j] > 0)
        k = np.minimum(i, j) * n + np.maximum(i, j)
        keys.append(np.where(cut, k, -1))
        ii, jj = i[cut], j[cut]
        s = phi[ii] / (phi[ii] - phi[jj])
        p = mesh.p[:, ii] + (mesh.p[:, jj] - mesh.p[:, ii]) * s
        points.update(zip(k[cut].tolist(), p.T))
    K = np.stack(keys, axis=1)  # per crossing triangle exactly two cut edges
    seg = np.sort(K, axis=1)[:, 1:]
    return seg, points


def meridian_curves(disc, phi: np.ndarray) -> list[np.ndarray]:
    """The zero level set of an axisymmetric field as polylines of (r, z) rows (module docstring);
    open curves first, each from one boundary end to the other; a closed curve repeats its start."""
    seg, points = _segments(disc.mesh, np.asarray(phi, float))
    nbr: dict[int, list[int]] = {}
    for a, b in seg.tolist():
        nbr.setdefault(a, []).append(b)
        nbr.setdefault(b, []).append(a)
    seen: set[int] = set()
    curves = []
    ends = [k for k, v in nbr.items() if len(v) == 1]
    for start in ends + list(nbr):
        if start in seen:
            continue
        chain, prev, cur = [start], None, start
        seen.add(start)
        while True:
            nxt = [k for k in nbr[cur] if k != prev and k not in seen]
            if not nxt:
                if len(chain) > 2 and start in nbr[cur] and prev is not None:
                    chain.append(start)  # a closed curve
                break
            prev, cur = cur, nxt[0]
            seen.add(cur)
            chain.append(cur)
        curves.append(np.array([points[k] for k in chain]))
    return curves


def revolve(curves, n_theta: int = N_THETA) -> Surface | None:
    """The surface swept by the curves about the z axis (module docstring); None without curves."""
    if not curves:
        return None
    theta = 2 * np.pi * np.arange(n_theta) / n_theta
    c, s = np.cos(theta), np.sin(theta)
    verts, faces, count, volumes = [], [], 0, []
    for curve in curves:
        first = len(faces)
        closed = len(curve) > 2 and np.array_equal(curve[0], curve[-1])
        pts = curve[:-1] if closed else curve
        ids = []  # per point: its ring of n_theta vertex ids, or one pole id (r = 0)
        for r, z in pts:
            if r <= 0.0:
                verts.append(np.array([[0.0, 0.0, z]]))
                ids.append(np.full(n_theta, count))
                count += 1
            else:
                verts.append(np.column_stack([r * c, r * s, np.full(n_theta, z)]))
                ids.append(count + np.arange(n_theta))
                count += n_theta
        links = list(zip(range(len(pts) - 1), range(1, len(pts))))
        if closed:
            links.append((len(pts) - 1, 0))
        for a, b in links:
            A, B = ids[a], ids[b]
            A1, B1 = np.roll(A, -1), np.roll(B, -1)
            quad = [np.column_stack([A, B, B1]), np.column_stack([A, B1, A1])]
            for tri in quad:  # drop the triangles a pole collapses
                keep = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
                faces.append(tri[keep])
        volumes.append(faces[first:])
    V = np.concatenate(verts)
    Fc = np.concatenate(faces).astype(np.int64)
    v0, v1, v2 = (V[Fc[:, i]] for i in range(3))
    cross = np.cross(v1 - v0, v2 - v0)
    area = float(0.5 * np.linalg.norm(cross, axis=1).sum())
    ends_on_axis = all(np.array_equal(cv[0], cv[-1]) or (cv[0][0] <= 0.0 and cv[-1][0] <= 0.0) for cv in curves)
    volume = None
    if ends_on_axis:  # every curve bounds a closed surface: the sum of their enclosed volumes
        volume = 0.0
        for part in volumes:
            f = np.concatenate(part) if part else np.zeros((0, 3), np.int64)
            w0, w1, w2 = (V[f[:, i]] for i in range(3))
            volume += float(abs(np.einsum("ij,ij->i", w0, np.cross(w1, w2)).sum()) / 6.0)
    return Surface(V, Fc, area, volume)


def write_meridian(path: Path, curves) -> None:
    """``meridian.csv``: one row per point, columns curve, r, z (curves in ``meridian_curves``' order)."""
    rows = ["curve,r,z"]
    for i, curve in enumerate(curves):
        rows.extend(f"{i},{r:.17g},{z:.17g}" for r, z in curve)
    Path(path).write_text("\n".join(rows) + "\n")


def phase_field_of(r, z, nodes: np.ndarray, epsilon: float) -> np.ndarray:
    """phi = tanh(d / (sqrt(2) eps)) on meridian ``nodes`` (r, z) of the closed curve through (r, z)
    (a meridian from the axis to the axis, e.g. a sharp reference's), d the distance to the polyline
    (to its vertices: pass a fine one), positive inside: the start the study ``phase_diagram`` seeds
    its branches with (the inside test is the even-odd rule for rays in +r, which never meet the closing segment on
    the axis)."""
    from scipy.spatial import cKDTree  # third-party, lazy: only seeds need it

    pr, pz = np.asarray(r, float), np.asarray(z, float)  # the closing segment on the axis is never right of a node
    x, y = nodes[:, 0], nodes[:, 1]
    inside = np.zeros(len(nodes), bool)
    for k in range(len(pr) - 1):  # even-odd rule: a ray in +r from each node crosses the edge k?
        r0, z0, r1, z1 = pr[k], pz[k], pr[k + 1], pz[k + 1]
        if z0 == z1:
            continue
        between = (y >= min(z0, z1)) & (y < max(z0, z1))
        r_cross = r0 + (y - z0) * (r1 - r0) / (z1 - z0)
        inside ^= between & (x < r_cross)
    dist, _ = cKDTree(np.column_stack([r, z])).query(nodes)
    return np.tanh(np.where(inside, dist, -dist) / (np.sqrt(2.0) * epsilon))
