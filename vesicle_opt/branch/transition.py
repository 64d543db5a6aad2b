"""A first-order transition line in two parameters: the energy crossing of two branches, continued
in a second parameter q (e.g. the prolate/oblate crossing v*(c0) of the spontaneous-curvature
model; Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991), Fig. 8's line D).

At each q the crossing p*(q) of branches a and b (e.g. p = the reduced volume) solves
Delta(p, q) = E_a(p, q) - E_b(p, q) = 0, E_x the energy (3) of the certified KKT point of branch x
(exact constraints (4), (5)). Continuation in q (``continue_line``), outward from the start q0 in each
direction of ``values``:

* predictor: the secant through the last two crossings in (q, p*); from the start, the tangent
  dp*/dq = -(dDelta/dq) / (dDelta/dp), both derivatives from the envelope identity
  (``branch.params``: dE/dp = lambda_V dalpha/dp, dE/dq = dE/dq|_phi) at the two certified points
  (the Clausius-Clapeyron slope of the line);
* ``local_crossing``: each branch re-followed locally around the predicted p, warm from the
  previous crossing's two shapes (the nearest solved point's field, the multipliers linear in p
  through the two nearest): a first solve at the prediction, a Newton step on Delta with the
  envelope derivatives, samples at that estimate and +- dp (extended outward, up to ``EXTEND``
  more steps, until Delta changes sign), the crossing located on the samples by cubic splines and
  brentq (``branch.crossing``) and both branches re-solved there as certified points; ``gap`` =
  |Delta| / |E| at those points says how well the spline located it. A crossing found farther
  than dp from its prediction is located again from samples centred on it (``RECENTRE`` rounds):
  the spline is then interpolating, not extrapolating, at p*. Then up to ``POLISH`` Newton steps
  on Delta at the two certified points, dDelta/dp from the envelope identity (exact for KKT points),
  while ``gap`` exceeds ``GAP_TOL``: the spline's error (O(dp^4), larger where the samples' states
  differ slightly) is not left in the line.

The start (q0) is located the same way from the scenes' own p, walking towards ``towards`` with
steps dp, cold from the scenes' initial shapes. A failed solve ends the line in that direction
(a row with ``converged`` false, its outcome and reason: never a crossing).

The problem (``solver``) gives ``solve(x, p, q, phi0, lam0) -> Sample`` for x in "a", "b"
(phi0 None: cold from that branch's own start), and ``disc`` for the snapshots
(``branch.transition_store``). Python API for vesicles: ``branch.transition_vesicle.transition_line``.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from vesicle_opt.branch.crossing import crossing

POLISH = 2  # Newton steps on Delta at the certified points after the spline, while gap > GAP_TOL
GAP_TOL = 1e-9  # |E_a - E_b| / |E|: above the solves' energy noise at IPOPT tol 1e-8 (gaps 2e-11 .. 2e-10 measured on
# the meridian line D(c0), eps = 0.05) and below what the spline leaves where samples are far (5e-4 at a cold start)
RECENTRE = 2  # rounds of samples re-centred on a crossing found farther than dp from its prediction
EXTEND = 6  # samples beyond the first three before the line gives up at a q (Delta of one sign)
BRANCHES = ("a", "b")


@dataclasses.dataclass
class Sample:
    """One solved point of a branch: its parameters, field, energy (the compared quantity),
    multipliers, the envelope derivatives dE/dp and dE/dq, whether certified, and its report
    (``row``: the branch-row columns, prefixed a_ / b_ in the line's CSV)."""

    p: float
    q: float
    phi: np.ndarray
    energy: float
    converged: bool
    lam: tuple | None = None
    dE_dp: float | None = None
    dE_dq: float | None = None
    row: dict = dataclasses.field(default_factory=dict)
    disc: object = None  # the mesh phi lives on where it is the point's own (interface-refined meshes)


def solve_from(solver, x: str, p: float, q: float, src: Sample | None, lam) -> Sample:
    """``solver.solve`` at (p, q) warm from ``src`` (None: cold), its mesh passed on (``disc0``)
    where the point has its own (an interface-refined mesh follows the interface)."""
    if src is not None and src.disc is not None:
        return solver.solve(x, p, q, src.phi, lam, disc0=src.disc)
    return solver.solve(x, p, q, None if src is None else src.phi, lam)


@dataclasses.dataclass
class Found:
    """The outcome of ``local_crossing`` at one q: the certified points (a, b) at p*, or why not."""

    q: float
    p: float | None
    points: dict  # "a"/"b" -> Sample (the re-solved ones; the failing one when not converged)
    predicted: float
    samples: int
    solves: int
    wall: float
    reason: str | None = None

    @property
    def converged(self) -> bool:
        return self.reason is None and all(self.points[x].converged for x in BRANCHES)

    @property
    def gap(self) -> float | None:
        if self.p is None or not all(x in self.points for x in BRANCHES):
            return None
        a, b = self.points["a"].energy, self.points["b"].energy
        return abs(a - b) / max(abs(a), abs(b), 1e-300)


def _nearest(samples: list[Sample], p: float) -> Sample:
    return min(samples, key=lambda s: abs(s.p - p))


def _lam_at(samples: list[Sample], p: float):
    """Multipliers at p, linear through the two nearest samples (the nearest's with one)."""
    near = sorted((s for s in samples if s.lam is not None), key=lambda s: abs(s.p - p))[:2]
    if not near:
        return None
    if len(near) == 1 or near[0].p == near[1].p:
        return tuple(near[0].lam)
    a, b = near
    t = (p - a.p) / (b.p - a.p)
    return tuple(float(x) + t * (float(y) - float(x)) for x, y in zip(a.lam, b.lam))


def local_crossing(solver, q: float, p_pred: float, dp: float, warm: dict | None,
                   towards: float | None = None, in_range=lambda p: True) -> Found:
    """The crossing at q near ``p_pred`` (module docstring); ``warm``: "a"/"b" -> Sample (None: cold
    starts); ``towards``: the sign of the search when Delta has no derivative (the start);
    ``in_range(p)``: the parameter's allowed values (samples outside are not tried)."""
    t0 = time.perf_counter()
    dp = abs(dp)
    pts: dict[str, list[Sample]] = {x: [] for x in BRANCHES}
    nsolves = [0]

    def at(p: float) -> str | None:
        """Solve both branches at p, warm from each one's nearest sample; why not (None: both)."""
        for x in BRANCHES:
            if any(abs(s.p - p) < 1e-12 * max(1.0, abs(p)) for s in pts[x]):
                continue
            src = _nearest(pts[x], p) if pts[x] else (None if warm is None else warm[x])
            lam = _lam_at(pts[x], p) if pts[x] else (None if src is None else src.lam)
            s = solve_from(solver, x, p, q, src, lam)
            nsolves[0] += 1
            if not s.converged:
                fail[x] = s
                why = s.row.get("reason") or s.row.get("outcome")
                return f"branch {x} not certified at p = {p:.8g} (q = {q:.6g}): {why}"
            pts[x].append(s)
        return None

    def delta(p):
        sa, sb = (next(s for s in pts[x] if abs(s.p - p) < 1e-12 * max(1.0, abs(p))) for x in BRANCHES)
        return sa.energy - sb.energy

    def done(why, p=None, points=None):
        points = points or {x: (fail.get(x) or (_nearest(pts[x], p_pred) if pts[x] else None)) for x in BRANCHES}
        return Found(q, p, {k: v for k, v in points.items() if v is not None}, p_pred, len(pts["a"]), nsolves[0],
                     time.perf_counter() - t0, why)

    fail: dict[str, Sample] = {}
    if not in_range(p_pred):
        return done(f"the predicted p = {p_pred:.8g} lies outside the parameter's range")
    why = at(p_pred)
    if why:
        return done(why)
    d0 = delta(p_pred)
    sa, sb = pts["a"][0], pts["b"][0]
    slope = None if sa.dE_dp is None or sb.dE_dp is None else sa.dE_dp - sb.dE_dp
    if slope:  # a Newton step on Delta, held within 3 dp (the samples then straddle it)
        p_c = p_pred - max(-3 * dp, min(3 * dp, d0 / slope))
        order = [p_c - dp, p_c, p_c + dp]
        sign = -math.copysign(1.0, d0 / slope)
    else:
        sign = math.copysign(1.0, (towards if towards is not None else p_pred - 1.0) - p_pred)
        order = [p_pred + sign * dp, p_pred + 2 * sign * dp, p_pred - sign * dp]
    for p in order:
        if in_range(p):
            why = at(p)
            if why:
                return done(why)
    for _ in range(EXTEND):  # Delta of one sign on the samples: extend where |Delta| falls
        ps = sorted(s.p for s in pts["a"])
        ds = [delta(p) for p in ps]
        if any(x * y <= 0 for x, y in zip(ds, ds[1:])):
            break
        lo_or_hi = ps[-1] + dp if abs(ds[-1]) < abs(ds[0]) else ps[0] - dp
        if not in_range(lo_or_hi):
            return done(f"no crossing in [{ps[0]:.6g}, {ps[-1]:.6g}] and the range ends")
        why = at(lo_or_hi)
        if why:
            return done(why)
    ps = sorted(s.p for s in pts["a"])
    x = crossing(*[v for k in BRANCHES for v in ([s.p for s in pts[k]], [s.energy for s in pts[k]])])
    if x is None:
        return done(f"no crossing among {len(ps)} samples in [{ps[0]:.6g}, {ps[-1]:.6g}]")
    p_star = x["reduced_volume"]  # crossing()'s name for the abscissa
    for it in range(POLISH + 1):
        final = {}
        for k in BRANCHES:
            src = _nearest(pts[k], p_star)
            s = solve_from(solver, k, p_star, q, src, _lam_at(pts[k], p_star))
            nsolves[0] += 1
            final[k] = s
            if not s.converged:
                return done(f"branch {k} not certified at the crossing p = {p_star:.8g}: "
                            f"{s.row.get('reason') or s.row.get('outcome')}", None, final)  # no crossing
        a, b = final["a"], final["b"]
        gap = abs(a.energy - b.energy) / max(abs(a.energy), abs(b.energy), 1e-300)
        if it == POLISH or gap <= GAP_TOL or a.dE_dp is None or b.dE_dp is None or a.dE_dp == b.dE_dp:
            break
        step = (a.energy - b.energy) / (a.dE_dp - b.dE_dp)  # Newton on Delta, exact derivatives
        if abs(step) > dp:  # not leaving the samples' span
            break
        for k in BRANCHES:
            pts[k].append(final[k])
        p_star -= step
    return done(None, p_star, final)


def predict(history: list[Found], q: float) -> float:
    """p* at q from the crossings found so far in this direction (module docstring)."""
    last = history[-1]
    if len(history) >= 2:
        prev = history[-2]
        return last.p + (q - last.q) * (last.p - prev.p) / (last.q - prev.q)
    a, b = last.points["a"], last.points["b"]
    if None in (a.dE_dp, b.dE_dp, a.dE_dq, b.dE_dq) or a.dE_dp == b.dE_dp:
        return last.p
    return last.p - (q - last.q) * (a.dE_dq - b.dE_dq) / (a.dE_dp - b.dE_dp)


def plan(q0: float, values) -> list[tuple[str, float]]:
    """(direction, q) in the order computed: the start, then outward up, then outward down."""
    up = sorted(v for v in values if v > q0)
    down = sorted((v for v in values if v < q0), reverse=True)
    return [("start", q0)] + [("up", v) for v in up] + [("down", v) for v in down]


def outward(q0: float, values, step, progress=None) -> list:
    """``step(q, past)`` at each q of ``plan(q0, values)``, ``past`` the results so far of the start
    and of q's direction ([] for the start itself), each result (with ``converged``) handed to
    ``progress``; a direction stops after its first unconverged result, and every direction after an
    unconverged start. Returns the results in the order computed."""
    out: list = []
    hist: dict[str, list] = {}
    for direction, q in plan(q0, values):
        past = hist.get("start", []) + (hist.get(direction, []) if direction != "start" else [])
        if direction != "start" and (not past or not past[-1].converged):
            continue
        result = step(q, past)
        hist.setdefault(direction, []).append(result)
        out.append(result)
        if progress is not None:
            progress(result)
    return out


def continue_line(solver, q0: float, p0: float, towards: float, values, dp: float, store,
                  in_range=lambda p: True, progress=None) -> list[dict]:
    """The line (module docstring): a row per q of ``plan(q0, values)`` appended to ``store``
    (``branch.transition_store.LineStore``: rows and the two fields of each, resumed), stopping a
    direction at its first failure. Returns the rows."""
    steps = plan(q0, values)
    done = {r["row"]: r for r in store.rows()}  # by plan index: a stopped direction leaves indices out
    history: dict[str, list[Found]] = {"start": [], "up": [], "down": []}
    stopped: set[str] = set()
    for i, (direction, q) in enumerate(steps):
        line = "start" if direction == "start" else direction
        if direction != "start" and "start" in stopped:
            break
        if line in stopped:
            continue
        if i in done:  # done before a kill: its crossing, read back
            r = done[i]
            if not r["converged"]:
                stopped.add(line)
                continue
            history[line].append(store.found(i, r))
            continue
        past = history["start"] + history[line] if line != "start" else []
        if line == "start":
            found = local_crossing(solver, q, p0, dp, None, towards, in_range)
        else:
            found = local_crossing(solver, q, predict(past[-2:], q), dp, past[-1].points, None, in_range)
        for _ in range(RECENTRE):  # p* more than dp from the prediction: the samples were not around it
            if not found.converged or abs(found.p - found.predicted) <= dp:
                break
            again = local_crossing(solver, q, found.p, dp, found.points, None, in_range)
            found = dataclasses.replace(again, predicted=found.predicted, samples=found.samples + again.samples,
                                        solves=found.solves + again.solves, wall=found.wall + again.wall)
        row = store.append(i, direction, found)
        if progress is not None:
            progress(row)
        if not found.converged:
            stopped.add(line)
        else:
            history[line].append(found)
    return store.rows()
