"""Branch switching at a located branch point, and recognising a branch already known.

At a simple branch point (p*, u*) of a branch of KKT points of (6)-(8) the reduced Hessian has one
zero eigenvalue with eigenvector v (M-normalised, the critical mode of ``branch.events``); the
bifurcating branch leaves u* tangent to (v, 0) at a pitchfork (and to (v, p') at a transcritical
point). Its first point is found with the predictor u* + sigma a v, sigma = +-1 (both directions),
and an amplitude control on a:

* with a corrector whose p is free (``free``, ``branch.bordered``): the point on the hyperplane
  <u - u*, v>_w = sigma a, p an unknown (the amplitude equation of BifurcationKit's and
  pde2path's switching: a sub- or supercritical pitchfork or a transcritical point alike);
* with a fixed-p corrector only: the solve at p* + tau dp and at p* - tau dp (dp: the branch's
  first step), from the predictor; a minimiser started off the parent goes to the new branch on
  the side where it exists and falls back to the parent on the other;

a trial is accepted when it converged, stays within ``max_dp`` in p, and is farther from the parent
branch than a / 4 (it did not fall back); otherwise a halves (free: a failure) or doubles (fixed
p: both sides fell back), at most ``MAX_TRIES`` trials in all.

A candidate's *distance to a branch* is its distance to the polyline of the branch's accepted
points in the arclength metric theta^2 <., .>_w + dp^2 (``branch.arclength``), the candidate's
field first replaced by its image under the problem's symmetry group nearest the segment
(``align``; on periodic grids: translations, the square's rotations and reflections), so that a
mirror image of a known branch is the known branch. A candidate is *known* (``known``) when it is
at least ``KNOWN_RATIO`` times closer to a known branch than to the branch it left.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from vesicle_opt.branch.events import Point

MAX_TRIES = 6
KNOWN_RATIO = 4.0  # a candidate this many times closer to a known branch than to its parent is it


def branch_distance(phi: np.ndarray, p: float, pts: list[Point], align: Callable, weights, theta: float) -> float:
    """The distance of (phi, p) to the polyline of the accepted points ``pts`` in the arclength
    metric theta^2 <., .>_w + dp^2, phi first moved by ``align(phi, ref)`` to its symmetric image
    nearest each segment's start (module docstring)."""
    def norm2(v):
        return float(np.dot(weights, v * v))
    best = math.inf
    for a, b in zip(pts, pts[1:]) if len(pts) > 1 else ((pts[0], pts[0]),) if pts else ():
        q = align(phi, a.phi)
        dphi, dp = b.phi - a.phi, b.p - a.p
        den = theta**2 * norm2(dphi) + dp**2
        t = 0.0 if den == 0 else min(max((theta**2 * float(np.dot(weights, (q - a.phi) * dphi)) + (p - a.p) * dp) / den, 0.0), 1.0)
        best = min(best, math.sqrt(theta**2 * norm2(q - a.phi - t * dphi) + (p - a.p - t * dp) ** 2))
    return best


def known(candidate: Point, parent: list[Point], branches: dict[int, list[Point]], align: Callable, weights,
          theta: float) -> int | None:
    """The id of the known branch the candidate lies on (module docstring), or None."""
    d_parent = branch_distance(candidate.phi, candidate.p, parent, align, weights, theta)
    best = None
    for k, pts in branches.items():
        d = branch_distance(candidate.phi, candidate.p, pts, align, weights, theta)
        if d * KNOWN_RATIO <= d_parent and (best is None or d < best[1]):
            best = (k, d)
    return None if best is None else best[0]


def first_point(bp: Point, mode: np.ndarray, sigma: int, amplitude: float, parent: list[Point],
                align: Callable, weights, theta: float, *, free: Callable | None = None, solve: Callable | None = None,
                dp: float = 0.0, max_dp: float = math.inf) -> tuple[Point | None, str, int]:
    """The first point of the branch leaving ``bp`` along sigma ``mode`` (module docstring):
    (point or None, how, trials). ``free(phi_pred, p_pred, t_phi, t_p, theta)`` and ``solve(p,
    phi0, lam0)`` return a certified Point or None."""
    a, tries = amplitude, 0
    while tries < MAX_TRIES:
        pred = bp.phi + sigma * a * mode
        if free is not None:
            tries += 1
            pt = free(pred, bp.p, mode, 0.0, 1.0)
            if pt is not None and abs(pt.p - bp.p) <= max_dp and \
                    branch_distance(pt.phi, pt.p, parent, align, weights, theta) > theta * a / 4:
                return pt, f"amplitude {a:.3g}, p free", tries
            a /= 2
            continue
        fell_back = True
        for side in (1.0, -1.0):
            tries += 1
            pt = solve(bp.p + side * dp, pred, bp.lam)
            if pt is None:
                fell_back = False
                continue
            if branch_distance(pt.phi, pt.p, parent, align, weights, theta) > theta * a / 4:
                return pt, f"amplitude {a:.3g}, p fixed at p* {'+' if side > 0 else '-'} {abs(dp):.3g}", tries
        a = 2 * a if fell_back else a / 2
    return None, f"no new point in {tries} trials", tries
