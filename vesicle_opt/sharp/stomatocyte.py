"""The stomatocyte branch of the spontaneous-curvature model at any c0 (sharp interface), its fold in
v and its crossing with the oblate branch: the references of the phase diagram's c0 = 0 row
(Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991), Fig. 8: the oblate/stomatocyte transition
near v = 0.59, the stomatocyte branch ending in a fold near v = 0.66), in their units (f = F / 8 pi
kappa, v; ``sharp.spontaneous``).

The shapes are ``sharp.spontaneous``'s (tangent angle psi = s + sum_{j=1..N} a_j sin(j s), the meridian
closed by the constraint r(pi) = 0, not by symmetry); this module adds

- ``cup_start``: a stomatocyte-like start built from three circular arcs (an inner cap of radius r_in
  turned inward, a rim of radius rho, the outer cap of radius 1) whose psi, linear in arc length on
  each arc, is fitted by the sine series; the outer cap's angle is set so the arcs close
  (r_in sin alpha + rho (sin gamma + sin alpha) = sin gamma). It is a START, not the answer: the KKT
  Newton below moves it onto the branch;
- ``newton``: Newton's method on the KKT system of min f s.t. v(a) = v, r(pi) = 0,

      G(a, lam_v, lam_c; v) = (grad f - lam_v grad v - lam_c grad closure, v(a) - v, closure(a)) = 0,

  its Jacobian in (a, lam) the bordered Hessian of the Lagrangian (central differences, step
  ``FD_STEP``, of the complex-step gradients), with a backtracking step on |G|. It converges to any
  stationary point (minimum, saddle), so it follows both sides of a fold;
- ``continue_branch``: pseudo-arclength continuation of G = 0 in (a, lam, v), the tangent from the
  null vector of [dG/d(a, lam), dG/dv]; it passes the fold where v turns;
- ``fold``: the turning point, where the tangent's v component vanishes (a secant on the arclength
  from the last point before the turn);
- ``crossing``: where the stomatocyte's f equals the oblate's (the up-down symmetric solution at the
  same v: the even coefficients of a ``sharp.axisymmetric`` oblate), a secant in v.

numpy and scipy only; no code shared with the phase-field path.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from vesicle_opt.sharp import axisymmetric, spontaneous
from vesicle_opt.sharp.spontaneous import Geometry, Shape

FD_STEP = 1e-6  # central differences of exact (complex-step) gradients: error ~1e-12 x third derivative
TOL = 1e-10  # |G| at which Newton stops; G's entries are O(1) (f, v ~ 1 at the sphere)


@dataclasses.dataclass(frozen=True)
class Point:
    """A stationary shape: coefficients ``a``, multipliers ``lam`` (v, closure), ``v``, ``f``,
    the unit tangent ``t`` of the branch in (a, lam, v) (None off a continuation), the residual."""
    a: np.ndarray
    lam: np.ndarray
    v: float
    f: float
    t: np.ndarray | None
    residual: float

    @property
    def asymmetry(self) -> float:
        """|sum of the odd coefficients|: 0 for an up-down symmetric shape."""
        return float(np.abs(self.a[0::2]).sum())

    def meridian(self, m: int = 512) -> tuple[np.ndarray, np.ndarray]:
        """(r, z) from pole to pole (m + 1 points), R0 = 1 (``sharp.spontaneous.Shape.meridian``)."""
        return Shape(self.v, self.f, 0.0, self.a, (0.0, 0.0), self.residual, True).meridian(m)


class NotConverged(RuntimeError):
    """Newton did not reach ``TOL``: no point is returned."""


def cup_start(n_modes: int, r_in: float = 0.5, rho: float = 0.2, alpha: float = math.pi / 2 + 0.6,
              m: int = 4000) -> np.ndarray:
    """The sine coefficients of a three-arc cup (see the module docstring): inner cap angle
    ``alpha``, radii ``r_in`` (inner cap) and ``rho`` (rim) in units of the outer cap's radius."""
    s_gam = (r_in + rho) * math.sin(alpha) / (1 - rho)
    if not (0 < r_in < 1 and 0 < rho < 1 and abs(s_gam) < 1):
        raise ValueError(f"no closed three-arc cup with r_in={r_in}, rho={rho}, alpha={alpha}")
    gam = math.asin(s_gam)
    lengths = np.array([r_in * alpha, rho * (gam + alpha), math.pi - gam])
    ell = np.linspace(0, lengths.sum(), m)
    b1, b2 = lengths[0], lengths[0] + lengths[1]
    psi = np.where(ell < b1, -ell / r_in, np.where(ell < b2, -alpha + (ell - b1) / rho, gam + (ell - b2)))
    s = math.pi * ell / lengths.sum()
    A = np.sin(np.outer(s, np.arange(1, n_modes + 1)))
    return np.linalg.lstsq(A, psi - s, rcond=None)[0]


