"""Spatial discretisations (Definition 2.2 and its FD special case): ``discretize(scene)``.

* ``base``: the shared :class:`Discretization` interface (nodes, weights, K, M, quadrature) and the
  one lumped-only guard ``require_lumped``;
* ``fd``: uniform periodic grids with the (2d+1)-point Laplacian (sparse);
* ``fem``: P1 finite elements on triangles / tetrahedra (scikit-fem);
* ``spectral``: periodic grids whose Laplacian is applied by FFT (pseudo-spectral, or FD by FFT);
* ``cosine``: mirror-symmetric grids (spectral with natural boundaries), Laplacian applied by DCT;
* ``axisymmetric``: P1 on the meridian half-plane with the weight 2 pi r (axisymmetric 3D vesicles);
  ``refine``: its interface-refined graded meshes (``mesh.refine = "interface"``), ``band_start``:
  where their band is built (the start) and rebuilt (a result that left it).
"""

from __future__ import annotations

from vesicle_opt.mesh import cosine, fd, spectral
from vesicle_opt.mesh.base import Discretization

__all__ = ["Discretization", "discretize"]


def discretize(scene, interface=None) -> Discretization:
    """Build the discretisation a scene asks for (``mesh.kind``, ``mesh.n``, ``mesh.mass``, ...).
    ``mesh.refine = "interface"`` refines about ``interface`` (a callable: (N, 2) meridian points ->
    their distance to the interface, e.g. ``refine.curve_distance`` of a sharp meridian), by default
    the scene's ``initial`` shape (its signed distance at (r, 0, z))."""
    if scene.mesh.kind == "fd":
        return fd.grid(scene.domain.box, scene.mesh.n)
    if scene.mesh.kind == "spectral" and scene.domain.boundary == "natural":
        return cosine.grid(scene.domain.box, scene.mesh.n)  # mirror-symmetric (cosine series)
    if scene.mesh.kind == "spectral":
        return spectral.grid(scene.domain.box, scene.mesh.n)
    if scene.mesh.kind == "axisymmetric":
        from vesicle_opt.mesh import axisymmetric  # scikit-fem: loaded with the first FEM mesh (below)
        if scene.mesh.refine == "interface":
            return axisymmetric.band_p1(scene.domain.box, scene.mesh.n, interface or initial_distance(scene),
                                        scene.mesh.band, scene.mesh.levels, scene.model.epsilon,
                                        mass=scene.mesh.mass, quadrature=scene.mesh.quadrature)
        return axisymmetric.p1(scene.domain.box, scene.mesh.n, mass=scene.mesh.mass,
                               quadrature=scene.mesh.quadrature)
    # P1 only here: scikit-fem (0.04 s at import) loads with the first FEM mesh, not with the package
    from vesicle_opt.mesh import fem
    return fem.p1(scene.domain.box, scene.mesh.n, periodic=scene.domain.boundary == "periodic",
                  mass=scene.mesh.mass, quadrature=scene.mesh.quadrature, mesh_file=scene.mesh.file)


def initial_distance(scene):
    """The distance of the meridian points (r, z) to the scene's ``initial`` shape (evaluated at the 3D
    points (r, 0, z), as ``AxisymmetricDiscretization.scene_points``)."""
    import numpy as np

    from vesicle_opt.scene.shapes import signed_distance  # only refined meshes measure the start's distance

    (_, R), (z0, z1) = scene.domain.box
    box3 = ((-R, R), (-R, R), (z0, z1))

    def distance(p):
        p = np.asarray(p, float)
        return np.abs(signed_distance(scene.initial, np.column_stack([p[:, 0], np.zeros(len(p)), p[:, 1]]), box3))
    return distance
