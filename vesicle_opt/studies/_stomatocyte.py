"""The stomatocyte cases of the ``phase_diagram`` study (c0 = 0): the sharp branch (eps = 0 rows,
``sharp.stomatocyte``) and the phase-field branch at one eps on the meridian half-plane.

Phase field: the branch is SEEDED (column ``seed``): the first point of each walk, at v = ``V_SEED``
(the lower side of the fold), starts from the tanh profile of the sharp stomatocyte there
(``io.meridian.phase_field_of``, on a mesh refined about it: ``studies._meridian``), as the prolate
and oblate cases start from their sharp shapes. The sharp stomatocyte itself is reached without a
seed, by switching at the sharp oblate's branch point (``sharp.stomatocyte_switch``: v = 0.51044);
the phase field has no such route here yet: at the eps this machine affords (>= 0.025) the meridian
oblate's dimples meet (a torus) above v = 0.51 (at v = 0.58 for eps = 0.03, measured).
From the seed two walks at fixed v (``_meridian.walk``: exact IPOPT solves, each warm from the
previous point, second-order checked, axisymmetric perturbations only): ``up`` towards the fold on
the v grid ``up`` (its steps shrinking towards the sharp fold, 0.6604), ending at the first point
that does not converge or is no cup (past the phase field's fold there is no stomatocyte at that
v); ``down`` below the crossing with the oblate. Fixed-v minimisers stay on the fold's lower
(stable) side: the branch package's pseudo-arclength walk (p free) had stalled below the fold
(steps shrinking to dv 4e-4; at v 0.645/0.638/0.637 after 26 points at eps 0.04/0.03/0.025), so the
fold is located from the lower side (``fold_of``). Every row carries the sharp lower side at its v
(``sharp_f``: Newton at 24 modes from the previous sharp point).

The fold of a walk (``fold_of``): the branch's v and f are smooth in the volume multiplier
lambda = df/dv (``lambda_volume`` of the solves, any fixed unit), which is monotone through a fold,
while f(v) has a cusp there; near it v = v* - a (lambda - lambda*)^2. With points on both sides the
fold is the vertex of the parabola v(lambda) through the three around the largest v; with the lower
side only, the vertex of the parabola through its three points nearest the fold (an extrapolation
in lambda of at most ``AHEAD`` times the last lambda step), f the parabola f(lambda) there.
"""

from __future__ import annotations

import math

import numpy as np

from vesicle_opt.sharp import stomatocyte as sharp_s
from vesicle_opt.studies._meridian import layout, walk

V_SEED = 0.62  # the seed's reduced volume: the lower side, 0.04 below the sharp fold (0.6604)
V_DOWN = 0.575  # the sharp reference's lower end: below the crossing with the oblate (0.5903)
AHEAD = 3.0  # a lower-side fold is extrapolated in lambda by at most this many of its last lambda steps
SHARP_MODES = 24  # the sharp lower side at each phase-field point (fold 0.660376 at 24 modes, 0.660850 at 48)


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def fold_of(v, f, lam) -> tuple[float, float] | None:
    """(v, f) at the fold of a branch given per point (v, f, lambda = df/dv in any fixed unit), in
    walk order (module docstring): the vertex of the parabola v(lambda) through the largest v and its
    two neighbours when the walk turned; else, on a walk that ends at its largest v (the lower side
    only), through its last three points, if the vertex lies ahead of the last lambda by at most
    ``AHEAD`` lambda steps; None otherwise."""
    v, f, lam = (np.asarray(x, float) for x in (v, f, lam))
    k = int(np.argmax(v))
    if len(v) < 3 or k == 0:
        return None
    sel = slice(k - 1, k + 2) if k < len(v) - 1 else slice(k - 2, k + 1)
    cv = np.polyfit(lam[sel], v[sel], 2)
    if cv[0] >= 0:
        return None
    at = -cv[1] / (2 * cv[0])
    if k == len(v) - 1:  # lower side only: the vertex must lie ahead, and not far
        dl = lam[k] - lam[k - 1]
        if not (0 <= (at - lam[k]) / dl <= AHEAD):
            return None
    return float(np.polyval(cv, at)), float(np.polyval(np.polyfit(lam[sel], f[sel], 2), at))


def sharp_case(case: dict) -> list[dict]:
    """The sharp stomatocyte branch (``sharp.stomatocyte.reference``): eps = 0 rows, its fold and
    its crossing with the oblate as rows of kind ``fold`` / ``crossing``."""
    ref = sharp_s.reference(0.0, case["n_modes"], ds=case.get("ds", 0.05), v_low=V_DOWN)
    base = {"branch": "stomatocyte", "shape": "cup", "c0": 0.0, "epsilon": 0.0, "n": str(case["n_modes"]),
            "converged": True, "seed": "three-arc cup (sharp.stomatocyte.cup_start)", "status": "ok"}
    rows = []
    for side in ("lower", "upper"):
        for v, f in ref[side]:
            rows.append({**base, "kind": "point", "side": side, "target_v": v, "reduced_volume": v, "f": f,
                         "sharp_f": f})
    for kind in ("fold", "crossing"):
        v, f = ref[kind]
        rows.append({**base, "kind": kind, "side": "", "target_v": v, "reduced_volume": v, "f": f, "sharp_f": f})
    return rows


def phase_case(case: dict, point_row) -> list[dict]:
    """The phase-field stomatocyte at ``case["epsilon"]``, the walk ``case["walk"]`` (up / down) over
    ``case["vs"]`` from the seed at vs[0] = ``V_SEED`` (module docstring); ``point_row(res, v, eps,
    lay, sharp_f, seed, side, walk)`` makes a study row (side "lower": fixed-v minimisers)."""
    eps, name = case["epsilon"], f"phase_diagram-stomatocyte-{case['walk']}"
    seed_pt = sharp_s.start_point(case["vs"][0], 0.0, case["n_modes"])
    r, z = seed_pt.meridian(2048)
    lay = layout([(r, z)], eps, case["eps_over_h"], case.get("refine", True))
    sharp_pts = {case["vs"][0]: seed_pt}
    rows = []

    def stop(res) -> bool:  # past the fold (no minimiser), or no stomatocyte any more (a torus, an oblate)
        return not res.converged or point_row(res, math.nan, eps, lay, math.nan, "", "", "")["shape"] != "cup"

    for v, res, label in walk(lay, eps, case["vs"], (r, z), name, stop, case.get("states"), case["case"]):
        q = sharp_pts.get(v)
        if q is None:
            try:
                q = sharp_s.newton(list(sharp_pts.values())[-1].a, v, 0.0, case["n_modes"])
                sharp_pts[v] = q
            except (sharp_s.NotConverged, np.linalg.LinAlgError):
                q = None  # past the sharp fold: no lower-side point
        seed = f"sharp stomatocyte at v = {case['vs'][0]} (a seed)" if label == "sharp shape" else label
        rows.append(point_row(res, v, eps, lay, q.f if q is not None else math.nan, seed, "lower", case["walk"]))
    return rows