class KKTSystem:
    """G, its Jacobian and v, f at (a, lam, v) for one (N, c0)."""

    def __init__(self, n_modes: int, c0: float, m: int | None = None):
        self.g, self.c0, self.n = Geometry(n_modes, m), float(c0), n_modes

    def values(self, a):
        return [float(np.real(q)) for q in self.g.all(a, self.c0)]

    def residual(self, a, lam, v):
        gf, gv, gc = self.g.grads(a, self.c0)
        _, vv, close = self.values(a)
        return np.concatenate([gf - lam[0] * gv - lam[1] * gc, [vv - v, close]])

    def jacobian(self, a, lam):
        """dG/d(a, lam) (N + 2 square) and dG/dv (the column -e_v)."""
        n = self.n
        H = np.empty((n, n))
        for j in range(n):
            d = np.zeros(n)
            d[j] = FD_STEP
            gp, gm = self.g.grads(a + d, self.c0), self.g.grads(a - d, self.c0)
            H[:, j] = ((gp[0] - lam[0] * gp[1] - lam[1] * gp[2]) - (gm[0] - lam[0] * gm[1] - lam[1] * gm[2])) / (2 * FD_STEP)
        _, gv, gc = self.g.grads(a, self.c0)
        J = np.zeros((n + 2, n + 2))
        J[:n, :n] = (H + H.T) / 2
        J[:n, n], J[:n, n + 1] = -gv, -gc
        J[n, :n], J[n + 1, :n] = gv, gc
        dv = np.zeros(n + 2)
        dv[n] = -1.0
        return J, dv


def _multipliers(sys: KKTSystem, a) -> np.ndarray:
    gf, gv, gc = sys.g.grads(a, sys.c0)
    return np.linalg.lstsq(np.column_stack([gv, gc]), gf, rcond=None)[0]


def _damped(step_fn, x, norm0, maxit=40):
    """Newton iterations x <- x + t dx with t halved until |G| decreases; returns (x, |G|)."""
    res = norm0
    for _ in range(maxit):
        if res < TOL:
            return x, res
        dx = step_fn(x)
        t = 1.0
        while t > 1e-4:
            trial = x + t * dx
            r = step_fn.norm(trial)
            if np.isfinite(r) and r < res:
                x, res = trial, r
                break
            t /= 2
        else:
            break
    return x, res


def newton(a0, v: float, c0: float = 0.0, n_modes: int | None = None, lam0=None) -> Point:
    """The stationary shape at reduced volume ``v`` from the coefficients ``a0`` (padded or cut to
    ``n_modes``): damped Newton on G. Raises ``NotConverged`` above ``TOL``."""
    n = n_modes or len(a0)
    a = np.zeros(n)
    a[: min(n, len(a0))] = np.asarray(a0, float)[:n]
    sys = KKTSystem(n, c0)
    lam = _multipliers(sys, a) if lam0 is None else np.asarray(lam0, float)

    def step(x):
        J, _ = sys.jacobian(x[:n], x[n:])
        return np.linalg.solve(J, -sys.residual(x[:n], x[n:], v))
    step.norm = lambda x: _norm(sys.residual(x[:n], x[n:], v))
    x, res = _damped(step, np.concatenate([a, lam]), step.norm(np.concatenate([a, lam])))
    if res >= TOL:
        raise NotConverged(f"KKT residual {res:.2e} at v = {v}")
    f, vv, _ = sys.values(x[:n])
    return Point(x[:n], x[n:], vv, f, None, res)


