"""Interface-refined meridian meshes (``mesh.refine = "interface"``): fine P1 triangles in a band
about the vesicle's interface, coarse ones away from it (Definition 2.2 on a graded mesh).

The energy (6) and the constraints (7), (8) of a tanh profile live in the diffuse interface: beyond a
few eps from phi = 0 the field is +-1 to exp(-sqrt(2) d / eps), so the mesh needs its fine spacing
h_L only in the band |d| <= ``mesh.band`` x eps about the interface of the start shape. The mesh:

* the tensor box of ``mesh.n`` **square** cells (side h_0), each split into two right isosceles
  triangles (``MeshTri.init_tensor``);
* ``mesh.levels`` = L rounds of scikit-fem's conforming red-green-blue refinement
  (``MeshTri.refined(elements)``), each marking the elements within reach of the band (a graded
  band: level k+1 reaches GRADE cells of its own side further than level k+2, so neighbouring
  levels differ by one);
* the refinement splits an element's longest edge first; on a right isosceles triangle that is the
  hypotenuse, and every red, green and blue child of a right isosceles triangle is again right
  isosceles. So every triangle of the mesh has angles 45, 45 and 90 degrees: no angle is obtuse, and
  the weighted stiffness K_ij = -pi sum_T r_T cot(theta_ij^T) (r_T the centroid's radius: the
  integrand 2 pi r grad psi_i . grad psi_j is linear, theta the angle opposite the edge ij) has
  K_ij <= 0 off the diagonal and zero row sums: the M-matrix of the co-volume (Voronoi-Delaunay)
  Laplacian that Definition 2.2's remark refers to, on the graded mesh too (tests check it).

The band is the start's: a solve or a branch whose interface moves away from it leaves the fine
band. :func:`band_margin` measures, for a field, the distance from its phi = 0 curve (the zero
crossings of the P1 interpolant on the mesh's edges) to the nearest vertex of a coarser element, in
units of eps; ``verify.band`` makes a result whose margin is below ``scene.ranges.BAND_MIN`` (3) not
converged (one line naming ``mesh.band``), never a silently less accurate point. :func:`remesh_distance` and
:func:`transfer` build the band about a new interface and interpolate a field onto it
(``mesh.band_start``: the front door re-meshes about a warm start, or a result, that left the band).
"""

from __future__ import annotations

import math

import numpy as np
import skfem

from vesicle_opt.errors import InputError
from vesicle_opt.scene.ranges import check_square

GRADE = 2.0  # each level keeps a ring of at least this many of its cells around the next finer one
MAX_SAMPLES = 4_000_000  # estimate_nodes' distance samples at most (a 32 MB array)
LEG_TOL = 1e-6  # relative: two legs of the same level agree to round-off (sides are h0 / 2^k)


def square_side(box, n) -> float:
    """h_0 of the box's tensor cells, which must be square (module docstring; ``scene.ranges.check_square``)."""
    return check_square(box, n)


def legs(mesh) -> np.ndarray:
    """Per element, the leg of its right isosceles triangle (the shortest edge)."""
    p, t = mesh.p, mesh.t
    e = [np.linalg.norm(p[:, t[a]] - p[:, t[b]], axis=0) for a, b in ((0, 1), (1, 2), (2, 0))]
    return np.minimum(np.minimum(e[0], e[1]), e[2])


def band_mesh(box, n, distance, width: float, levels: int) -> skfem.MeshTri:
    """The graded mesh (module docstring): ``distance`` maps (N, 2) points (r, z) to their unsigned
    distance from the interface (1-Lipschitz), ``width`` is the band's half-width (absolute units),
    ``levels`` the number of halvings from h_0 to the fine spacing."""
    h0 = square_side(box, n)
    mesh = mirrored_tensor(box, n)
    for k in range(levels):
        h_next = h0 / 2 ** (k + 1)
        reach = _reach(width, h0, levels, k)
        d = np.abs(np.asarray(distance(mesh.p.T), float))
        leg = legs(mesh)
        near = d[mesh.t].min(axis=0) - math.sqrt(2.0) * leg <= reach  # some point of T within reach
        marked = np.flatnonzero(near & (leg > h_next * (1 + LEG_TOL)))
        if marked.size == 0:
            break
        mesh = mesh.refined(marked)
    return mesh


def _reach(width: float, h0: float, levels: int, k: int) -> float:
    """How far from the interface :func:`band_mesh`'s round k marks (the graded band's ring)."""
    return width + GRADE * sum(h0 / 2**j for j in range(k + 1, levels))


def estimate_nodes(box, n, distance, width: float, levels: int) -> int:
    """About the nodes of :func:`band_mesh` (same arguments), without building it (the memory guard,
    ``resources``): the tensor box's nodes plus, per round k, the area A_k within that round's reach
    (+ sqrt2 leg_k, its marking test) times the nodes per unit area the halving adds, 3 x 4^k / h0^2
    (a square cell of side h holds one node per h^2). A_k counts the points of a sampling grid of
    spacing h0 / 2 (coarser on boxes past MAX_SAMPLES points) whose distance is within the reach."""
    h0 = square_side(box, n)
    (r0, r1), (z0, z1) = box
    s = max(h0 / 2, math.sqrt((r1 - r0) * (z1 - z0) / MAX_SAMPLES))
    R, Z = np.meshgrid(np.arange(r0 + s / 2, r1, s), np.arange(z0 + s / 2, z1, s), indexing="ij")
    d = np.abs(np.asarray(distance(np.column_stack([R.ravel(), Z.ravel()])), float))
    nodes = (n[0] + 1) * (n[1] + 1)
    for k in range(levels):
        area = np.count_nonzero(d <= _reach(width, h0, levels, k) + math.sqrt(2.0) * h0 / 2**k) * s * s
        nodes += area * 3 * 4**k / h0**2
    return int(math.ceil(nodes))


