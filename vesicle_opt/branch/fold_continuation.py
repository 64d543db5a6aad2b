"""A fold (limit of stability) continued in a second parameter q: the turning point p_f(q) of a
branch, re-located at each q from warm fixed-p solves on its stable side (a continuation, where
``branch.lines.sweep`` builds a whole diagram per q).

At a fold the branch turns in p: along it p is a smooth function of a coordinate with a vertex at
the fold. The coordinate used is the envelope derivative g = dE/dp (``branch.params``: lambda_V
dalpha/dp + dE/dp|_phi, smooth through the fold and monotone along a generic one), so
p = p_f + k (g - g_f)^2 + O((g - g_f)^3). ``local_fold`` solves the branch at p_k = p_pred + s k dp,
k = 3, 2, 1 (s = +1 when the branch exists above the fold, -1 below), from the farthest to the
nearest, each warm from the last, and takes the vertex of the parabola p(g) through the three:
p_f (error O(dp^(3/2)) from the cubic term) and, integrating dE = g dp = g p'(g) dg along it, the
energy E_f. Cross-check (``p_mu``): at a generic fold the least eigenvalue mu of the reduced
Hessian (``second_order_min_eigenvalue``) vanishes like sqrt|p - p_f|, so mu^2 linear through the
samples vanishes near p_f; it does not where the critical mode is not the turn's (a symmetric
turning point whose eigenvalue touches zero on both sheets: there dE/dp is even along the branch
too, and ``branch.symmetric_fold`` continues the turn in its symmetric subspace). A sample that fails or is not a
minimum (mu <= 0: the prediction overshot the fold) shifts the samples 1, 2, 4, ... dp away (up to
``EXTEND`` times); a fold found more than 2 dp beyond p_1 is located again from samples next to it
(``RECENTRE``). The next q's prediction: the secant through the last two folds (the last fold with
one). Every sample is a certified point; the fold itself is not one (the
Hessian is singular there): ``nearest`` is the certified sample next to it.

``solver.solve(x, p, q, phi0, lam0) -> branch.transition.Sample`` (x ignored; the Sample's
``row["second_order_min_eigenvalue"]``), as ``branch.transition``'s.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from vesicle_opt.branch.transition import Sample, plan, solve_from

EXTEND = 5  # shifts of the samples, doubling: up to 16 dp beyond the prediction
RECENTRE = 2
REACH = 16  # a vertex farther than this many dp beyond the nearest sample is not taken for a fold


@dataclasses.dataclass
class Fold:
    q: float
    p: float | None
    energy: float | None
    predicted: float
    nearest: Sample | None
    samples: int
    wall: float
    reason: str | None = None
    dE_dp: float | None = None  # at the fold (the parabola's vertex)
    p_mu: float | None = None  # the cross-check: where mu^2, linear through the samples, vanishes

    @property
    def converged(self) -> bool:
        return self.reason is None


def _mu(s: Sample) -> float | None:
    mu = s.row.get("second_order_min_eigenvalue")
    return None if mu is None or not math.isfinite(mu) else float(mu)


def local_fold(solver, q: float, p_pred: float, dp: float, warm: Sample | None, side: float) -> Fold:
    """The fold at q near ``p_pred`` (module docstring); ``side`` +1: the branch exists for p above
    the fold, -1 below; ``warm``: the previous fold's nearest sample (None: cold)."""
    t0, dp, side = time.perf_counter(), abs(dp), math.copysign(1.0, side)
    src, solves, shift = warm, 0, 0
    for _ in range(EXTEND + 1):
        pts, why = [], None
        for k in (3 + shift, 2 + shift, 1 + shift):
            p = p_pred + side * k * dp
            s = solve_from(solver, "a", p, q, src, None if src is None else src.lam)
            solves += 1
            if not s.converged or _mu(s) is None or _mu(s) <= 0:
                why = f"at p = {p:.8g}: " + ("not certified" if not s.converged else "not a minimum (mu <= 0)")
                break
            pts.append(s)
            src = s
        if why is None:
            break
        shift = 2 * shift or 1  # overshot the fold (or failed next to it): 1, 2, 4, ... dp back, warm
        # from the last good sample
    else:
        return Fold(q, None, None, p_pred, src, solves, time.perf_counter() - t0, f"no minimum next to the fold {why}")
    p = np.array([s.p for s in pts])
    g = np.array([np.nan if s.dE_dp is None else s.dE_dp for s in pts], float)
    if not np.all(np.isfinite(g)) or np.ptp(g) == 0:
        return Fold(q, None, None, p_pred, pts[-1], solves, time.perf_counter() - t0,
                    "no envelope derivative dE/dp at the samples (the fold's coordinate)")
    a, b, c = np.polyfit(g, p, 2)
    if a * side <= 0:  # the parabola opens away from the branch: no turn on this side
        return Fold(q, None, None, p_pred, pts[-1], solves, time.perf_counter() - t0,
                    "p(dE/dp) does not turn towards the samples (no fold there)")
    g_f = -b / (2 * a)
    p_f = c - b * b / (4 * a)
    if not (side * (p_f - p[-1]) <= 0 and abs(p_f - p[-1]) <= REACH * dp):  # a flat parabola's far vertex
        return Fold(q, None, None, p_pred, pts[-1], solves, time.perf_counter() - t0,
                    f"p(dE/dp) has no vertex within {REACH} dp beyond the samples (no fold there)")
    prim = lambda t: 2 * a / 3 * t**3 + b / 2 * t**2  # noqa: E731  (E = int g dp = int g p'(g) dg)
    e_f = float(np.mean([s.energy + prim(g_f) - prim(gk) for s, gk in zip(pts, g)]))
    mu2 = np.polyfit(p - p[-1], [_mu(s) ** 2 for s in pts], 1)  # the cross-check: mu^2 linear in p
    p_mu = float(p[-1] - mu2[1] / mu2[0]) if mu2[0] != 0 else math.nan
    return Fold(q, float(p_f), e_f, p_pred, pts[-1], solves, time.perf_counter() - t0, None, float(g_f), p_mu)


def fold_line(solver, q0: float, p0: float, values, dp: float, side: float, warm: Sample | None = None,
              progress=None) -> list[Fold]:
    """The fold at q0 (from ``p0``) and at each q of ``values`` outward from q0 (up, then down), each
    predicted by the secant of its direction and warm from the previous fold's nearest sample; a
    failure ends its direction."""
    out: list[Fold] = []
    hist: dict[str, list[Fold]] = {}
    for direction, q in plan(q0, values):
        past = hist.get("start", []) + (hist.get(direction, []) if direction != "start" else [])
        if direction != "start" and (not past or not past[-1].converged):
            continue
        if direction == "start":
            pred, w = p0, warm
        elif len(past) >= 2:
            a, b = past[-2], past[-1]
            pred, w = b.p + (q - b.q) * (b.p - a.p) / (b.q - a.q), b.nearest
        else:
            pred, w = past[-1].p, past[-1].nearest
        f = local_fold(solver, q, pred, dp, w, side)
        for _ in range(RECENTRE):  # the fold far beyond the nearest sample: samples next to it
            if not f.converged or abs(f.p - f.nearest.p) <= 2 * dp:
                break
            g = local_fold(solver, q, f.p, dp, f.nearest, side)
            f = dataclasses.replace(g, predicted=f.predicted, samples=f.samples + g.samples, wall=f.wall + g.wall)
        hist.setdefault(direction, []).append(f)
        out.append(f)
        if progress is not None:
            progress(f)
    return out
