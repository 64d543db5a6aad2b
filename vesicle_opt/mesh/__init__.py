"""Spatial discretisations (Definition 2.2 and its FD special case): ``discretize(scene)``.

* ``base``: the shared :class:`Discretization` interface (nodes, weights, K, M, quadrature) and the
  one lumped-only guard ``require_lumped``;
* ``fd``: uniform periodic grids with the (2d+1)-point Laplacian (sparse);
* ``fem``: P1 finite elements on triangles / tetrahedra (scikit-fem);
* ``spectral``: periodic grids whose Laplacian is applied by FFT (pseudo-spectral, or FD by FFT);
* ``cosine``: mirror-symmetric grids (spectral with natural boundaries), Laplacian applied by DCT;
* ``axisymmetric``: P1 on the meridian half-plane with the weight 2 pi r (axisymmetric 3D vesicles).
"""

from __future__ import annotations

from vesicle_opt.mesh import cosine, fd, spectral
from vesicle_opt.mesh.base import Discretization

__all__ = ["Discretization", "discretize"]


def discretize(scene) -> Discretization:
    """Build the discretisation a scene asks for (``mesh.kind``, ``mesh.n``, ``mesh.mass``, ...)."""
    if scene.mesh.kind == "fd":
        return fd.grid(scene.domain.box, scene.mesh.n)
    if scene.mesh.kind == "spectral" and scene.domain.boundary == "natural":
        return cosine.grid(scene.domain.box, scene.mesh.n)  # mirror-symmetric (cosine series)
    if scene.mesh.kind == "spectral":
        return spectral.grid(scene.domain.box, scene.mesh.n)
    if scene.mesh.kind == "axisymmetric":
        from vesicle_opt.mesh import axisymmetric  # scikit-fem: loaded with the first FEM mesh (below)
        return axisymmetric.p1(scene.domain.box, scene.mesh.n, mass=scene.mesh.mass,
                               quadrature=scene.mesh.quadrature)
    # P1 only here: scikit-fem (0.04 s at import) loads with the first FEM mesh, not with the package
    from vesicle_opt.mesh import fem
    return fem.p1(scene.domain.box, scene.mesh.n, periodic=scene.domain.boundary == "periodic",
                  mass=scene.mesh.mass, quadrature=scene.mesh.quadrature, mesh_file=scene.mesh.file)
