"""Meridian-plane solves of the ``phase_diagram`` study (not a study): the box and interface-refined
mesh about a sharp shape, the tanh seed of that shape on it, and a walk along the reduced volume.

* ``layout``: the box is the sharp meridians' extent plus ``WALL`` eps on every side (natural walls
  attract a vesicle: ``mesh.axisymmetric``), widened to whole coarse cells of side
  h0 = 2^levels h (``mesh.refine = "interface"`` needs square cells), h = eps / eps_over_h the band's
  spacing; ``refine = False``: the uniform mesh of spacing h (the quick run). Along the axis the box
  is centred on the first meridian's volume centroid and reaches ``WALL`` eps beyond the farthest
  point of any meridian from its own centroid (``axial_extent``): the solve's axial pin holds the
  centre of mass of the inside at the box's mid-height (``nlp.reuse.pin_row``), so that is where
  every shape sits. Centred on the extent's middle instead, the sharp stomatocyte at v = 0.62 sat
  2.2-3.3 eps off-centre, 10.1-10.5 eps from the lower wall (a translation saddle at 10 eps);
  up-down symmetric shapes get the box they had (their centroid is their middle), one coarse cell
  taller where its n_z was odd: the refined mesh mirrors about the mid-height only with n_z even
  (``mesh.refine.mirrored_tensor``), and on the odd one an up-down symmetric oblate turned
  asymmetric and the pin held a force (the low oblate at eps 0.025, n_z 13: kkt_not_met from v 0.595).
* ``seed``: the mesh refined about the sharp meridian, moved along the axis to put its volume
  centroid at the box's mid-height where the pin holds it (``mesh.refine.curve_distance``), and on it
  phi = tanh(d / (sqrt2 eps)) (``io.meridian.phase_field_of``): a cold start whose band already sits
  on the interface (the front door keeps a start's own refined mesh while its interface is deep in
  the band: ``mesh.band_start``).
* ``walk``: fixed-v exact solves (IPOPT, second-order checked) at the reduced volumes in order,
  the first from the seed (at most ``SEED_MAX_ITER`` IPOPT iterations), each other warm from the
  previous converged point (its mesh and multipliers; the front door re-meshes when the interface
  leaves the band); a point that fails is a row, the next starts from the last converged one.
"""

from __future__ import annotations

import math
import types
import warnings
from pathlib import Path

import numpy as np

from vesicle_opt.api import solve
from vesicle_opt.io.meridian import phase_field_of
from vesicle_opt.mesh import discretize
from vesicle_opt.mesh.refine import curve_distance
from vesicle_opt.scene import from_dict

WALL = 12.0  # walls this many eps from the sharp shapes (a translation saddle at 10 eps: measured)
LEVELS = 4  # the coarse cells are 2^LEVELS band cells: 4 eps at eps/h = 4 (fewer where the box is small)
BAND = 8.0  # the band's half-width in eps (mesh.band's default: narrower bands perturb the axial slide)
MAX_ITER = 150  # IPOPT iterations a warm point: the full run's converged ones took <= 79 (the oblate's low walk),
# 77 (the stomatocyte's down walk), 41 (prolate near, dv = 0.01; 67 before re-meshed starts kept their
# multipliers), 44 (the stomatocyte's up walk: measured); a point past the fold ran into the default 500
SEED_MAX_ITER = 300  # a walk's first, cold point from a sharp shape: the stomatocyte seed (v 0.62) took 62, 86, 129
# iterations at eps 0.03, 0.025, 0.02 on this layout's box, 178 at 0.02 on the former one (measured)


def centroid(r, z) -> float:
    """The height of the volume centroid of the solid of revolution of a meridian (r, z) (frusta);
    the middle of its extent where it encloses no volume (a segment of the axis: a box's spacer)."""
    r, z = np.asarray(r, float), np.asarray(z, float)
    dv = np.diff(z) * (r[1:] ** 2 + r[1:] * r[:-1] + r[:-1] ** 2) / 3  # frusta: pi dropped in the ratio
    vol = float(np.sum(dv))
    if vol == 0.0:
        return (float(z.max()) + float(z.min())) / 2
    return float(np.sum((z[1:] + z[:-1]) / 2 * dv) / vol)


def axial_extent(meridians) -> tuple[float, float]:
    """(zc, ext): the first meridian's volume centroid, where a box's mid-height goes, and the
    farthest any meridian's point lies along the axis from its own centroid: the pin
    (``nlp.reuse.pin_row``) puts each shape's centroid at the mid-height, so ext + the walls'
    distance is the box's half-height (``layout``; ``_pear.box_of``)."""
    zc = centroid(*meridians[0])
    ext = 0.0
    for r, z in meridians:
        c = centroid(r, z)
        ext = max(ext, float(np.max(z)) - c, c - float(np.min(z)))
    return zc, ext


