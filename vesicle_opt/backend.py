"""``solver.backend``: which engine solves a scene ("ipopt" | "newton-krylov" | "auto").

* ``ipopt``: the exact-Hessian CasADi/IPOPT NLP (``nlp.build_nlp`` + ``solve.solve``); 2D and small 3D.
  A ``spectral`` mesh has a dense Laplacian, so it is refused here (InputError).
* ``newton-krylov``: the matrix-free backend (``newton_krylov.solve``); needs lumped mass and nodal
  quadrature (InputError otherwise).
* ``auto``: newton-krylov for spectral meshes and for 3D lumped/nodal meshes above ``AUTO_3D_NODES``
  (the sparse factorisation of the bi-Laplacian fills in beyond that: ~24 s per IPOPT iteration
  at 32^3 was measured), IPOPT otherwise.
"""

from __future__ import annotations

import math

from .errors import InputError

AUTO_3D_NODES = 20**3


def _nk_capable(scene) -> bool:
    return scene.mesh.mass == "lumped" and scene.mesh.quadrature == "nodal"


def choose_backend(scene) -> str:
    """The backend a scene runs on, validated (see the module docstring)."""
    b = scene.solver.backend
    spectral = scene.mesh.kind == "spectral"
    if b == "auto":
        n_nodes = math.prod(scene.mesh.n)
        if spectral or (scene.dim == 3 and n_nodes > AUTO_3D_NODES and _nk_capable(scene)):
            return "newton-krylov"
        return "ipopt"
    if b == "ipopt" and spectral:
        raise InputError("solver.backend", "mesh.kind 'spectral' needs 'newton-krylov' or 'auto' "
                         "(its Laplacian is dense; IPOPT is for fem-p1 and fd)")
    if b == "newton-krylov" and not _nk_capable(scene):
        raise InputError("solver.backend", "'newton-krylov' needs mesh.mass = 'lumped' and "
                         "mesh.quadrature = 'nodal'; use 'ipopt' for consistent mass or Gauss quadrature")
    return b
