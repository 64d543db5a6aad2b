"""A branch followed from its branch point by pseudo-arclength, p free, to a target value of p.

``branch.switch.first_point`` finds the *first* point of a bifurcating branch; a minimiser then walks
it at fixed p. That fails where the new branch leaves the branch point on the side where the parent
is still stable (a subcritical pitchfork): there the new branch is a saddle, and a minimiser started
off the unstable parent falls to whatever minimum lies below (at the vesicle's odd branch point in
c0 at v = 0.62: a torus or two nested spheres, never the cup; ``branch.detour``). Here the branch is
followed as a curve of KKT points, whatever their inertia:

1. **switch**: the point on the hyperplane <u - u*, v>_w = a through u* + a v, p free (the amplitude
   equation of ``branch.switch``; v the critical mode, M-normalised), from the predictor (u* + a v,
   p*); a failure (no convergence, or a point ``accept`` refuses) halves a, at most ``MAX_TRIES``
   times;
2. **follow**: the secant predictor (u_k, p_k) + ds t, t the unit secant of the last two points in
   the metric theta^2 <., .>_w + dp^2, and Newton onto the hyperplane through the prediction
   orthogonal to t (Keller's pseudo-arclength: folds in p pass, the sign of dp/ds is free). A step
   that fails or that ``accept`` refuses (e.g. the shape left its form: a torus) halves ds; Newton
   taking at most ``GROW_BELOW`` steps grows it by ``GROW``, more than ``SHRINK_ABOVE`` shrinks it by as much;
3. **land**: where p passes ``target`` between two points, Newton at p = target (``fixed``) from
   their linear interpolation.

``corrector``: ``solve(phi_pred, p_pred, lam_pred, t_phi, t_p, theta)`` and ``fixed(phi0, p, lam0)``
returning an object with phi, p, lam, converged, iterations (``branch.bordered.BorderedCorrector``,
``Newton``). The points are KKT points of the bordered system, not certified; the caller certifies
the landing (a minimiser from a Newton-converged point takes 0-1 iterations there).
``tests/branch/test_emanate.py`` runs it on a closed-form subcritical pitchfork with a fold.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from vesicle_opt.errors import InputError

log = logging.getLogger(__name__)

MAX_TRIES = 6  # switch amplitudes a, a/2, ... a/32 (as ``branch.switch``)
GROW, GROW_BELOW, SHRINK_ABOVE = 1.6, 6, 10  # Newton steps: ds grows after at most a fifth of the
# corrector's 30 (``bordered.MAX_NEWTON``), shrinks after more than a third: the quadratic phase from a
# close prediction, or the edge of its basin


@dataclass(frozen=True)
class Followed:
    """The followed branch: ``points`` (phi, p, lam, Newton steps) from the branch point's switch on,
    ``end`` the point at p = target (None: not reached), ``stopped`` why not, ``amplitude`` of the switch,
    ``rejected`` steps refused (not converged or not accepted), ``seconds`` CPU."""

    points: list = field(repr=False)
    end: Any = field(repr=False)
    stopped: str | None
    amplitude: float | None
    rejected: int
    seconds: float

    @property
    def ps(self) -> list[float]:
        return [float(q.p) for q in self.points]

    @property
    def turns(self) -> list[int]:
        """Indices k where p turned (a fold in p between points k - 1, k, k + 1)."""
        d = np.sign(np.diff(self.ps))
        return [k + 1 for k in range(len(d) - 1) if d[k] * d[k + 1] < 0]


def _ok(nw, accept) -> bool:
    return bool(nw.converged) and np.all(np.isfinite(nw.phi)) and (accept is None or bool(accept(nw)))


def follow(corrector, phi_star, p_star: float, lam_star, mode, amplitude: float, weights, target: float, *,
           accept: Callable | None = None, theta: float = 1.0, ds: float | None = None, ds_max: float = math.inf,
           ds_min: float = 1e-4, max_steps: int = 500, budget_s: float = math.inf) -> Followed:
    """The branch leaving (phi_star, p_star) along ``mode`` (module docstring), followed until p passes
    ``target``. ``accept(newton) -> bool``: a point's guard (None: all); ``ds``: the first arclength step
    (None: ``amplitude``); ``ds_min``: below this the walk stops; ``budget_s``: CPU seconds."""
    if not (isinstance(amplitude, (int, float)) and amplitude > 0 and math.isfinite(amplitude)):
        raise InputError("amplitude", f"a positive number, got {amplitude!r}")
    if not (math.isfinite(target) and theta > 0):
        raise InputError("target", f"finite target and theta > 0, got {target!r}, {theta!r}")
    t0 = time.process_time()
    w = np.asarray(weights, float)
    v = np.asarray(mode, float)
    v = v / math.sqrt(float(w @ (v * v)))
    phi_star = np.asarray(phi_star, float)
    lam_star = np.asarray(lam_star, float)
    a, first = float(amplitude), None
    for _ in range(MAX_TRIES):
        nw = corrector.solve(phi_star + a * v, p_star, lam_star, v, 0.0, 1.0)
        if _ok(nw, accept):
            first = nw
            break
        a /= 2
    if first is None:
        return Followed([], None, f"no switch in {MAX_TRIES} amplitudes from {amplitude:g}", None, MAX_TRIES,
                        time.process_time() - t0)
    prev = type("Star", (), {"phi": phi_star, "p": float(p_star), "lam": lam_star})()
    pts, rejected = [first], 0
    ds = a if ds is None else float(ds)
    side = math.copysign(1.0, first.p - target) if first.p != target else 0.0

    def done(why, end=None):
        return Followed(pts, end, why, a, rejected, time.process_time() - t0)

    while len(pts) < max_steps:
        if time.process_time() - t0 > budget_s:
            return done(f"CPU budget {budget_s:g} s spent at p = {pts[-1].p:g}")
        b, c = (prev if len(pts) == 1 else pts[-2]), pts[-1]
        dphi, dp = c.phi - b.phi, c.p - b.p
        norm = math.sqrt(theta**2 * float(w @ (dphi * dphi)) + dp**2)
        t_phi, t_p = dphi / norm, dp / norm
        dlam = (np.asarray(c.lam, float) - np.asarray(b.lam, float)) / norm
        while True:
            nw = corrector.solve(c.phi + ds * t_phi, c.p + ds * t_p, np.asarray(c.lam, float) + ds * dlam,
                                 t_phi, t_p, theta)
            if _ok(nw, accept):
                break
            rejected += 1
            log.info("emanate: step ds = %.3g refused (converged %s)", ds, nw.converged)
            ds /= 2
            if ds < ds_min:
                return done(f"step below {ds_min:g} at p = {c.p:g}")
        pts.append(nw)
        log.info("emanate: p = %.6g, %d Newton steps, ds %.3g", nw.p, nw.iterations, ds)
        if side and math.copysign(1.0, nw.p - target) != side or nw.p == target:
            s = (target - c.p) / (nw.p - c.p)
            lam0 = (1 - s) * np.asarray(c.lam, float) + s * np.asarray(nw.lam, float)
            end = corrector.fixed((1 - s) * c.phi + s * nw.phi, target, lam0)
            if _ok(end, accept):
                return done(None, end)
            return done(f"Newton at p = {target:g} between p = {c.p:g} and {nw.p:g} failed")
        if nw.iterations <= GROW_BELOW:
            ds = min(ds * GROW, ds_max)
        elif nw.iterations > SHRINK_ABOVE:
            ds /= GROW
    return done(f"{max_steps} points without reaching p = {target:g}")