def layout(meridians, eps: float, eps_over_h: float, refine: bool = True) -> dict:
    """{"box", "n", "h", "mesh"}: the box about the meridians [(r, z), ...] and its mesh keys."""
    h = eps / eps_over_h
    pad = WALL * eps
    r_hi = max(float(r.max()) for r, _ in meridians) + pad
    zc, ext = axial_extent(meridians)
    half = ext + pad
    if not refine:
        n = [max(4, math.ceil(r_hi / h)), max(4, math.ceil(2 * half / h))]
        box = [[0.0, r_hi], [zc - half, zc + half]]
        return {"box": box, "n": n, "h": max(r_hi / n[0], 2 * half / n[1]),
                "mesh": {"kind": "axisymmetric", "n": n}}
    levels = LEVELS
    while levels > 1 and r_hi / (h * 2**levels) < 4:  # mesh.n >= 4 cells a side (small boxes, large eps)
        levels -= 1
    h0 = h * 2**levels
    n = [max(4, math.ceil(r_hi / h0)), 2 * max(2, math.ceil(half / h0))]  # n_z even: ``refine.mirrored_tensor``
    box = [[0.0, n[0] * h0], [zc - n[1] * h0 / 2, zc + n[1] * h0 / 2]]
    return {"box": box, "n": n, "h": h,
            "mesh": {"kind": "axisymmetric", "n": n, "refine": "interface", "levels": levels, "band": BAND}}


def scene(lay: dict, eps: float, v: float, name: str, c0: float = 0.0, max_iter: int = MAX_ITER):
    """The point's scene; ``c0`` in literature units (C0 R0 at R0 = 1: ``model.c0`` = c0 / 2)."""
    model = {"epsilon": eps, "c0": c0 / 2} if c0 else {"epsilon": eps}
    raw = {"domain": {"box": lay["box"], "boundary": "natural"}, "mesh": lay["mesh"], "model": model,
           "constraints": {"reduced_volume": v, "area": 4 * math.pi},
           "initial": {"shape": "sphere", "radius": 1.0}, "solver": {"method": "exact", "max_iter": max_iter}}
    return from_dict(raw, name=name)


def seed(sc, r, z, eps: float, h: float):
    """The tanh profile of the meridian (r, z) on the scene's mesh (refined about that meridian), the
    meridian moved along the axis to put its volume centroid at the box's mid-height (the pin's)."""
    lo, hi = (float(b) for b in sc.domain.box[-1])
    z = np.asarray(z, float) + ((lo + hi) / 2 - centroid(r, z))
    if sc.mesh.refine == "interface":
        disc = discretize(sc, interface=curve_distance(np.column_stack([r, z]), h))
    else:
        disc = discretize(sc)
    return types.SimpleNamespace(disc=disc, phi=phase_field_of(r, z, disc.nodes, eps))


def solve_quiet(sc, start):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # near-bound warnings do not apply; verdicts are recorded
        return solve(sc, x0=start)


def walk(lay: dict, eps: float, vs, first, name: str, stop=None, start=None, states=None, case: str = "",
         max_iter: int = MAX_ITER):
    """Yield (v, Result, seed label) along ``vs``: the first from ``first`` ((r, z) of a sharp shape
    at vs[0]) or from ``start`` (a converged Result at vs[0], label "previous point"), then each
    warm from the last converged point; ``stop(result) -> bool`` ends the walk after a point (e.g. one
    that left its branch's form); ``states``: a directory where each converged point's field is saved
    (``save``, as ``case``: what the h-levels, ``_hlevel``, restart from); ``max_iter``: IPOPT's cap on
    a warm point."""
    label = "sharp shape" if start is None else "previous point"
    for v in vs:
        sc = scene(lay, eps, v, f"{name}-v{v:g}-eps{eps:g}", max_iter=SEED_MAX_ITER if start is None else max_iter)
        if start is None:
            start = seed(sc, *first, eps, lay["h"])
        res = solve_quiet(sc, start)
        if lay["mesh"].get("refine") == "interface":
            save(states, case, v, res, lay)
        yield v, res, label
        if stop is not None and stop(res):
            return
        if res.converged:
            start, label = res, "previous point"


def state_path(states, case: str, v: float) -> Path:
    return Path(states) / f"{case}-v{float(v):g}.npz"


def save(states, case: str, v: float, res, lay: dict) -> None:
    """A converged point's field, mesh and layout in ``states`` (npz; what ``_hlevel.run`` restarts
    from); nothing where ``states`` is None or the point did not converge."""
    if states is None or not res.converged:
        return
    Path(states).mkdir(parents=True, exist_ok=True)
    m = res.disc.mesh
    np.savez_compressed(state_path(states, case, v), p=m.p, t=m.t, phi=np.asarray(res.phi, float),
                        h_fine=res.disc.h_fine, box=np.asarray(lay["box"], float), n=np.asarray(lay["n"]),
                        levels=lay["mesh"]["levels"], band=lay["mesh"]["band"], h=lay["h"])
