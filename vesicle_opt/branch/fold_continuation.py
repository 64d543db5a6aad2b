"""A fold (limit of stability) continued in a second parameter q: the turning point p_f(q) of a
branch, re-located at each q from warm fixed-p solves on its stable side (a continuation, where
``branch.lines.sweep`` builds a whole diagram per q).

At a generic fold the least eigenvalue mu of the reduced Hessian at fixed p (the check of the
certificate, ``second_order_min_eigenvalue``) vanishes like sqrt|p - p_f|: mu^2 is smooth and
linear in p to first order, mu^2 = k (p - p_f) + O((p - p_f)^2). ``local_fold`` solves the branch
at p_k = p_pred + s k dp, k = 1, 2, 3 (s = +1 when the branch exists above the fold, -1 below), from
the farthest to the nearest, each warm from the last; the quadratic through (p_k, mu_k^2) has its
root nearest p_1 at p_f (error O(dp^3)). The energy there: E = E_f + c2 t^2 + c3 t^3 in
t = sqrt|p - p_f| (the branch's expansion about a fold) through the three samples. A sample that
fails or is not a minimum (mu <= 0: the prediction overshot the fold) shifts the samples 1, 2, 4,
... dp away (up to ``EXTEND`` times); a fold found more than 2 dp beyond p_1 is located again from
samples next to it (``RECENTRE``). The next q's prediction: the secant through the last two folds
(the last fold with one). Every sample is a certified point; the fold itself is not one (the
Hessian is singular there): ``nearest`` is the certified sample next to it.

``solver.solve(x, p, q, phi0, lam0) -> branch.transition.Sample`` (x ignored; the Sample's
``row["second_order_min_eigenvalue"]``), as ``branch.transition``'s.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from vesicle_opt.branch.transition import Sample

EXTEND = 5  # shifts of the samples, doubling: up to 16 dp beyond the prediction
RECENTRE = 2


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
            s = solver.solve("a", p, q, None if src is None else src.phi, None if src is None else src.lam)
            solves += 1
            if not s.converged or _mu(s) is None or _mu(s) <= 0:
                why = f"at p = {p:.8g}: " + ("not certified" if not s.converged else "not a minimum (mu <= 0)")
                break
            pts.append(s)
            src = s
        if why is None:
            break
        shift = 2 * shift or 1  # overshot the fold (or failed next to it): 1, 2, 4, ... dp back, warm from the last good
    else:
        return Fold(q, None, None, p_pred, src, solves, time.perf_counter() - t0, f"no minimum next to the fold {why}")
    p = np.array([s.p for s in pts])
    m2 = np.array([_mu(s) ** 2 for s in pts])
    c = np.polyfit(p - p[-1], m2, 2)
    roots = [r.real for r in np.roots(c) if abs(r.imag) < 1e-12] if abs(c[0]) > 1e-300 else [-c[2] / c[1]]
    roots = [r for r in roots if r * side <= 0]  # beyond the nearest sample, towards the fold
    if not roots:
        return Fold(q, None, None, p_pred, pts[-1], solves, time.perf_counter() - t0,
                    "mu^2 does not reach zero beyond the samples (no fold there)")
    p_f = p[-1] + max(roots, key=lambda r: r * side)  # the root nearest the samples
    t = np.sqrt(np.abs(p - p_f))
    A = np.column_stack([np.ones(3), t**2, t**3])
    e_f = float(np.linalg.solve(A, [s.energy for s in pts])[0])
    return Fold(q, float(p_f), e_f, p_pred, pts[-1], solves, time.perf_counter() - t0)


def fold_line(solver, q0: float, p0: float, values, dp: float, side: float, warm: Sample | None = None,
              progress=None) -> list[Fold]:
    """The fold at q0 (from ``p0``) and at each q of ``values`` outward from q0 (up, then down), each
    predicted by the secant of its direction and warm from the previous fold's nearest sample; a
    failure ends its direction."""
    from vesicle_opt.branch.transition import plan  # the same order as a transition line
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
