"""P1 finite elements on triangles (2D) and tetrahedra (3D) with scikit-fem (Section 2).

Boxes are tensor meshes (``MeshTri.init_tensor`` / ``MeshTet.init_tensor``); natural (variational)
boundary conditions need nothing; periodic boxes fold the nodes on the upper faces onto the lower
ones with a 0/1 matrix U (K_per = U^T K U, M_per = U^T M U), so periodic FEM nodes are numbered
exactly like the FD grid. Any mesh scikit-fem/meshio can read works with natural conditions.
"""

from __future__ import annotations

import os
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import scipy.sparse as sp
import skfem
from skfem.models.poisson import laplace, mass as mass_form

from vesicle_opt.mesh.base import Discretization
from vesicle_opt.mesh.check import checked
from vesicle_opt.errors import InputError

GAUSS_ORDER = 6  # exact for the degree-6 integrand r^2 of (6) with r cubic in phi
STIFFNESS_ORDER = 1  # P1 gradients are constant per element: a one-point rule is exact (the matrix
# equals the intorder-2 one to max difference 0.0, tests/mesh/test_fem.py)
MASS_ORDER = 2  # phi_i phi_j is quadratic: the lowest exact order for the consistent mass
CHUNK = 1 << 17  # elements per assembly chunk: the COO triplets of a chunk (16 per tetrahedron,
# 24 bytes each) stay ~50 MB, so the peak is the matrices, not the triplets (one asm of the 64^3
# torus held 1.1 GB of triplets and coo->csr copies at once)


def _box_mesh(box, n):
    axes = [np.linspace(a, b, k + 1) for (a, b), k in zip(box, n)]
    return (skfem.MeshTri if len(box) == 2 else skfem.MeshTet).init_tensor(*axes)


def _fold(mesh, box, n) -> sp.csr_matrix:
    """Periodic identification: full mesh node -> periodic dof (C-order grid index mod n)."""
    lo = np.array([a for a, _ in box])
    h = np.array([(b - a) / k for (a, b), k in zip(box, n)])
    ijk = np.rint((mesh.p.T - lo) / h).astype(int) % np.array(n)
    cols = np.ravel_multi_index(ijk.T, n)
    return sp.csr_matrix((np.ones(len(cols)), (np.arange(len(cols)), cols)), shape=(len(cols), int(np.prod(n))))


def gauss_interpolation(basis) -> tuple[sp.csr_matrix, np.ndarray]:
    """Interpolation matrix to all Gauss points (row e*nq + q) and their weights."""
    dofs = basis.element_dofs  # (n_local, n_elem)
    n_elem, nq = basis.dx.shape
    rows = np.arange(n_elem * nq).reshape(n_elem, nq)
    R, C, V = [], [], []
    for i in range(dofs.shape[0]):
        R.append(rows.ravel())
        C.append(np.repeat(dofs[i], nq))
        V.append(basis.basis[i][0].value.ravel())
    P = sp.csr_matrix((np.concatenate(V), (np.concatenate(R), np.concatenate(C))),
                      shape=(n_elem * nq, basis.N))
    return P, basis.dx.ravel().copy()


def _assemble(mesh, elem, form, intorder: int, dofs=None) -> sp.csr_matrix:
    """``skfem.asm(form, Basis(mesh, elem, intorder))`` summed over element chunks of ``CHUNK``:
    the same matrix (a sum over elements in another grouping: equal to round-off), with one chunk's
    Basis and COO triplets alive at a time."""
    n_elem = mesh.t.shape[1]
    out = None
    for start in range(0, n_elem, CHUNK):
        elements = np.arange(start, min(start + CHUNK, n_elem))
        basis = skfem.Basis(mesh, elem, intorder=intorder, elements=elements, dofs=dofs, disable_doflocs=True)
        part = skfem.asm(form, basis).tocsr()
        del basis
        out = part if out is None else out + part
        del part
    return out.tocsr()


def max_edge(mesh) -> float:
    t = mesh.t
    return float(max(np.max(np.linalg.norm(mesh.p[:, t[i]] - mesh.p[:, t[j]], axis=0))
                     for i in range(t.shape[0]) for j in range(i)))


def p1(box, n, periodic: bool, mass: str = "lumped", quadrature: str = "nodal",
       mesh_file: str | None = None) -> Discretization:
    if mesh_file is not None:
        if periodic:
            raise InputError("domain.boundary", "a mesh file supports only 'natural'")
        try:  # meshio raises many types, even SystemExit, and prints, for unreadable files
            with open(os.devnull, "w") as null, redirect_stdout(null), redirect_stderr(null):
                mesh = skfem.Mesh.load(mesh_file)
        except (Exception, SystemExit) as exc:
            why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise InputError("mesh.file", f"cannot read {mesh_file!r} as a mesh ({why})") from None
        if not isinstance(mesh, (skfem.MeshTri1, skfem.MeshTet1)):
            raise InputError("mesh.file", f"need a triangle or tetrahedron mesh, got {type(mesh).__name__}")
        if mesh.p.shape[0] != len(box):
            raise InputError("mesh.file", f"{mesh_file!r} is a {mesh.p.shape[0]}D mesh, the scene is "
                             f"{len(box)}D (domain.box has {len(box)} pairs)")
        mesh = checked(mesh, mesh_file)  # orphans, degenerate, duplicate, non-manifold, pieces (mesh.check)
        lo, hi = mesh.p.min(axis=1), mesh.p.max(axis=1)
        box = tuple((float(a), float(b)) for a, b in zip(lo, hi))
    else:
        mesh = _box_mesh(box, n)
    dim = mesh.p.shape[0]
    elem = skfem.ElementTriP1() if dim == 2 else skfem.ElementTetP1()
    dofs = skfem.assembly.Dofs(mesh, elem)
    K = _assemble(mesh, elem, laplace, STIFFNESS_ORDER, dofs)
    M = _assemble(mesh, elem, mass_form, MASS_ORDER, dofs)
    quad_P = quad_w = None
    if quadrature == "gauss":
        quad_P, quad_w = gauss_interpolation(skfem.Basis(mesh, elem, intorder=GAUSS_ORDER, dofs=dofs))
    del dofs
    nodes = mesh.p.T
    unfold = None
    if periodic:
        unfold = _fold(mesh, box, n)
        K = sp.csr_matrix(unfold.T @ K @ unfold)
        M = sp.csr_matrix(unfold.T @ M @ unfold)
        if quad_P is not None:
            quad_P = sp.csr_matrix(quad_P @ unfold)
        lo = np.array([a for a, _ in box])
        h = np.array([(b - a) / k for (a, b), k in zip(box, n)])
        nodes = lo + h * np.array(np.unravel_index(np.arange(unfold.shape[1]), n)).T
    weights = np.asarray(M.sum(axis=1)).ravel()
    volume = float(weights.sum())
    return Discretization(kind="fem-p1", dim=dim, nodes=np.ascontiguousarray(nodes), weights=weights,
                          K=K, M=M, mass=mass, h=max_edge(mesh), volume=volume, box=tuple(box),
                          quad_P=quad_P, quad_w=quad_w,
                          grid_shape=tuple(n) if periodic else None, mesh=mesh, unfold=unfold)