def _norm(r) -> float:
    with np.errstate(invalid="ignore", over="ignore"):
        val = float(np.linalg.norm(r))
    return val if np.isfinite(val) else math.inf


def _tangent(sys: KKTSystem, p: Point, previous: np.ndarray | None) -> np.ndarray:
    J, dv = sys.jacobian(p.a, p.lam)
    full = np.column_stack([J, dv])
    t = np.linalg.svd(full)[2][-1]
    if previous is not None and t @ previous < 0:
        t = -t
    return t


def arclength_step(sys: KKTSystem, p: Point, ds: float) -> Point:
    """The point at pseudo-arclength ``ds`` along p.t: Newton on (G, t . (y - y_pred)) in y = (a, lam, v)."""
    n = sys.n
    y0 = np.concatenate([p.a, p.lam, [p.v]])
    pred = y0 + ds * p.t

    def res(y):
        return np.concatenate([sys.residual(y[:n], y[n:n + 2], y[-1]), [p.t @ (y - pred)]])

    def step(y):
        J, dv = sys.jacobian(y[:n], y[n:n + 2])
        return np.linalg.solve(np.vstack([np.column_stack([J, dv]), p.t]), -res(y))
    step.norm = lambda y: _norm(res(y))
    y, r = _damped(step, pred, step.norm(pred), maxit=20)
    if r >= TOL:
        raise NotConverged(f"arclength corrector: residual {r:.2e} after ds = {ds}")
    f, vv, _ = sys.values(y[:n])
    q = Point(y[:n], y[n:n + 2], float(y[-1]), f, None, r)
    return dataclasses.replace(q, t=_tangent(sys, q, p.t))


def continue_branch(start: Point, c0: float, ds: float, steps: int, direction: float = 1.0,
                    stop=lambda p: False) -> list[Point]:
    """``steps`` pseudo-arclength steps of length ``ds`` from ``start`` (v increasing at first when
    ``direction`` > 0); the step is halved (down to ds / 64) where the corrector fails. Stops early when
    ``stop(point)``."""
    sys = KKTSystem(len(start.a), c0)
    p = dataclasses.replace(start, t=_tangent(sys, start, None))
    if p.t[-1] * direction < 0:
        p = dataclasses.replace(p, t=-p.t)
    out = [p]
    for _ in range(steps):
        h = ds
        while True:
            try:
                p = arclength_step(sys, p, h)
                break
            except NotConverged:
                h /= 2
                if h < ds / 64:
                    return out
        out.append(p)
        if stop(p):
            break
    return out


def fold(points: list[Point], c0: float) -> Point:
    """The turning point in v of a continued branch: between the last two points whose tangents' v
    components differ in sign, the arclength at which that component vanishes (secant iteration)."""
    sys = KKTSystem(len(points[0].a), c0)
    for p, q in zip(points, points[1:]):
        if p.t[-1] * q.t[-1] <= 0:
            break
    else:
        raise ValueError("no fold among these points (the tangent's v component keeps its sign)")
    y = lambda r: np.concatenate([r.a, r.lam, [r.v]])
    s0, s1 = 0.0, float(p.t @ (y(q) - y(p)))
    g0, g1 = p.t[-1], q.t[-1]
    best = q
    for _ in range(30):
        s2 = s1 - g1 * (s1 - s0) / (g1 - g0)
        best = arclength_step(sys, p, s2)
        if abs(best.t[-1]) < 1e-10:
            break
        s0, g0, s1, g1 = s1, g1, s2, best.t[-1]
    return best


