"""Where two branches of an energy diagram cross, and that crossing's eps -> 0 limit.

* ``crossing``: the reduced volume and energy at which two branches' reduced energies e(v) are equal
  (e.g. the 3D prolate and oblate vesicles, whose sharp-interface crossing is
  ``sharp.axisymmetric.crossing()``);
* ``extrapolate_crossing``: the crossings of a sequence of interface widths eps extrapolated to
  eps -> 0 (the phase-field energies converge like eps^2: the 2D ``sharp_limit`` study observes
  order 2.03-2.09, the 3D branches 2.0-2.1).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

from vesicle_opt.verify.metrics import richardson, richardson_fixed


def crossing(va, ea, vb, eb) -> dict | None:
    """Where two branches' reduced energies cross: a cubic spline e(v) through each branch's points
    (not-a-knot; error O(dv^4)), the root of their difference on the overlap of the ranges (brentq
    on the first sign change, from the high-v end); None when there is none."""
    va, ea, vb, eb = (np.asarray(x, float) for x in (va, ea, vb, eb))
    if len(va) < 2 or len(vb) < 2:
        return None
    ia, ib = np.argsort(va), np.argsort(vb)
    sa, sb = CubicSpline(va[ia], ea[ia]), CubicSpline(vb[ib], eb[ib])
    lo, hi = max(va.min(), vb.min()), min(va.max(), vb.max())
    if not lo < hi:
        return None
    grid = np.linspace(hi, lo, 201)
    d = sa(grid) - sb(grid)
    k = next((i for i in range(len(grid) - 1) if d[i] == 0 or d[i] * d[i + 1] < 0), None)
    if k is None:
        return None
    vx = float(grid[k]) if d[k] == 0 else float(brentq(lambda v: float(sa(v) - sb(v)), grid[k + 1], grid[k], xtol=1e-14))
    return {"reduced_volume": vx, "reduced_energy": float(sa(vx))}


def extrapolate_crossing(per_eps: dict) -> dict:
    """eps -> 0 of the crossing's v and reduced energy from {eps: crossing}: the free-order
    Richardson fit through the three finest eps (``metrics.richardson``; its order ``order_*``),
    the fixed order p = 2 from the two finest (``*_p2``), and the least-squares line y0 + c eps^2
    through every level with its residual rms (``*_lsq_p2``, ``*_lsq_p2_rms``); nan where too few
    levels."""
    eps = np.array(sorted(per_eps, reverse=True), float)
    out = {"epsilons": [float(e) for e in eps]}
    for key in ("reduced_volume", "reduced_energy"):
        y = np.array([per_eps[e][key] for e in eps])
        out[key + "_richardson"], out["order_" + key] = richardson(eps, y) if len(eps) >= 3 else (math.nan, math.nan)
        out[key + "_p2"] = richardson_fixed(eps, y, 2.0) if len(eps) >= 2 else math.nan
        if len(eps) >= 3:
            c, y0 = np.polyfit(eps**2, y, 1)
            out[key + "_lsq_p2"], out[key + "_lsq_p2_rms"] = float(y0), float(np.std(y - (y0 + c * eps**2)))
    return out
