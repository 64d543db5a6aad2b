"""A mesh read from a file (``mesh.file``) checked before any work (Section 2's P1 spaces need a
conforming simplicial mesh of one connected domain).

Refused, all defects in one ``InputError`` line under ``mesh.file`` with their counts: vertices in
no element (their rows of K and M are zero, so the systems are singular), elements of zero measure
(a degenerate Jacobian: the assembly divides by it), duplicate nodes (two vertices at one point:
the mesh is not conforming there), non-manifold facets (an edge of 3+ triangles, a face of 3+
tetrahedra) and pieces that share no vertex (a disconnected domain). Elements of negative signed
measure pass silently: scikit-fem sorts each element's vertex numbers when it builds the mesh and
assembles with |det J|, so the orientation a file gives is already normalised and changes nothing
computed (tested: a mesh with every other triangle reversed gives the same K and M).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from vesicle_opt.errors import InputError

ZERO_MEASURE = 1e-10  # |det J| below this fraction of the median element's is degenerate (round-off of
# a collapsed simplex is ~1e-16 relative; a strongly graded but valid mesh stays far above 1e-10)
SAME_POINT = 1e-12  # nodes closer than this fraction of the bounding box's diagonal are one point


def signed_measures(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """det J of each simplex (dim! times its signed measure); ``p`` (dim, N), ``t`` (dim + 1, E)."""
    edges = p[:, t[1:]] - p[:, t[0]][:, None, :]  # (dim, dim, E): coordinate, edge, element
    return np.linalg.det(np.moveaxis(edges, -1, 0))


def defects(p: np.ndarray, t: np.ndarray) -> list[str]:
    """The defects of the mesh (module docstring) in words, with their counts."""
    dim, n = p.shape
    out = []
    used = np.zeros(n, bool)
    used[t.ravel()] = True
    if (~used).any():
        out.append(f"{int((~used).sum())} vertices in no element")
    diag = float(np.linalg.norm(np.ptp(p, axis=1))) or 1.0
    keys = np.round(p.T / (SAME_POINT * diag)).astype(np.int64)
    n_unique = len(np.unique(keys, axis=0))
    if n_unique < n:
        out.append(f"{n - n_unique} duplicate nodes (vertices at the same point)")
    det = signed_measures(p, t)
    scale = float(np.median(np.abs(det))) if det.size else 0.0
    zero = np.abs(det) <= ZERO_MEASURE * scale
    if zero.any() or scale == 0.0:
        out.append(f"{int(zero.sum())} elements of zero {'area' if dim == 2 else 'volume'}")
    facets = np.sort(np.concatenate([np.delete(t, k, axis=0).T for k in range(dim + 1)]), axis=1)
    _, counts = np.unique(facets, axis=0, return_counts=True)
    if (counts > 2).any():
        out.append(f"{int((counts > 2).sum())} non-manifold {'edges' if dim == 2 else 'faces'} "
                   f"(shared by more than two elements)")
    rows = np.repeat(np.arange(t.shape[1]), dim + 1)
    incidence = sp.csr_matrix((np.ones(t.size), (rows, t.T.ravel())), shape=(t.shape[1], n))
    pieces, _ = connected_components(incidence.T @ incidence, directed=False)
    pieces -= int((~used).sum())  # an orphan vertex is a piece of its own here; counted above
    if pieces > 1:
        out.append(f"{pieces} disconnected pieces")
    return out


def checked(mesh, path: str):
    """``mesh``, or an InputError (``mesh.file``) naming every defect with its count."""
    found = defects(np.asarray(mesh.p, float), np.asarray(mesh.t))
    if found:
        raise InputError("mesh.file", f"{path!r} is not a usable mesh: {', '.join(found)}; repair it (e.g. "
                         "gmsh, meshio) and retry")
    return mesh
