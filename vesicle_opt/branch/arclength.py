"""Predictor, corrector and step control of a continuation in one scalar parameter p.

The branch is a curve s -> (phi(s), p(s)) of KKT points. Arclength is measured in the metric

    |(d phi, d p)|^2 = theta^2 <d phi, d phi>_w + d p^2,

<.,.>_w the weighted (mass, L2) inner product of the fields and theta fixed after the first step so
that this step's field change counts as much as its parameter change (theta |d phi_1| = |d p_1|).

* Predictor: the first step is a parameter step from the start (zero-order: the previous field),
  or, given the start's tangent dphi/dp (``tangent``; Newton-Krylov, ``branch.nk_free.tangent``), a
  step along it with p free (``_first_tangent``); afterwards the secant
  t = (phi_i - phi_{i-1}, p_i - p_{i-1}) / |.|, u_pred = u_i + ds t.
* Corrector (``correct(p, phi_start)``: a solve with p fixed, e.g. the exact-constraint front door):
  natural, p = p_pred, while the branch is steep in p (|t_p| >= ``Settings.turn``); near a fold
  (|t_p| small) pseudo-arclength: p is the unknown of the scalar equation
      N(p) = theta^2 <phi(p) - phi_pred, t_phi>_w + (p - p_pred) t_p = 0
  (the point on the hyperplane through u_pred orthogonal to t), solved by one Newton step
  (dN/dp ~ 1/t_p) and secants, every trial solve started from phi_pred so that it stays on the
  predicted sheet. Limitation (measured on x^2 + p^2 = 1, ``tests/branch/test_arclength.py``):
  with a corrector that holds p fixed, the walk approaches a fold to |p - p_fold| ~ 1e-4 but does
  not pass it (the trials beyond the fold have no point, those before it land on the same sheet).
  Given a corrector with p free (``free``: the point on that hyperplane, p an unknown; for
  vesicles the bordered Newton system of ``branch.bordered``) it replaces the scalar iteration,
  and the walk passes the fold: after it t_p has changed sign and the natural steps go on on the
  other sheet (p decreasing).
* A converged corrector farther than ``max_deviation`` ds from the prediction has jumped to
  another branch (measured on a smooth 2D branch, 48², step 0.05: 0.07-0.14): rejected like a
  failure.
* Step: ds <- ds * clip(min(sqrt(target_iterations / iterations), sqrt(target_deviation /
  deviation)), 0.5, 1.5) (iterations: the attempt's ``control`` count where it gives one, the part of
  its work that grows with the step), at most the first step's ds (the deviation |u - u_pred| / ds of the
  secant grows like the branch's curvature times ds: where the branch bends the step shrinks); a failed corrector halves ds (and the attempt is recorded, never skipped); below
  ``min_step_factor`` times the first ds the branch stops. Where ``Settings.predict`` gives the p-free
  corrector a start, the control reads the deviation from the nearer of that start and the linear
  prediction (the start is the predictor the corrector may use: on the octant prolate at eps 0.05 the
  linear prediction's deviation sat at 0.22-0.24 from blending two profiles, the profile secant's at
  0.07-0.08, and the step shrank to a third with Newton at 5 steps a point against the target 8; read
  from the start: the first step's ds held, 532 against 1034 CPU s a unit of v). The jump test
  (``max_deviation``) reads the linear prediction's.

The state of the walk (``Track``) is a function of what is recorded (the last two accepted points,
the next ds and theta), so a walk is resumed from its records alone. Nothing here knows about
vesicles: the tests run it on curves with a closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class Settings:
    step: float  # the first parameter step, signed (towards ``to``)
    to: float
    max_points: int = 200  # accepted points of one branch, the start included
    min_step_factor: float = 1.0 / 64
    target_iterations: int = 6  # corrector iterations the step control aims at (IPOPT warm: 4-8)
    turn: float = 0.35  # |t_p| below which the pseudo-arclength corrector runs
    arc_tol: float = 1e-3  # |N| <= arc_tol * ds ends the scalar iteration
    max_arc_solves: int = 4
    target_deviation: float = 0.08  # |u - u_pred| / ds the step control aims at where the branch bends
    # (measured on the 128^2 elastica: 0.05 on the smooth part, 0.1-0.26 at nu 0.63-0.56, where
    # lambda_area dips and the envelope residual / step^2 rose from ~0.4 to ~200 at a fixed step)
    max_deviation: float = 2.0  # |u - u_pred| / ds above which a converged corrector has left the
    # predicted branch (a jump to another branch): rejected as a failed attempt, the step halves
    predict: Callable | None = None  # (phi_a, phi_b, k) -> the p-free corrector's start (``start=``), k =
    # ds / |secant|; None: it starts at the linear prediction. The hyperplane stays the linear one's


@dataclass(frozen=True)
class Attempt:
    """What one corrector call returned: the field, its parameter and the verdict."""

    p: float
    phi: np.ndarray
    converged: bool
    iterations: int
    payload: object = None  # the solver's result (a Result) and anything the caller needs
    control: int | None = None  # the iterations the step control reads (None: ``iterations``): those
    # that grow with the step, where a corrector also spends a fixed count (``VesicleProblem.free_corrector``)


@dataclass(frozen=True)
class Step:
    """One recorded attempt of the walk (a CSV row's bookkeeping)."""

    attempt: Attempt
    accepted: bool
    corrector: str  # "start" | "natural" | "arclength"
    solves: int
    arc_step: float  # the ds of the next attempt (before theta is known: the next parameter step)
    theta: float | None
    arc_condition: float | None = None  # N(p) / ds of the accepted arclength point
    deviation: float | None = None  # |u - u_pred| / ds in the arclength metric (predictor error)


@dataclass(frozen=True)
class Track:
    """The walk's state: accepted points (p, phi), newest last (at most two kept), ds and theta."""

    points: tuple = ()
    ds: float | None = None  # None: the first step is a parameter step of size ``first``
    first: float | None = None  # the next first step (signed; halved on failures)
    theta: float | None = None
    accepted: int = 0
    started: bool = False  # the start has been attempted

    def push(self, p: float, phi: np.ndarray) -> "Track":
        return replace(self, points=(self.points + ((float(p), phi),))[-2:], accepted=self.accepted + 1)


def norm_w(weights, v) -> float:
    return float(np.sqrt(np.dot(weights, v * v)))


def finished(track: Track, s: Settings, p_start: float) -> str | None:
    """Why the walk is over (None: it goes on)."""
    if not track.started:
        return None
    if not track.points:
        return "start failed"
    if track.accepted >= s.max_points:
        return "max_points"
    p = track.points[-1][0]
    if p == s.to:
        return "reached"
    lo, hi = sorted((p_start, s.to))
    span = hi - lo
    if not lo - 1e-9 * span <= p <= hi + 1e-9 * span:
        return "left the range (turned back past the start)"
    ds_max = math.sqrt(2.0) * abs(s.step)
    if track.ds is not None and track.ds < s.min_step_factor * ds_max:
        return "step below minimum"
    if track.ds is None and track.first is not None and abs(track.first) < s.min_step_factor * abs(s.step):
        return "step below minimum"
    return None


def _work(a: Attempt) -> int:
    return a.iterations if a.control is None else a.control


def _controlled(ds: float, iterations: int, s: Settings, deviation: float | None = None) -> float:
    factor = math.sqrt(s.target_iterations / max(iterations, 1))
    if deviation is not None and deviation > 0:  # the secant's error is ~ curvature ds^2: its
        factor = min(factor, math.sqrt(s.target_deviation / deviation))  # relative size ~ ds
    return min(ds * min(max(factor, 0.5), 1.5), math.sqrt(2.0) * abs(s.step))


def advance(track: Track, s: Settings, p_start: float, correct: Callable, weights,
            free: Callable | None = None, tangent: Callable | None = None) -> tuple[Track, list[Step]]:
    """One accepted point or one failed attempt (module docstring): the new track and its records.
    ``free(phi_pred, p_pred, t_phi, t_p, theta)``: a corrector with p free (an Attempt on the
    hyperplane), used instead of the scalar iteration where |t_p| < ``turn``; ``tangent(p, phi)``:
    dphi/dp at the start (or None), which makes the first step a tangent one (``_first_tangent``)."""
    if not track.started:
        a = correct(p_start, None)
        new = replace(track, started=True, first=s.step)
        new = new.push(a.p, a.phi) if a.converged else new
        return new, [Step(a, a.converged, "start", 1, abs(s.step), None)]
    if len(track.points) == 1:
        p0, phi0 = track.points[0]
        first = track.first
        p1 = p0 + first
        if (p1 - s.to) * math.copysign(1.0, s.step) > 0:
            p1 = s.to
        d = tangent(p0, phi0) if tangent is not None and free is not None else None
        if d is not None:
            return _first_tangent(track, s, free, weights, p0, phi0, p1 - p0, d)
        a = correct(p1, phi0)
        if not a.converged:
            new = replace(track, first=first / 2)
            return new, [Step(a, False, "natural", 1, abs(first / 2), None)]
        new = _after_first(track, s, weights, p0, phi0, p1, a)
        return new, [Step(a, True, "natural", 1, new.ds, new.theta)]
    (pa, phia), (pb, phib) = track.points
    theta, ds = track.theta, track.ds
    dphi, dp = phib - phia, pb - pa
    length = math.hypot(theta * norm_w(weights, dphi), dp)
    t_phi, t_p = dphi / length, dp / length
    final = False
    towards = (s.to - pb) * t_p > 0
    if towards and abs(s.to - pb) <= ds * abs(t_p):
        ds, final = abs(s.to - pb) / abs(t_p), True
    phi_pred, p_pred = phib + ds * t_phi, pb + ds * t_p
    if final or abs(t_p) >= s.turn:
        a = correct(s.to if final else p_pred, phi_pred)
        dev = _deviation(a, phi_pred, p_pred, theta, ds, weights) if a.converged else None
        if not a.converged or dev > s.max_deviation:  # half the ds used (clipped at the end: no repeat)
            return replace(track, ds=ds / 2), [Step(a, False, "natural", 1, ds / 2, theta, deviation=dev)]
        new = replace(track.push(a.p, a.phi), ds=_controlled(track.ds, _work(a), s, dev))
        return new, [Step(a, True, "natural", 1, new.ds, theta, deviation=dev)]
    if free is not None:
        start = None if s.predict is None else s.predict(phia, phib, ds / length)
        return _free(track, s, free, weights, theta, ds, t_phi, t_p, phi_pred, p_pred, start)
    return _arclength(track, s, correct, weights, theta, ds, t_phi, t_p, phi_pred, p_pred)


def _first_tangent(track, s, free, weights, p0, phi0, dp, d):
    """The first step along the start's tangent (d = dphi/dp there), p free: the prediction
    u0 + dp (d, 1) (p predicted at p0 + dp, the natural step's), the corrector on the hyperplane
    through it orthogonal to the tangent, in the metric of theta_t = 1 / |d|_w (the tangent's field
    and parameter parts counting equally). The point accepted, theta and ds are set from it as after
    a natural first step (theta |dphi_1| = |dp_1|, the module docstring), so the walk goes on as one
    started naturally would. A natural first step (p fixed, the previous field) fails near a fold,
    where the fixed-p Jacobian is nearly singular: measured on a meridian cup 0.004 below its fold in v
    (eps 0.04, Newton-Krylov), dv = 1e-3 not converged in 25 bordered Newton steps (then the fixed-p
    minimiser, 525 iterations), dv = 2e-4 in 22; along the tangent dv = 1e-3 in 12. A failure (not
    converged, or farther than ``max_deviation`` from the prediction) halves dp, as a natural one's."""
    nd = norm_w(weights, d)
    theta_t = 1.0 / nd if nd > 0 else 1.0
    sign = math.copysign(1.0, dp)
    d = np.asarray(d, float)
    t_phi, t_p = sign * d / math.sqrt(2.0), sign / math.sqrt(2.0)
    ds_t = math.sqrt(2.0) * abs(dp)
    phi_pred, p_pred = phi0 + dp * d, p0 + dp
    a = free(phi_pred, p_pred, t_phi, t_p, theta_t)
    dev = _deviation(a, phi_pred, p_pred, theta_t, ds_t, weights) if a.converged else None
    if not a.converged or dev > s.max_deviation or a.p == p0:
        new = replace(track, first=track.first / 2)
        return new, [Step(a, False, "arclength", 1, abs(track.first / 2), None, deviation=dev)]
    N = theta_t**2 * float(np.dot(weights, (a.phi - phi_pred) * t_phi)) + (a.p - p_pred) * t_p
    new = _after_first(track, s, weights, p0, phi0, a.p, a)
    return new, [Step(a, True, "arclength", 1, new.ds, new.theta, N / ds_t, dev)]


def _after_first(track, s, weights, p0, phi0, p1, a):
    """The track once the first step's point (p1, a.phi) is accepted: theta with theta |dphi_1| =
    |dp_1| (module docstring) and ds from it, under the step control."""
    dphi = norm_w(weights, a.phi - phi0)
    theta = abs(p1 - p0) / dphi if dphi > 0 else 1.0
    ds = math.hypot(theta * dphi, p1 - p0)
    return replace(track.push(p1, a.phi), theta=theta, ds=_controlled(ds, _work(a), s))


def _free(track, s, free, weights, theta, ds, t_phi, t_p, phi_pred, p_pred, start=None):
    """The pseudo-arclength corrector with p free (module docstring): one call (from ``start`` where
    ``Settings.predict`` gives one, on the hyperplane through the linear prediction either way), then
    the same acceptance as a natural step (converged, near the prediction), and the hyperplane residual."""
    a = free(phi_pred, p_pred, t_phi, t_p, theta) if start is None else \
        free(phi_pred, p_pred, t_phi, t_p, theta, start=start)
    if not a.converged:
        return replace(track, ds=ds / 2), [Step(a, False, "arclength", 1, ds / 2, theta)]
    N = theta**2 * float(np.dot(weights, (a.phi - phi_pred) * t_phi)) + (a.p - p_pred) * t_p
    dev = _deviation(a, phi_pred, p_pred, theta, ds, weights)
    if dev > s.max_deviation:
        return replace(track, ds=ds / 2), [Step(a, False, "arclength", 1, ds / 2, theta, N / ds, dev)]
    nearer = dev if start is None else min(dev, _deviation(a, start, p_pred, theta, ds, weights))
    new = replace(track.push(a.p, a.phi), ds=_controlled(track.ds, _work(a), s, nearer))
    return new, [Step(a, True, "arclength", 1, new.ds, theta, N / ds, dev)]


def _arclength(track, s, correct, weights, theta, ds, t_phi, t_p, phi_pred, p_pred):
    """The pseudo-arclength corrector (module docstring): a scalar Newton/secant iteration on p."""
    def condition(a):
        return theta**2 * float(np.dot(weights, (a.phi - phi_pred) * t_phi)) + (a.p - p_pred) * t_p

    trials: list[tuple[float, float, Attempt]] = []
    p = p_pred
    for k in range(s.max_arc_solves):
        a = correct(p, phi_pred)
        if not a.converged:
            return replace(track, ds=ds / 2), [Step(a, False, "arclength", k + 1, ds / 2, theta)]
        N = condition(a)
        trials.append((p, N, a))
        if abs(N) <= s.arc_tol * ds:
            break
        if len(trials) == 1:
            p = p - N * math.copysign(max(abs(t_p), 0.1), t_p)  # Newton, dN/dp ~ 1 / t_p (bounded)
        else:
            (p1, N1, _), (p2, N2, _) = trials[-2], trials[-1]
            p = p2 - N2 * (p2 - p1) / (N2 - N1) if N2 != N1 else p2 - N2 * t_p
    p_best, N_best, a = min(trials, key=lambda tr: abs(tr[1]))
    dev = _deviation(a, phi_pred, p_pred, theta, ds, weights)
    if abs(N_best) > 0.5 * ds or dev > s.max_deviation:  # the hyperplane not reached, or another branch
        return replace(track, ds=ds / 2), [Step(a, False, "arclength", len(trials), ds / 2, theta,
                                                N_best / ds, dev)]
    new = replace(track.push(a.p, a.phi), ds=_controlled(track.ds, _work(a), s, dev))
    return new, [Step(a, True, "arclength", len(trials), new.ds, theta, N_best / ds, dev)]


def _deviation(a: Attempt, phi_pred, p_pred: float, theta: float, ds: float, weights) -> float:
    return math.hypot(theta * norm_w(weights, a.phi - phi_pred), a.p - p_pred) / ds


def walk(s: Settings, p_start: float, correct: Callable, weights, track: Track | None = None,
         record: Callable[[Step], None] | None = None, free: Callable | None = None,
         stop: Callable[[Track], str | None] | None = None,
         tangent: Callable | None = None) -> tuple[Track, str]:
    """Advance until ``finished`` (or ``stop(track)`` gives a reason: e.g. the branch has joined a
    known one, ``branch.tree``); ``record`` sees every attempt as it happens; ``free``: the
    corrector with p free, ``tangent``: the start's dphi/dp (``advance``). Returns the final track
    and why it stopped."""
    track = track or Track()
    while (why := finished(track, s, p_start) or (stop(track) if stop is not None and track.points else None)) is None:
        track, steps = advance(track, s, p_start, correct, weights, free, tangent)
        for st in steps:
            if record is not None:
                record(st)
    return track, why


@dataclass
class _Replay:
    """Rebuild a ``Track`` from recorded (p, phi or None, accepted, arc_step, theta) in order."""

    first: float
    track: Track = field(default_factory=Track)

    def feed(self, p: float, phi, accepted: bool, arc_step: float, theta: float | None) -> None:
        t = replace(self.track, started=True)
        if accepted:
            t = t.push(p, phi)
        if t.accepted >= 2 or (theta is not None and accepted):
            t = replace(t, ds=arc_step, theta=theta)
        elif t.ds is not None:
            t = replace(t, ds=arc_step)
        else:
            t = replace(t, first=math.copysign(arc_step, self.first))
        self.track = t


def replay(first_step: float, records) -> Track:
    """The track after ``records`` (dicts with p, phi, accepted, arc_step, theta), as ``advance``
    would have left it: the resume of a killed walk."""
    r = _Replay(first_step)
    for rec in records:
        r.feed(rec["p"], rec["phi"], rec["accepted"], rec["arc_step"], rec["theta"])
    return r.track
