"""Where the band of an interface-refined mesh (``mesh.refine = "interface"``) is built, and when it
is built again: the start of a solve and its re-meshing (``vesicle_opt.solve`` uses both).

* No warm start, or a field / path: the band about the scene's ``initial`` shape (``discretize``).
* A warm start that is a Result on a meridian mesh of the same box: if it is on a refined mesh of
  the scene's own settings and its interface is still deep in that band (margin >= ``REUSE`` eps,
  halfway between ``mesh.band`` and ``scene.ranges.BAND_MIN``), its mesh is reused, and with it
  IPOPT's multipliers (a branch walks on one mesh while its interface moves by less than that);
  otherwise a band about its phi = 0 curve, its field interpolated onto the new mesh, with its physical
  multipliers (lambda_A, lambda_B: mesh-independent), so IPOPT starts warm there too (``nlp.reuse.point``;
  measured on the prolate walk of ``phase_diagram`` at eps 0.025, dv 0.01: the re-meshed points took 33
  IPOPT iterations against 68-69 from the bare field).
* :func:`left_band`: a result that is not certified because its interface left the band
  (``verify.band``), or :func:`held`: one whose axial pin's force failed the KKT test (``nlp.reuse``); the front
  door then re-meshes about it and solves again, at most ``REMESH_ROUNDS`` times, and reports the
  last result whatever it is.
"""

from __future__ import annotations

import math
import types

import numpy as np

from vesicle_opt.result import Status
from vesicle_opt.scene.ranges import BAND_MIN

REMESH_ROUNDS = 3  # re-mesh and solve again at most this often (each round starts at the last field)


def refined(scene) -> bool:
    """Whether the scene asks for an interface-refined meridian mesh."""
    return scene.mesh.kind == "axisymmetric" and scene.mesh.refine == "interface"


def reuse_margin(band: float) -> float:
    """The margin (eps) down to which a warm start's own refined mesh is reused: halfway between the
    band and ``BAND_MIN`` (so a re-used mesh leaves room before the check fails)."""
    return (band + BAND_MIN) / 2


def _same_mesh_settings(scene, disc) -> bool:
    from vesicle_opt.mesh.refine import square_side  # scikit-fem: loaded for refined scenes only

    m = scene.mesh
    h_fine = square_side(scene.domain.box, m.n) / 2**m.levels
    return (disc.band == m.band and math.isclose(disc.h_fine, h_fine, rel_tol=1e-9)
            and disc.mass == m.mass and disc.quadrature == m.quadrature)


def start(scene, x0, remesh: bool = False):
    """(disc, x0) for a refined scene (module docstring); ``remesh``: a band about a warm start's
    interface even where its own mesh could be reused (``held``)."""
    from vesicle_opt.mesh import discretize, refine  # scikit-fem: loaded for refined scenes only

    disc = getattr(x0, "disc", None)
    if disc is None or not getattr(disc, "axisymmetric", False) or not hasattr(x0, "phi") \
            or tuple(map(tuple, disc.box)) != tuple(tuple(map(float, b)) for b in scene.domain.box):
        return discretize(scene), x0
    eps = scene.model.epsilon
    if not remesh and getattr(disc, "band", None) is not None and _same_mesh_settings(scene, disc) \
            and refine.band_margin(disc.mesh, x0.phi, disc.h_fine, eps) >= reuse_margin(scene.mesh.band):
        return disc, x0
    edge = disc.h_fine if getattr(disc, "band", None) is not None else disc.h  # x0's edges at its interface
    phi = centred(disc, x0.phi, edge)
    distance = refine.remesh_distance(disc.mesh, phi, math.sqrt(2.0) * edge)
    new = discretize(scene, interface=distance)
    moved = refine.transfer(disc.mesh, phi, new.nodes)
    lam = (getattr(x0, "lambda_volume", None), getattr(x0, "lambda_area", None))
    if all(v is not None and np.isfinite(v) for v in lam):  # the physical multipliers hold on any mesh
        return new, types.SimpleNamespace(disc=new, phi=moved, x=None, lambda_volume=lam[0], lambda_area=lam[1])
    return new, moved


def axial_centre(disc, phi) -> float:
    """z of the inside's centre of mass, int z (1 + phi) / int (1 + phi): the quantity the solve's
    pin holds at the box's mid-height (``nlp.reuse.pin_row``)."""
    w = np.asarray(disc.weights, float) * (1 + np.asarray(phi, float))
    return float(w @ np.asarray(disc.nodes, float)[:, 1] / w.sum())


def centred(disc, phi, edge: float):
    """phi translated along the axis so that the centre of mass of its inside, int z (1 + phi) /
    int (1 + phi), lies at the box's mid-height, where the solve's pin holds it (``nlp.reuse.pin_row``);
    phi itself where it is there within a hundredth of ``edge``. A start elsewhere would be moved there
    by the pin's linear row in IPOPT's first step, a linear change of phi that blurs the profile
    instead of moving it (measured: an up-down asymmetric pear, c0 = 2.4, v = 0.72, fell to the
    symmetric shape that way); translated first, the band is built about it where it will be solved."""
    from vesicle_opt.mesh import refine  # scikit-fem: loaded for refined scenes only

    phi = np.asarray(phi, float)
    nodes = np.asarray(disc.nodes, float)
    lo, hi = (float(b) for b in disc.box[-1])
    dz = axial_centre(disc, phi) - (lo + hi) / 2
    if abs(dz) <= 0.01 * edge:
        return phi
    q = nodes + [0.0, dz]
    q[:, 1] = np.clip(q[:, 1], lo, hi)  # beyond the wall: the field at the wall (the bulk)
    return refine.transfer(disc.mesh, phi, q)


def left_band(result) -> bool:
    """Not certified only because its interface left the band (``verify.band``)."""
    margin = result.extra.get("band_margin")
    return (margin is not None and margin < BAND_MIN and result.outcome == Status.NOT_CERTIFIED
            and str(result.extra.get("reason", "")).startswith("the interface left the refined band"))


def held(result) -> bool:
    """Not certified because the axial pin (``nlp.reuse``) held a force: the KKT test, which leaves the
    pin's row out, failed on a pinned solve. The pin puts the centre of mass at the box's mid-height,
    the mirror plane of a band built about an up-down symmetric interface there; a band built about
    a start elsewhere is not mirrored about it, and its coarse cells push the vesicle along the axis
    (measured: the eps = 0.1 prolate started 0.37 up, held at the centre on the start's band:
    multiplier 7.9e-3, kkt_dual 7.9e-6). The front door then re-meshes about the result, whose band is
    mirrored where the shape is up-down symmetric, and solves again (multiplier 2e-11, certified).
    Only where the pin's force is what fails the test (``extra["pin_held"]``, ``nlp.reuse.unpinned``:
    with the row's force the residual passes, there 6.2e-11 against kkt_dual 7.9e-6): a pinned
    kkt_not_met with the pin's force negligible (the residual fails with the row too) is not the
    band's asymmetry, and a re-mesh would only solve it again (up to ``REMESH_ROUNDS`` times)."""
    return result.outcome == Status.KKT_NOT_MET and bool(result.extra.get("pin_held", False))
