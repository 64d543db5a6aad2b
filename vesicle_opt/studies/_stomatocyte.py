"""The stomatocyte cases of the ``phase_diagram`` study (c0 = 0): the sharp branch (eps = 0 rows,
``sharp.stomatocyte``) and the phase-field branch at one eps on the meridian half-plane.

Phase field: the branch is SEEDED (column ``seed``): the first point, at v = ``V_SEED`` (the lower side
of the fold), starts from the tanh profile of the sharp stomatocyte there (``io.meridian.phase_field_of``),
as the prolate and oblate cases start from their sharp shapes. The sharp stomatocyte itself is reached
without a seed, by switching at the sharp oblate's branch point (``sharp.stomatocyte_switch``: v =
0.51044); the phase field has no such route here yet: at the eps this machine affords (>= 0.025) the
meridian oblate's dimples meet (a torus) above v = 0.51 (at v = 0.58 for eps = 0.03, measured), and
one deflation attempt from the meridian "oblate" at eps = 0.05, v = 0.62 started from a state that
was no oblate (f 1.772 against the sharp 1.904) and was stopped after 10 min without a root.
From the seed the branch
package walks (``branch.branch``, IPOPT, exact constraints; near the fold the pseudo-arclength
corrector with p free): up in v past the fold and back along its upper side, and down in v for the
crossing with the oblate. Every point is certified with its second-order verdict (axisymmetric
perturbations only).

The fold of a walk (``fold_of``): the branch's v and f are smooth in the volume multiplier
lambda = df/dv (``dE_dp`` of the branch rows, in any fixed unit), which is monotone through a fold,
while f(v) has a cusp there (df = lambda dv on both sides); the fold is the vertex of the parabola
v(lambda) through the three points around the largest v, f the parabola f(lambda) at that lambda.
"""

from __future__ import annotations

import math
import tempfile
import warnings
from pathlib import Path

import numpy as np

from vesicle_opt.api import solve
from vesicle_opt.branch.run import branch
from vesicle_opt.io import output
from vesicle_opt.io.meridian import phase_field_of
from vesicle_opt.mesh import discretize
from vesicle_opt.scene import from_dict
from vesicle_opt.sharp import stomatocyte as sharp_s

V_SEED = 0.62  # the seed's reduced volume: the lower side, 0.04 below the sharp fold (0.6604)
V_UP, V_DOWN = 0.70, 0.575  # the walks' ends: above the fold (never reached: the walk turns), below the crossing
STEP = 0.01  # the walks' first v step
MAX_POINTS = 26  # per walk: at eps = 0.05 the up walk was still 0.01 below its fold after 14 points (the
# arclength steps shrink near it: dv 4e-4 a step)
WALL = 12.0  # walls this many eps from the seed's sharp shape (as the study's other cases)


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def fold_of(v, f, lam) -> tuple[float, float] | None:
    """(v, f) at the fold of a branch given per point (v, f, lambda = df/dv in any fixed unit), in
    walk order: the parabolas v(lambda), f(lambda) through the largest v and its two neighbours in
    the walk, at the vertex of v(lambda) (module docstring); None without an interior maximum."""
    v, f, lam = (np.asarray(x, float) for x in (v, f, lam))
    k = int(np.argmax(v))
    if not 0 < k < len(v) - 1:
        return None
    sel = slice(k - 1, k + 2)
    cv = np.polyfit(lam[sel], v[sel], 2)
    if cv[0] >= 0:
        return None
    at = -cv[1] / (2 * cv[0])
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


def _scene(box, n, eps: float, v: float, initial: dict, name: str):
    raw = {"domain": {"box": box, "boundary": "natural"}, "mesh": {"kind": "axisymmetric", "n": n},
           "model": {"epsilon": eps}, "constraints": {"reduced_volume": v, "area": 4 * math.pi},
           "initial": initial, "solver": {"method": "exact"}}
    return from_dict(raw, name=name)


def phase_case(case: dict, point_row) -> list[dict]:
    """The phase-field stomatocyte at ``case["epsilon"]``: the seeded point, then the two walks
    (module docstring); ``point_row(res_or_row, v, eps, n, box, sharp_f, seed, side, walk)`` makes a
    study row. The walks' rows keep the branch package's ``corrector`` in ``status`` and get
    ``side`` lower/upper (upper: after the walk's largest v)."""
    eps = case["epsilon"]
    seed_pt = sharp_s.start_point(V_SEED, 0.0, case["n_modes"])
    r, z = seed_pt.meridian(2048)
    pad = WALL * eps
    box = [[0.0, float(r.max()) + pad], [float(z.min()) - pad, float(z.max()) + pad]]
    h = eps / case["eps_over_h"]
    n = [max(4, math.ceil((hi - lo) / h)) for lo, hi in box]
    sc = _scene(box, n, eps, V_SEED, {"shape": "sphere", "radius": 1.0}, f"phase_diagram-stomatocyte-eps{eps:g}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # near-bound warnings do not apply; verdicts are recorded
        res = solve(sc, x0=phase_field_of(r, z, discretize(sc).nodes, eps))
    seed = f"sharp stomatocyte at v = {V_SEED} (a seed)"
    rows = [point_row(res, V_SEED, eps, n, box, seed_pt.f, seed, "lower", "seed")]
    if not res.converged:
        return rows
    with tempfile.TemporaryDirectory() as tmp:
        output.write_result(Path(tmp), sc, res.disc, res)  # phi.npz, the walks' start file
        start = _scene(box, n, eps, V_SEED, {"shape": "file", "file": str(Path(tmp) / "phi.npz")}, sc.name)
        for to in (V_UP, V_DOWN):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                b = branch(start, "reduced_volume", to=to, step=math.copysign(STEP, to - V_SEED), switch=False,
                           depth=0, max_points=MAX_POINTS, snapshots=False)
            walk = [q for q in b.rows if q.get("corrector") not in ("start", "locate")]
            k_max = int(np.argmax([_num(q.get("reduced_volume")) for q in walk])) if walk and to > V_SEED else None
            for i, q in enumerate(walk):
                side = "upper" if k_max is not None and i > k_max and _num(q.get("reduced_volume")) < \
                    _num(walk[k_max].get("reduced_volume")) else "lower"
                rows.append(point_row(q, _num(q.get("target")), eps, n, box, math.nan,
                                      f"branch walk from the seed ({q.get('corrector')})", side,
                                      "up" if to > V_SEED else "down"))
    return rows
