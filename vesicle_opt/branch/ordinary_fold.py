"""An ordinary fold (saddle-node) continued in a second parameter q, with another mode negative on
both of its sheets.

At a simple fold of the branch in p the p-fixed Hessian of the Lagrangian on the constraints'
tangent space (paper eqs. (6)-(8), the reduced Hessian of ``verify.second_order``) has one
eigenvalue crossing zero and the tangent's p-component dp/ds changes sign with it. Where another
eigenvalue is negative on both sheets (on the 2D pair of droplets below nu_c ~ 0.802: their
relative rotation, a near-symmetry mode of the periodic box) the least eigenvalue keeps its sign
and the fold is invisible to a test on it (``branch.fold_continuation`` wants minima beside the
fold); what changes is the count of decidedly negative eigenvalues (``events.decided``), 1 -> 2 across it,
and the eigenvalue that crosses is the one ``branch.events.critical_values`` picks at the two ends
(the largest decidedly negative on one side, the least decidedly positive on the other), followed
by continuity. The other modes are not touched: the rotation stays in the check and is passed over
because it is decided at both ends.

``locate`` finds the fold at one q from a centre phi_c (a field near the fold), a direction t (the
chord through the fold: nearly its null vector) and a half-width h:

1. two points with p free on the hyperplanes <phi - phi_c, t>_w = -+h (the bordered corrector of
   ``branch.bordered``, each certified at its own p: ``free(phi_pred, p_pred, t_phi, t_p, theta)``
   with t_p = 0), so one on each sheet; widened (h doubled, up to ``EXPAND`` times) until their
   indices differ;
2. the Illinois iteration on the chord between them with p free (``events.locate_on_chord``, as a
   walk locates a fold), which ends where the critical eigenvalue is zero to its own error bound
   (or, failing that, the chord's parameter is bracketed to ``TAU_TOL``);
3. the checks: the parameter turns there (p at the fold beyond p at both ends: the two sheets lie on
   one side of it) and, as a cross-check independent of the eigenvalue, the vertex of the parabola
   p(sigma) through the two ends and the located point (sigma = <phi - phi_c, t>_w).

``line`` continues it over ``values`` of q outward from q0 (up, then down; a failure ends its
direction): at each q the centre and p are predicted by the secant through the last two folds
(the last one's with one), t is the last chord and h the last half-width. Nothing here knows about
vesicles (``tests/branch/test_ordinary_fold.py`` runs it on a closed form); ``solver`` provides
``free(q)`` (the callable above, at q), ``weights`` and ``solves`` (a running count).
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import ClassVar

import numpy as np

from vesicle_opt.branch import events as ev
from vesicle_opt.branch.transition import outward

WIDTHS = (1, 0.5, 2, 0.25, 4, 0.125, 8, 16)  # the half-widths tried, in units of h, until the sides' indices
# differ: narrower first (a wide pair may straddle two folds, as near the cusp where two meet), then wider
TAU_TOL = 1e-6  # the chord's parameter to this where the eigenvalue's bound is not met first (a walk
# stops at 1e-3, ``branch.tree.TAU_TOL``; a fold line wants the critical eigenvalue zero to its bound)


@dataclasses.dataclass
class Fold:
    """The fold at one q: p (None: not found, ``reason``), its energy, the critical eigenvalue there
    (its position ``critical`` in the point's list) and its bound, the final chord bracket (in tau),
    p on the two sheets' points, the parabola's vertex in p, the chord (t, h) for the next q, solves,
    wall and CPU seconds."""

    q: float
    p: float | None
    energy: float | None
    eigenvalue: float
    error: float
    critical: int | None
    bracket: float
    sheets: tuple[float, float] | None
    vertex: float | None
    solves: int
    wall: float
    cpu: float
    point: ev.Point | None = dataclasses.field(default=None, repr=False)
    chord: tuple[np.ndarray, float] | None = dataclasses.field(default=None, repr=False)
    reason: str | None = None
    kind: ClassVar[str] = "ordinary"  # fold_line.csv's fold_kind (``branch.symmetric_fold.Turn``: symmetric)

    @property
    def converged(self) -> bool:
        return self.reason is None


def _sigma(weights, phi, centre, t) -> float:
    return float(np.dot(weights, (np.asarray(phi, float) - centre) * t))


def vertex(sig, ps) -> float | None:
    """p at the vertex of the parabola p(sigma) through three points (None: collinear)."""
    a, b, c = np.polyfit(np.asarray(sig, float), np.asarray(ps, float), 2)
    return None if a == 0 else float(c - b * b / (4 * a))


def locate(solver, q: float, centre, p_pred: float, t, h: float, theta: float = 1.0) -> Fold:
    """The fold at q near the hyperplane through ``centre`` orthogonal to ``t`` (module docstring)."""
    t0, c0, s0 = time.perf_counter(), time.process_time(), solver.solves
    w = np.asarray(solver.weights, float)
    centre = np.asarray(centre, float)
    t = np.asarray(t, float) / math.sqrt(float(w @ (np.asarray(t, float) ** 2)))
    free = solver.free(q)

    def done(reason, loc=None, a=None, b=None, vx=None, chord=None):
        pt = None if loc is None else loc.point
        return Fold(q, None if reason else pt.p, None if reason else pt.energy,
                    math.nan if loc is None else loc.eigenvalue, math.nan if loc is None else loc.error,
                    None if loc is None else loc.critical, math.nan if loc is None else loc.bracket,
                    None if a is None else (a.p, b.p), vx, solver.solves - s0, time.perf_counter() - t0,
                    time.process_time() - c0, pt, chord, reason)
    tried = []  # (h, decided count on both sides) or (h, None: a side had no point)
    for k in WIDTHS:
        a = free(centre - k * h * t, p_pred, t, 0.0, theta)
        b = free(centre + k * h * t, p_pred, t, 0.0, theta)
        if a is not None and b is not None and a.decided != b.decided:
            h *= k
            break
        tried.append((k * h, None if a is None or b is None else a.decided))
    else:
        said = "; ".join(f"+-{x:.3g}: " + ("no point on a side" if i is None else f"decided count {i} on both sides")
                         for x, i in tried)
        return done(f"no change of the decided count between the sides ({said}): no fold there")
    loc = ev.locate_on_chord(free, a, b, w, theta, TAU_TOL)
    if loc.point is None:
        return done(f"the location failed ({loc.located_by})", a=a, b=b)
    d = b.phi - a.phi
    chord = (d / math.sqrt(float(w @ (d * d))), h)
    if abs(loc.eigenvalue) > loc.error and loc.bracket > TAU_TOL:
        return done(f"not located: |mu| = {abs(loc.eigenvalue):.3g} > its bound {loc.error:.3g}", loc, a, b)
    if (loc.p - a.p) * (loc.p - b.p) <= 0:  # the sheets on both sides of p_f: no turn, a branch point
        return done(f"the parameter does not turn at {loc.p:.8g} (sheets at {a.p:.8g}, {b.p:.8g})", loc, a, b)
    vx = vertex([_sigma(w, x.phi, centre, t) for x in (a, loc.point, b)], [a.p, loc.p, b.p])
    return done(None, loc, a, b, vx, chord)


def line(solver, q0: float, centre, p0: float, t, h: float, values, theta: float = 1.0,
         progress=None) -> list[Fold]:
    """The fold at q0 (from ``centre``, ``p0``, chord ``t``, half-width ``h``) and at each q of
    ``values`` outward from q0, each predicted by the secant of its direction (module docstring)."""

    def step(q: float, past: list[Fold]) -> Fold:
        if not past:  # the start
            c, p, tt, hh = centre, p0, t, h
        else:
            last = past[-1]
            c, p = last.point.phi, last.p
            if len(past) >= 2:  # the secant through the last two folds, for the field and p
                r = (q - last.q) / (last.q - past[-2].q)
                c, p = c + r * (c - past[-2].point.phi), p + r * (p - past[-2].p)
            tt, hh = last.chord
        return locate(solver, q, c, p, tt, hh, theta)
    return outward(q0, [float(v) for v in values], step, progress)