def mirrored_tensor(box, n) -> skfem.MeshTri:
    """The box's square cells split into right isosceles triangles whose diagonals mirror each other
    about the box's mid-height (z -> z0 + z1 - z): with an even n_z the mesh, and every refinement of
    it about an up-down symmetric interface, is symmetric under that reflection, so an up-down
    symmetric vesicle is exactly stationary along the axial translation (odd) on it."""
    (r0, r1), (z0, z1) = box
    nr, nz = n
    R, Z = np.meshgrid(np.linspace(r0, r1, nr + 1), np.linspace(z0, z1, nz + 1), indexing="ij")
    p = np.vstack([R.ravel(), Z.ravel()])
    i, j = np.meshgrid(np.arange(nr), np.arange(nz), indexing="ij")
    i, j = i.ravel(), j.ravel()
    a, b, c, d = i * (nz + 1) + j, (i + 1) * (nz + 1) + j, i * (nz + 1) + j + 1, (i + 1) * (nz + 1) + j + 1
    upper = 2 * j + 1 >= nz  # cells above the mid-height: diagonal a-d; below: b-c (its mirror image)
    t1 = np.where(upper, [a, b, d], [a, b, c])
    t2 = np.where(upper, [a, d, c], [b, d, c])
    return skfem.MeshTri(p, np.hstack([t1, t2]))


def fine_elements(mesh, h_fine: float) -> np.ndarray:
    """Boolean per element: at the finest level (leg h_fine)."""
    return legs(mesh) <= h_fine * (1 + LEG_TOL)


def zero_crossings(mesh, phi: np.ndarray) -> np.ndarray:
    """The points (M, 2) where the P1 interpolant of ``phi`` vanishes on the mesh's edges (inside
    is phi > 0, as in ``verify.topology``)."""
    i, j = mesh.facets
    a, b = phi[i], phi[j]
    cut = (a > 0) != (b > 0)
    s = a[cut] / (a[cut] - b[cut])
    return (mesh.p[:, i[cut]] + (mesh.p[:, j[cut]] - mesh.p[:, i[cut]]) * s).T


def band_margin(mesh, phi: np.ndarray, h_fine: float, epsilon: float) -> float:
    """min over the vertices of coarser-than-fine elements of their distance to the field's phi = 0
    curve, in units of eps (inf when every element is fine or the field has no interface; 0 when
    the curve crosses a coarse element)."""
    from scipy.spatial import cKDTree  # third-party, lazy

    coarse = ~fine_elements(mesh, h_fine)
    pts = zero_crossings(mesh, np.asarray(phi, float))
    if not coarse.any() or len(pts) == 0:
        return math.inf
    phi_c = np.asarray(phi)[mesh.t[:, coarse]] > 0
    if (phi_c.any(axis=0) & ~phi_c.all(axis=0)).any():
        return 0.0
    verts = np.unique(mesh.t[:, coarse])
    dist, _ = cKDTree(pts).query(mesh.p[:, verts].T)
    return float(dist.min() / epsilon)


def curve_distance(points: np.ndarray, spacing: float):
    """The unsigned distance to a polyline cloud ``points`` (M, 2), densified to ``spacing``: a
    callable for :func:`band_mesh` (accurate to spacing / 2, which the band's GRADE ring covers)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(points, float))
    return lambda p: tree.query(np.asarray(p, float))[0] - spacing / 2


def remesh_distance(mesh, phi: np.ndarray, spacing: float):
    """The distance callable of a field's phi = 0 curve on its mesh (:func:`zero_crossings`, whose
    points are at most one fine edge apart inside the band): what a re-mesh refines about (``mesh.band_start``)."""
    pts = zero_crossings(mesh, np.asarray(phi, float))
    if len(pts) == 0:
        raise InputError("x0", "the field has no interface (phi does not change sign): nothing to "
                         "refine about")
    return curve_distance(pts, spacing)


def transfer(mesh_from, phi: np.ndarray, nodes_to: np.ndarray) -> np.ndarray:
    """The P1 interpolant of ``phi`` (on ``mesh_from``'s triangles) at the points ``nodes_to`` (N, 2)
    (matplotlib's trapezoid-map triangle finder: O(log n) a point, where scikit-fem's ``probes``
    tests every element, 13 s for 3 k points on a 3 k-node mesh, measured)."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation  # third-party, lazy

    tri = Triangulation(mesh_from.p[0], mesh_from.p[1], np.ascontiguousarray(mesh_from.t.T))
    q = np.asarray(nodes_to, float)
    out = LinearTriInterpolator(tri, np.asarray(phi, float))(q[:, 0], q[:, 1])
    if np.ma.is_masked(out):
        raise ValueError(f"transfer: {int(np.ma.count_masked(out))} points outside the mesh")
    return np.asarray(out, float)
