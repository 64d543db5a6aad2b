"""The fixed-parameter corrector of a branch on an interface-refined meridian mesh
(``mesh.refine = "interface"``): the band follows the point, not the scene's ``initial``.

``branch.corrector.IpoptCorrector`` builds one mesh, ``discretize(scene)``, and one NLP on it. On a
refined scene that mesh is fine only within ``mesh.band`` x eps of the *start's* interface, so a
walk whose interface moves (along the line D(c0), c0 = -0.5 to 0.5, the sharp prolate's poles move
by ~0.7 R0: half-length 1.77 at v = 0.746, 2.48 at v = 0.564) leaves the band and every later point
fails the band check (``verify.band``).
Here every point is the front door's solve (``vesicle_opt.solve``) of the point's scene from the
warm start (its field *on its own mesh*, the predicted multipliers):

* ``mesh.band_start.start``: the warm start's mesh is kept while its interface is at least
  ``reuse_margin`` eps from the coarse cells (one graph and IPOPT solver per mesh, ``nlp.reuse``,
  warm with the predicted multipliers), else a band about its phi = 0 curve is built and the field
  interpolated onto it;
* the solve's own re-mesh when the result left the band (``band_start.left_band``), the axial pin
  (``nlp.reuse``) and the second-order check with the pin in its tangent space, as every front-door
  solve on a refined mesh.

So each point lives on its own mesh: ``Result.disc``, which the caller keeps with the field (the
transition line's ``Sample.disc``). The start (no warm field) is a ladder in eps (``ladder``):
the scene at eps 2^k, with k fewer halvings of the band's cells (the same eps / h and band in
units of eps), cold from ``initial``, then each finer rung from the last one's result. A cold start
at the scene's eps from an ellipsoid moves its interface by more than the band (measured: eps =
0.025, band 6 eps, prolate v = 0.66 from semi-axes (0.7, 0.7, 1.6): margin 0, not converged after
168 IPOPT iterations); a rung moves it by O(eps) only.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from vesicle_opt.api import solve
from vesicle_opt.mesh import band_start
from vesicle_opt.mesh import discretize
from vesicle_opt.result import Result
from vesicle_opt.scene.schema import Scene


RUNGS = 2  # eps 2 eps_scene, then eps_scene: a coarser first rung smears a thin oblate into another state
# (measured: eps = 0.1 from semi-axes (1.3, 1.3, 0.5) at v = 0.66 went prolate)


@dataclasses.dataclass(frozen=True)
class Warm:
    """A warm start for the front door on a refined mesh: a field on its mesh and the predicted
    physical multipliers (``mesh.band_start`` and ``nlp.reuse`` read disc, phi, x, lambda_*)."""

    disc: object
    phi: np.ndarray
    lambda_volume: float | None = None
    lambda_area: float | None = None
    x: np.ndarray | None = None


def ladder(scene: Scene) -> list[Scene]:
    """The start's rungs (module docstring): the scene at eps 2^k with ``mesh.levels`` - k, k from
    ``min(levels, RUNGS) - 1`` down to 0 (the last rung is the scene itself)."""
    m, eps = scene.mesh, scene.model.epsilon
    return [scene.replace(mesh=dataclasses.replace(m, levels=m.levels - k),
                          model=dataclasses.replace(scene.model, epsilon=eps * 2**k))
            for k in range(min(m.levels, RUNGS) - 1, -1, -1)]


def seeded(scene: Scene, r, z) -> tuple[object, np.ndarray]:
    """(mesh, field) of a start from a meridian curve (r, z) from the axis to the axis (e.g. a sharp
    reference's, ``sharp.axisymmetric``): the scene's band about that curve and the tanh profile of
    its distance (``io.meridian.phase_field_of``)."""
    from vesicle_opt.io.meridian import phase_field_of  # scipy's KD-tree: seeds only
    from vesicle_opt.mesh.refine import curve_distance, square_side  # scikit-fem: refined meshes only

    pts = np.column_stack([np.asarray(r, float), np.asarray(z, float)])
    spacing = square_side(scene.domain.box, scene.mesh.n) / 2**scene.mesh.levels
    disc = discretize(scene, interface=curve_distance(pts, spacing))
    return disc, phase_field_of(pts[:, 0], pts[:, 1], disc.nodes, scene.model.epsilon)


class RefinedCorrector:
    """The certified point of a refined scene from a warm field on its own mesh (module docstring).
    ``disc``: the band about the scene's ``initial`` (the line's default mesh for records)."""

    def __init__(self, scene: Scene, options=None):
        if not band_start.refined(scene):
            raise ValueError("RefinedCorrector needs mesh.kind 'axisymmetric' with mesh.refine 'interface'")
        self.scene = scene.replace(solver=dataclasses.replace(scene.solver, method="exact"))
        self.options = options
        self.disc = discretize(self.scene)

    def start(self, scene: Scene) -> Result:
        """The point of ``scene`` with no warm field: up the ``ladder`` from ``initial``; the last
        rung's result (failed rungs go on: the last one reports)."""
        scene = scene.replace(solver=dataclasses.replace(scene.solver, method="exact"))
        res = None
        for rung in ladder(scene):
            res = solve(rung, x0=res if res is not None and res.phi is not None else None, options=self.options)
        return res

    def solve(self, scene: Scene, phi0: np.ndarray, lam0: tuple[float, float] | None = None,
              disc0=None, options=None) -> Result:
        """The certified, second-order checked point of ``scene`` (a point of the branch: other
        constraints or c0) from ``phi0`` on ``disc0`` (None: this corrector's ``disc``) with the
        multipliers ``lam0`` (physical; None: IPOPT's own estimate, as a cold start). Infeasible
        targets raise InputError before any solve (the front door's check). ``options``: IPOPT's
        for this solve (None: the corrector's)."""
        scene = scene.replace(solver=dataclasses.replace(scene.solver, method="exact"))
        disc = self.disc if disc0 is None else disc0
        phi0 = np.asarray(phi0, float)
        if phi0.size != disc.n_nodes:
            raise ValueError(f"the warm field has {phi0.size} values, its mesh {disc.n_nodes} nodes")
        lam = (None, None) if lam0 is None else tuple(float(v) for v in lam0)
        return solve(scene, x0=Warm(disc, phi0, *lam), options=options or self.options)