def oblate_point(v: float, c0: float, n_modes: int, start=None) -> Point:
    """The up-down symmetric (oblate) stationary shape at v: Newton from ``start`` or from
    ``sharp.axisymmetric``'s oblate (its sin(2 j s) coefficients are the even wavenumbers here)."""
    if start is None:
        ref = axisymmetric.solve(v, "oblate", n_modes // 2, second_order=False)
        start = np.zeros(n_modes)
        start[1::2] = ref.a[: n_modes // 2]
    return newton(start, v, c0, n_modes)


def crossing(points: list[Point], c0: float, oblate_start=None) -> tuple[float, float]:
    """(v, f) where the branch ``points`` (not passing a fold between the bracketing pair) meets the
    up-down symmetric branch: f_stomatocyte(v) - f_oblate(v) = 0 by a secant in v, each side solved by
    ``newton`` warm-started from the nearest point."""
    n = len(points[0].a)
    diffs, obl = [], {}
    prev = oblate_start
    for p in points:
        o = oblate_point(p.v, c0, n, prev)
        prev = o.a
        obl[id(p)] = o
        diffs.append(p.f - o.f)
    for i in range(len(points) - 1):
        if diffs[i] * diffs[i + 1] <= 0:
            break
    else:
        raise ValueError("the branch does not meet the oblate between these points")
    p, q = points[i], points[i + 1]
    v0, v1, d0, d1 = p.v, q.v, diffs[i], diffs[i + 1]
    sa, oa = p.a, obl[id(p)].a
    for _ in range(40):
        if d1 == d0:  # converged to round-off (or a flat difference: the last iterate is as good)
            return float(v1), float(newton(sa, v1, c0, n).f)
        v2 = v1 - d1 * (v1 - v0) / (d1 - d0)
        s2, o2 = newton(sa, v2, c0, n), newton(oa, v2, c0, n)
        d2 = s2.f - o2.f
        if abs(d2) < 1e-12 or abs(v2 - v1) < 1e-13:
            return float(v2), float(s2.f)
        v0, d0, v1, d1, sa, oa = v1, d1, v2, d2, s2.a, o2.a
    raise NotConverged("crossing secant did not converge")


def start_point(v: float = 0.62, c0: float = 0.0, n_modes: int = 32) -> Point:
    """A point of the stomatocyte branch at ``v`` (the lower side of the fold at c0 = 0): the three-arc
    cup relaxed by SLSQP with 16 modes (Newton from the cup itself diverges), then Newton at 24 and
    ``n_modes`` modes."""
    a = spontaneous.solve(v, c0, cup_start(16), 16).a
    for n in sorted({min(24, n_modes), n_modes}):
        a = newton(a, v, c0, n).a
    return newton(a, v, c0, n_modes)


def reference(c0: float = 0.0, n_modes: int = 32, ds: float = 0.03, v_low: float = 0.57) -> dict:
    """The stomatocyte branch's fold and its crossing with the oblate branch: from ``start_point``,
    continued up in v past the fold (``fold``), and down to ``v_low`` (``crossing``). Returns
    {"fold": (v, f), "crossing": (v, f), "lower": [(v, f), ...], "upper": [(v, f), ...], "up_walk":
    [(v, f, lam_v), ...] in walk order} (lam_v = df/dv, the volume multiplier)."""
    p = start_point(0.62, c0, n_modes)
    up = continue_branch(p, c0, ds, 80, 1.0, stop=lambda q: q.t[-1] < 0 and q.v < 0.62)
    turn = fold(up, c0)
    down = continue_branch(p, c0, ds, 40, -1.0, stop=lambda q: q.v < v_low)
    x = crossing(down, c0)
    lower = sorted([(q.v, q.f) for q in down] + [(q.v, q.f) for q in up if q.t[-1] > 0])
    upper = sorted((q.v, q.f) for q in up if q.t[-1] <= 0)
    return {"fold": (turn.v, turn.f), "crossing": x, "lower": lower, "upper": upper, "n_modes": n_modes,
            "up_walk": [(q.v, q.f, float(q.lam[0])) for q in up]}
