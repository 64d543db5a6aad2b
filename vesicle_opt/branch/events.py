"""Stability changes along a branch: detected, located and classified (fold or branch point).

Every point of a branch carries the least few eigenvalues mu_1 <= mu_2 <= ... of the reduced
Hessian (the Hessian of the Lagrangian of (6)-(8) on the tangent space of the constraints (7), (8),
symmetry modes excluded as the second-order check decides, ``verify.verdict``), in mu_ref units, and
their error bounds. Two counts of negative ones:

* the *index* (``index``, the CSV's ``index``): the eigenvalues certified negative by the
  certificate's own rule (``verify.verdict.classify``), mu < -TOL_REL whatever the bound, since a Ritz
  value from exact products on T bounds its eigenvalue from above (Poincare: the k-th Ritz value >=
  the k-th eigenvalue). A lower bound of the Morse index; 1 or more exactly where the verdict reads
  "saddle". (Until this release it was the count below, so a matrix-free check that stops once its
  saddle is decided, with bounds 0.05-0.3 against mu -3e-4 ... -6e-3 on the meridian cup past its fold,
  wrote "saddle" beside index 0.)
* the *decided* count (``decided``), which the events use: mu < -max(err, TOL_REL), a change beyond
  the eigenvalue's bound on both sides of zero. A mode within its bound of zero, e.g. the relative
  translation of two far components, or the asymmetric mode near a symmetric turning point (the 2D
  ellipse's in c0: -2.0e-6 ... -2.4e-6, bound 1.2e-5 ... 6.8e-5, on three points at its top, an
  undecided one among them, positive ones on both sides), counts for neither side and makes no event.

Between two accepted points whose decided counts differ one eigenvalue has crossed zero: the
*critical* one (``critical_values``: the largest decidedly negative on one side, the least decidedly
positive on the other), followed through the trials by continuity (``tracked``: the eigenvalue
nearest the linear interpolation of its end values).

* **Classification** (``classify``): at a fold (saddle-node) the branch turns in p, so the
  tangent's parameter component changes sign: some secant of the three around the bracket has dp
  of the other sign. At a branch point (pitchfork, transcritical) p moves on monotonically.
* **A branch point** is located by the Illinois (modified regula falsi) iteration on
  g(p), the critical eigenvalue, each trial a fixed-p solve started from the linear interpolation of the bracket's
  fields and multipliers (``locate_branch_point``): superlinear for a simple crossing, bracketed, so
  it cannot leave the interval; it ends where |g| is within the eigenvalue's own error bound or the
  bracket is narrower than ``p_tol``.
* **A fold** is not a fixed-p point: with a corrector whose p is free (``free``: the point on the
  hyperplane through a chord point orthogonal to the chord, ``branch.bordered``) the same Illinois
  iteration runs on the chord parameter tau in [0, 1] (``locate_on_chord``); without one the fold
  is the vertex of the parabola p(s) through the three points around it (s the chord arclength),
  located to O(ds^3) only and marked so (``located_by`` = ``parabola``).

Nothing here knows about vesicles: ``tests/branch/test_tree.py`` runs it on closed forms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from vesicle_opt.verify.verdict import TOL_REL

FOLD, BRANCH_POINT = "fold", "branch point"
MAX_LOCATE = 12  # solves of one location (Illinois: ~5-8 for a simple crossing to 1e-6 of the step)


@dataclass(frozen=True)
class Point:
    """One certified point of a branch, as the event logic needs it."""

    p: float
    phi: np.ndarray = field(repr=False)
    energy: float
    eigenvalues: tuple[float, ...]  # least few, ascending (mu_ref units)
    errors: tuple[float, ...] = ()  # their error bounds
    lam: tuple[float, ...] | None = None  # the multipliers (a warm start for re-solves)
    payload: object = field(default=None, repr=False, compare=False)  # the solver's result

    @property
    def index(self) -> int:
        return index(self.eigenvalues, self.errors)

    @property
    def decided(self) -> int:
        return decided(self.eigenvalues, self.errors)


def _pairs(eigenvalues, errors):
    """(mu, err) of each eigenvalue, 0 where no bound is given."""
    return zip(eigenvalues, tuple(errors) + (0.0,) * (len(eigenvalues) - len(errors)))


def sign(mu, err) -> int:
    """The verdict's sign of one eigenvalue (``verify.verdict.classify``): -1 where mu < -TOL_REL (its
    "saddle"), +1 where mu - err >= TOL_REL (its "minimum"), else 0 (undecided, "marginal" or "not
    checked"; so is a value without a finite bound)."""
    if mu is None or err is None or not (math.isfinite(mu) and math.isfinite(err)):
        return 0
    return -1 if mu < -TOL_REL else (1 if mu - abs(err) >= TOL_REL else 0)


def index(eigenvalues, errors=()) -> int:
    """The number of eigenvalues certified negative (module docstring): mu < -TOL_REL with a finite
    error bound (without one the eigensolver's result is not trusted: the verdict's "not checked")."""
    return sum(1 for mu, e in _pairs(eigenvalues, errors) if sign(mu, e) < 0)


def decided(eigenvalues, errors=()) -> int:
    """The number of eigenvalues decidedly negative: mu < -max(err, TOL_REL) (its error bound, and the
    certificate's own threshold of a saddle, ``verify.verdict.TOL_REL``: a mode within either of zero, such
    as the relative translation of two far components or the rotation on a spectral grid, is not counted;
    the rotation's -5.3e-8 / +3.8e-8 mu_ref on the 48^2 spectral elastica, bound ~1e-9, flipped sign
    with the BLAS kernel and read as a branch point: measured). At most ``index``."""
    return sum(1 for mu, e in _pairs(eigenvalues, errors) if sign(mu, e) < 0 and mu < -abs(e))


def _bound(point: Point, i: int) -> float:
    """The error bound of the point's i-th eigenvalue as given (0 where none is)."""
    e = point.errors[i] if i < len(point.errors) else 0.0
    return abs(e) if math.isfinite(e) else 0.0


def _err(point: Point, i: int) -> float:
    return max(_bound(point, i), TOL_REL)


def critical_values(a: Point, b: Point) -> tuple[float, float]:
    """(g_a, g_b): the critical eigenvalue at both ends. On the side with more decidedly negative
    eigenvalues its largest decidedly negative one; on the other its least decidedly positive one
    (mu > err), so that a mode within its bound of zero at both ends is passed over."""
    def largest_negative(q):
        return max(mu for i, mu in enumerate(q.eigenvalues) if mu < -_err(q, i))

    def least_positive(q):
        pos = [mu for i, mu in enumerate(q.eigenvalues) if mu > _err(q, i)]
        return min(pos) if pos else max(q.eigenvalues)
    if a.decided > b.decided:
        return largest_negative(a), least_positive(b)
    return least_positive(a), largest_negative(b)


def tracked(point: Point, target: float) -> tuple[int, float, float]:
    """(position, value, error bound) of the point's eigenvalue nearest ``target`` (the critical
    one, followed by continuity between the bracket's ends)."""
    i = min(range(len(point.eigenvalues)), key=lambda j: abs(point.eigenvalues[j] - target))
    return i, point.eigenvalues[i], _err(point, i)


def crossings(points: list[Point]) -> list[int]:
    """k such that the decided count changes between points[k - 1] and points[k] and keeps its new value at
    points[k + 1] (the last point: kept). A one-point blip is no crossing: measured at a symmetric
    turning point in c0 (2D ellipse, nu = 0.8, 48^2) the critical eigenvalue (the relative
    translation of its two droplets; the rotation, kept in the check, is below it) touches zero, +1.6e-6,
    -2.7e-6, -8.4e-7 (bound 1.5e-7: one point decidedly negative), +3.4e-5, and rises again."""
    out, confirmed = [], points[0].decided if points else 0
    for k in range(1, len(points)):
        i = points[k].decided
        if i != confirmed and (k + 1 == len(points) or points[k + 1].decided == i):
            out.append(k)
            confirmed = i
    return out


def turns(points: list[Point], window: int = 5) -> list[int]:
    """k where the parameter turns at points[k] ((p_k - p_{k-1})(p_{k+1} - p_k) < 0), a turn within
    ``window`` points of the previous one counted with it (a walk creeping round a fold zigzags in
    p by ~1e-6: measured 0.73476515, 0.73476171, 0.73475984, 0.73476227, 0.73476518, 0.73475825)."""
    out: list[int] = []
    for k in range(1, len(points) - 1):
        if (points[k].p - points[k - 1].p) * (points[k + 1].p - points[k].p) < 0 and \
                (not out or k - out[-1] > window):
            out.append(k)
    return out


def _undecided(q: Point) -> int:
    """The number of q's eigenvalues within their bound of zero (|mu| <= err)."""
    return sum(1 for i, mu in enumerate(q.eigenvalues) if math.isfinite(mu) and abs(mu) <= _err(q, i))


def bracket(points: list[Point], k: int, reach: int = 3) -> tuple[int, int]:
    """(a, b), a < k <= b: the change of the decided count between points[k - 1] and points[k], widened so
    that the critical eigenvalue is decided at both ends. The count takes the decidedly negative
    eigenvalues only, so on the side with the lower count the crossing eigenvalue may still be
    within its bound of zero; that end moves on (up to ``reach`` points, the count unchanged) to
    the first point with no more undecided eigenvalues than the other end has (a soft mode within
    its bound at both ends, such as the relative translation of far components, is not the
    crossing one). Measured on the switched branch of the
    nu = 0.8 pair in c0 (2D, FD 48^2): -1.1e-5 (bound 6.3e-6), -4.3e-6 (6.6e-6), +2.7e-6 (2.6e-7),
    the parameter turning at the third: the bracket is the first and the third, not the first two
    (whose ends' critical values would be -1.1e-5 and the next mode, +0.078)."""
    a, b = k - 1, k
    if points[k].decided < points[k - 1].decided:  # the low side after the change: b moves on
        soft = _undecided(points[k - 1])
        while b + 1 < len(points) and b - k < reach and _undecided(points[b]) > soft and \
                points[b + 1].decided == points[k].decided:
            b += 1
    else:
        soft = _undecided(points[k])
        while a - 1 >= 0 and k - 1 - a < reach and _undecided(points[a]) > soft and \
                points[a - 1].decided == points[k - 1].decided:
            a -= 1
    return a, b


def classify(ps: list[float], k: int, a: int | None = None, b: int | None = None) -> str:
    """FOLD if the parameter turns at a point of the bracket [a, b] (default: k - 1, k; widened
    by ``bracket``) of the parameter values ``ps``, else BRANCH_POINT (module docstring): a turn at
    j, (p_j - p_{j-1})(p_{j+1} - p_j) < 0, puts the vertex of p(s) within (s_{j-1}, s_{j+1}), which
    meets the bracket's [s_a, s_b], where the critical eigenvalue crosses zero, iff a <= j <= b.
    A fold is a zero crossing of the p-fixed Hessian's eigenvalue (its determinant changes sign
    with the tangent's p-component), so a crossing that coincides with a turn is the fold."""
    a = k - 1 if a is None else a
    b = k if b is None else b
    turn = any((ps[j] - ps[j - 1]) * (ps[j + 1] - ps[j]) < 0 for j in range(max(a, 1), min(b, len(ps) - 2) + 1))
    return FOLD if turn else BRANCH_POINT


@dataclass(frozen=True)
class Located:
    """A located event: the point (certified where ``point`` came from a solve), how, and the
    bracket it was found in."""

    kind: str
    point: Point | None  # None: parabola (no solve) or the location failed
    p: float
    energy: float
    critical: int  # the critical eigenvalue's position in the located point's list (its mode's)
    eigenvalue: float  # g at the located point (nan for a parabola)
    error: float  # its error bound (nan for a parabola)
    bracket: float  # final width of the bracket, in p (branch point) or tau (chord)
    solves: int
    located_by: str  # "illinois" | "chord" | "parabola" | "failed: ..."
    iterations: int = 0


def _illinois(evaluate: Callable, lo: float, g_lo: float, hi: float, g_hi: float, tol: float,
              max_solves: int):
    """Illinois iteration on [lo, hi] with g(lo) g(hi) < 0 (or one end within ``TOL_REL`` of zero with
    the other's sign: one secant step past it first); ``evaluate(x)`` -> (g, err, point) or
    None (a failed solve: the next trial is the midpoint). Returns (best point, g, err, width, solves)."""
    best, side, solves, failed = None, 0, 0, False
    if g_lo * g_hi > 0 and g_lo != g_hi:
        # one end's critical value is within TOL_REL of zero (undecided for ``index``) but of the other
        # end's sign: the zero lies just beyond it. One secant step past that end (at most the bracket's
        # width) restores a sign change (measured on the symmetric fold line: -5e-10, bound 2e-11, at the
        # predicted turn; bisecting towards it instead took 12 solves to a 1.2e-7 bracket)
        near, g_near, far, g_far = (hi, g_hi, lo, g_lo) if abs(g_hi) < abs(g_lo) else (lo, g_lo, hi, g_hi)
        step = -g_near * (near - far) / (g_near - g_far)
        x = near + math.copysign(min(abs(step), abs(hi - lo)), step)
        r = evaluate(x)
        solves += 1
        if r is None:
            return None, math.nan, math.nan, abs(hi - lo), solves
        gx, err, pt = r
        best = (pt, gx, err)
        if abs(gx) <= err:  # zero to its own bound
            return pt, gx, err, abs(x - near), solves
        if gx * g_near > 0:  # still no sign change: no bracket (the width returned is the ends')
            return pt, gx, err, abs(hi - lo), solves
        lo, g_lo, hi, g_hi = near, g_near, x, gx
    while solves < max_solves and abs(hi - lo) > tol:
        x = (lo + hi) / 2 if failed else lo - g_lo * (hi - lo) / (g_hi - g_lo)
        if not min(lo, hi) < x < max(lo, hi):
            x = (lo + hi) / 2
        r = evaluate(x)
        solves += 1
        if r is None:
            if failed:  # two failures in a row: stop with what there is
                break
            failed = True
            continue
        failed = False
        gx, err, pt = r
        if best is None or abs(gx) < abs(best[1]):
            best = (pt, gx, err)
        if abs(gx) <= err:  # zero to its own error bound
            return pt, gx, err, abs(hi - lo), solves
        if gx * g_lo > 0:
            lo, g_lo = x, gx
            if side == -1:
                g_hi /= 2  # Illinois: the retained end's value halved
            side = -1
        else:
            hi, g_hi = x, gx
            if side == 1:
                g_lo /= 2
            side = 1
    if best is None:
        return None, math.nan, math.nan, abs(hi - lo), solves
    return best[0], best[1], best[2], abs(hi - lo), solves


def _mix(a, b, t):
    return None if a is None or b is None else tuple((1 - t) * x + t * y for x, y in zip(a, b))


def locate_branch_point(solve: Callable, a: Point, b: Point, p_tol: float,
                        max_solves: int = MAX_LOCATE) -> Located:
    """The branch point between a and b (same sheet, p monotone): ``solve(p, phi0, lam0)`` -> a
    certified Point or None; each trial warm from the interpolation of a and b."""
    ga, gb = critical_values(a, b)

    def evaluate(p):
        t = (p - a.p) / (b.p - a.p)
        pt = solve(p, (1 - t) * a.phi + t * b.phi, _mix(a.lam, b.lam, t))
        return _tracked(pt, ga + t * (gb - ga))

    return _located(BRANCH_POINT, _illinois(evaluate, a.p, ga, b.p, gb, p_tol, max_solves), a, b, "illinois")


def _tracked(pt: Point | None, target: float):
    if pt is None or not pt.eigenvalues or not all(math.isfinite(x) for x in pt.eigenvalues):
        return None
    i, mu, _ = tracked(pt, target)
    return mu, _bound(pt, i), (pt, i)  # located to its own bound, not TOL_REL


def _located(kind, found, a, b, how) -> Located:
    best, gx, err, width, n = found
    if best is None:
        return Located(kind, None, (a.p + b.p) / 2, (a.energy + b.energy) / 2, 0, math.nan, math.nan, width, n,
                       "failed: no trial converged")
    pt, i = best
    return Located(kind, pt, pt.p, pt.energy, i, gx, err, width, n, how)


def locate_on_chord(free: Callable, a: Point, b: Point, weights, theta: float, tau_tol: float,
                    kind: str = FOLD, max_solves: int = MAX_LOCATE) -> Located:
    """The event between a and b with p free: ``free(phi_pred, p_pred, t_phi, t_p, theta)`` -> a
    certified Point on the hyperplane through the chord point at tau orthogonal to the chord (in
    the metric theta^2 <., .>_w + dp^2) or None; Illinois in tau."""
    ga, gb = critical_values(a, b)
    dphi, dp = b.phi - a.phi, b.p - a.p
    length = math.hypot(theta * math.sqrt(float(np.dot(weights, dphi * dphi))), dp)
    t_phi, t_p = dphi / length, dp / length

    def evaluate(tau):
        return _tracked(free(a.phi + tau * dphi, a.p + tau * dp, t_phi, t_p, theta), ga + tau * (gb - ga))

    return _located(kind, _illinois(evaluate, 0.0, ga, 1.0, gb, tau_tol, max_solves), a, b, "chord")


def locate_fold_parabola(pts: list[Point], weights, theta: float, m: int = 0) -> Located:
    """The fold as the vertex of the parabola p(s) through three points around it (s: the chord
    arclength in the metric theta^2 <., .>_w + dp^2), the energy from the parabola E(s) through the
    same points (module docstring)."""
    s = [0.0]
    for x, y in zip(pts, pts[1:]):
        d = y.phi - x.phi
        s.append(s[-1] + math.hypot(theta * math.sqrt(float(np.dot(weights, d * d))), y.p - x.p))
    cp = np.polyfit(s, [q.p for q in pts], 2)
    ce = np.polyfit(s, [q.energy for q in pts], 2)
    sv = -cp[1] / (2 * cp[0]) if cp[0] != 0 else s[1]
    sv = min(max(sv, s[0]), s[-1])
    return Located(FOLD, None, float(np.polyval(cp, sv)), float(np.polyval(ce, sv)), m, math.nan, math.nan,
                   0.0, 0, "parabola")


def with_index(point: Point, eigenvalues, errors=()) -> Point:
    return replace(point, eigenvalues=tuple(float(x) for x in eigenvalues), errors=tuple(float(x) for x in errors))


def spectrum_extra(so) -> dict:
    """A second-order check's (``verify.verdict.SecondOrder``) least few eigenvalues and their
    error bounds (mu_ref units), for a Result's extra: the point's index."""
    return {"second_order_eigenvalues": tuple(float(x) for x in so.eigenvalues),
            "second_order_errors": tuple(float(x) for x in so.errors)}
