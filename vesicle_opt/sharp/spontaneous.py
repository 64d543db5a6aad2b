"""Axisymmetric vesicles of the spontaneous-curvature model without up-down symmetry, any c0: the
sharp-interface reference for pears, stomatocytes and the c0 != 0 phase diagram (Seifert, Berndl &
Lipowsky, Phys. Rev. A 44, 1182 (1991)), in their units: f = F / 8 pi kappa with
F = (kappa/2) int (C1 + C2 - C0)^2 dA, c0 = C0 R0, R0 = sqrt(A / 4 pi), v = 6 sqrt(pi) V / A^(3/2).

Method: as ``sharp.axisymmetric`` (spectral direct minimisation; this module shares no code with it
nor with the phase-field path), but with every wavenumber in the tangent angle,

    psi(s) = s + sum_{j=1..N} a_j sin(j s),   s in [0, pi] from the north pole to the south pole,

so the shape is not mirror-symmetric about its equator and the meridian does not close by
construction: r(pi) = int_0^pi cos psi ds = 0 is a constraint (``closure``), beside v = v0. The arc
length is pi; f is scale-free in R0 units, (R0 (k1 + k2) - c0)^2 integrated over dA / R0^2:

    f = (1 / 16 pi) 2 pi int_0^pi (k1 + k2 - c0 / R0)^2 r ds,   R0 = sqrt(area / 4 pi),

k1 = psi', k2 = sin psi / r (= psi' at the poles); the sphere (a = 0, arc pi: R0 = 1) has
f = (1 - c0/2)^2. On the doubled interval [0, 2 pi) psi - s is odd and 2 pi-periodic (sines), cos psi
even, so r (the antiderivative of cos psi, odd) is periodic exactly when the closure holds; the FFT
gives every quantity spectrally. Minimise f subject to (v, closure) by SLSQP with complex-step
gradients.

Checks (``tests/sharp/test_spontaneous.py``): the sphere's closed form for every c0; at c0 = 0 the
up-down symmetric prolate and oblate of ``sharp.axisymmetric`` (an independent code) from a start
with odd modes; spectral convergence in N; and ``budded_limit``, the two spheres joined by an ideal
neck (1/r1 + 1/r2 = c0, r1^2 + r2^2 = 1, v = r1^3 + r2^3, f = (1 - c0 r1/2)^2 + (1 - c0 r2/2)^2),
which bounds the pear branch; at c0 = 2.4 the up-down symmetric branch passes the published
pear/prolate crossing (v, f) = (0.746, 0.107) (f = 0.106768 here).

The pear branch at c0 = 2.4 is reached at v = 0.72 from the symmetric shape kicked along sin(3 s)
(amplitude 0.3; small kicks decay: the symmetric branch is stable to odd modes there, least odd
eigenvalue +0.12 at v = 0.725); it crosses the symmetric branch at (0.7416, 0.1043) (linear
interpolation between v = 0.740 and 0.746), the published (0.746, 0.107) within its reading error.
The stomatocyte branch: from the cup-shaped starts tried here
(psi - s = b sin s ((1 - cos s)/2)^p, b = 5, 6) SLSQP went back to the oblate (same f to 1e-15) or
left the shapes (area <= 0: reported not converged, NaN, never returned as a solution); from a
three-arc cup it reaches the branch, which ``sharp.stomatocyte`` follows through its fold by Newton
and pseudo-arclength continuation on these same shapes.

numpy and scipy only.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import optimize

CS_STEP = 1e-30  # complex step: exact derivatives to round-off
KKT_TOL = 1e-6  # SLSQP stops at relative KKT residuals 6e-10 .. 1.2e-7 here (measured, N = 6 .. 32 at
# v = 0.9, c0 = 1): a point is called converged 8x above the worst of them


@dataclasses.dataclass(frozen=True)
class Shape:
    """A computed vesicle: reduced volume ``v``, literature ``f``, ``c0`` (= C0 R0), the coefficients
    ``a`` of psi - s at wavenumbers 1..N, the multipliers (v, closure), the relative KKT residual,
    and ``asymmetry`` = |sum of the odd coefficients| (0: up-down symmetric)."""
    v: float
    f: float
    c0: float
    a: np.ndarray
    multipliers: tuple[float, float]
    kkt_residual: float
    converged: bool

    @property
    def asymmetry(self) -> float:
        return float(np.abs(self.a[0::2]).sum())

    def meridian(self, m: int = 512) -> tuple[np.ndarray, np.ndarray]:
        """(r, z) on [0, pi] (m + 1 points), scaled to R0 = 1."""
        g = Geometry(len(self.a), max(m, _grid(len(self.a))))
        r, z, _, _ = g.shape(self.a)
        scale = 1.0 / math.sqrt(g.area(self.a).real / (4 * math.pi))
        half = g.m // 2 + 1
        return scale * r[:half].real, scale * z[:half].real


def _grid(n_modes: int) -> int:
    return int(2 ** math.ceil(math.log2(max(256, 16 * n_modes))))


def _real_matmul(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    if np.iscomplexobj(x):
        return A @ x.real + 1j * (A @ x.imag)
    return A @ x


class Geometry:
    """f, v and the closure of psi = s + sum a_j sin(j s) on the doubled grid (complex-safe)."""

    def __init__(self, n_modes: int, m: int | None = None):
        self.n = n_modes
        self.m = m or _grid(n_modes)
        self.s = 2 * math.pi * np.arange(self.m) / self.m
        self.kj = np.arange(1, n_modes + 1, dtype=float)
        self.SIN = np.sin(np.outer(self.s, self.kj))
        self.COS = np.cos(np.outer(self.s, self.kj))
        k = np.fft.fftfreq(self.m, 1.0 / self.m)
        ik = 1j * k
        self.inv_ik = np.where(k != 0, 1 / np.where(k != 0, ik, 1), 0)
        # int_0^pi exp(i k s) ds: pi (k = 0), ((-1)^k - 1) / (i k) otherwise
        self.half_w = np.where(k == 0, math.pi, ((-1.0) ** np.abs(k) - 1) * self.inv_ik)
        self.poles = np.array([0, self.m // 2])

    def _split(self, fn, x):
        return fn(x.real) + 1j * fn(x.imag) if np.iscomplexobj(x) else fn(x)

    def half_integral(self, g):
        """int_0^pi g ds of a 2 pi-periodic grid function (axis 0), term-wise exact."""
        def one(x):
            G = np.fft.fft(x, axis=0) / self.m
            w = self.half_w.reshape((-1,) + (1,) * (x.ndim - 1))
            return np.sum(G.real * w.real - G.imag * w.imag, axis=0)
        return self._split(one, g)

    def cumulative(self, g):
        """int_0^s g: the mean times s plus the periodic antiderivative of the rest (axis 0)."""
        def one(x):
            G = np.fft.fft(x, axis=0)
            mean = G[0].real / self.m
            y = np.fft.ifft(G * self.inv_ik.reshape((-1,) + (1,) * (x.ndim - 1)), axis=0).real
            s = self.s.reshape((-1,) + (1,) * (x.ndim - 1))
            return y - y[0] + mean * s
        return self._split(one, g)

    def shape(self, a):
        """(r, z, psi, psi') on the grid; a of shape (N,) or (N, batch)."""
        ka = (self.kj * a.T).T
        s = self.s if a.ndim == 1 else self.s[:, None]
        psi = s + _real_matmul(self.SIN, a)
        dpsi = 1 + _real_matmul(self.COS, ka)
        return self.cumulative(np.cos(psi)), self.cumulative(-np.sin(psi)), psi, dpsi

    def area(self, a):
        return 2 * math.pi * self.half_integral(self.shape(a)[0])

    def all(self, a, c0: float):
        """(f, v, closure r(pi)) of a (real or complex; (N,) or (N, B))."""
        r, _, psi, dpsi = self.shape(a)
        safe = r.copy()
        safe[self.poles] = 1.0
        k2 = np.sin(psi) / safe
        k2[self.poles] = dpsi[self.poles]  # sin psi / r -> psi' on the axis
        area = 2 * math.pi * self.half_integral(r)
        R0 = np.sqrt(area / (4 * math.pi))
        f = 2 * math.pi * self.half_integral((dpsi + k2 - c0 / R0) ** 2 * r) / (16 * math.pi)
        V = math.pi * self.half_integral(r**2 * np.sin(psi))
        v = V / (4 * math.pi / 3 * R0**3)
        return f, v, r[self.m // 2]

    def grads(self, a, c0: float):
        X = a[:, None] + 1j * CS_STEP * np.eye(self.n)
        return tuple(q.imag / CS_STEP for q in self.all(X, c0))


def solve(v: float, c0: float, start: np.ndarray, n_modes: int | None = None, m: int | None = None) -> Shape:
    """The stationary shape of f at reduced volume ``v`` and closure, from the coefficients
    ``start`` (padded or cut to ``n_modes``): SLSQP with complex-step gradients."""
    if not 0 < v <= 1:
        raise ValueError(f"v must lie in (0, 1], got {v!r}")
    n = n_modes or len(start)
    g = Geometry(n, m)
    a0 = np.zeros(n)
    a0[: min(n, len(start))] = np.asarray(start, float)[:n]
    cache: dict = {}

    def ev(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = ([q.real for q in g.all(x, c0)], g.grads(x, c0))
        return cache[key]

    cons = [{"type": "eq", "fun": lambda x: ev(x)[0][1] - v, "jac": lambda x: ev(x)[1][1][None, :]},
            {"type": "eq", "fun": lambda x: ev(x)[0][2], "jac": lambda x: ev(x)[1][2][None, :]}]
    with np.errstate(invalid="ignore", divide="ignore"):  # a trial step may leave the shapes: NaN, refused
        opt = optimize.minimize(lambda x: ev(x)[0][0], a0, jac=lambda x: ev(x)[1][0], constraints=cons,
                                method="SLSQP", options={"ftol": 1e-15, "maxiter": 2000})
    a = opt.x
    with np.errstate(invalid="ignore", divide="ignore"):
        (f, vv, close), (gf, gv, gc) = ev(a)
    if not all(np.all(np.isfinite(q)) for q in (f, vv, close, gf, gv, gc)):  # left the shapes (area <= 0)
        nan = float("nan")
        return Shape(nan, nan, float(c0), a, (nan, nan), nan, False)
    C = np.column_stack([gv, gc])
    lam, *_ = np.linalg.lstsq(C, gf, rcond=None)
    scale = np.linalg.norm(gf) + np.abs(lam) @ np.linalg.norm(C, axis=0)
    kkt = float(max(np.linalg.norm(gf - C @ lam) / scale, abs(vv - v), abs(close)))
    return Shape(float(vv), float(f), float(c0), a, (float(lam[0]), float(lam[1])), kkt, bool(kkt < KKT_TOL))


def branch(vs, c0: float, start: np.ndarray, n_modes: int | None = None) -> list[Shape]:
    """Solves at the reduced volumes ``vs`` in order, each from the previous (``start`` the first's)."""
    out = []
    for v in vs:
        sol = solve(float(v), c0, start, n_modes)
        out.append(sol)
        start = sol.a
    return out


def budded_limit(c0: float) -> tuple[float, float, float, float]:
    """(v, f, r1, r2) of two spheres joined by an ideal neck at spontaneous curvature c0 > 2 (R0
    units): 1/r1 + 1/r2 = c0 (a stress-free neck), r1^2 + r2^2 = 1 (the area), v = r1^3 + r2^3,
    f = (1 - c0 r1/2)^2 + (1 - c0 r2/2)^2; r1 >= r2. With p = r1 r2, (r1 + r2) = c0 p and
    (r1 + r2)^2 = 1 + 2 p: c0^2 p^2 - 2 p - 1 = 0; real radii need (r1 + r2)^2 >= 4 p, i.e.
    c0 >= 2 sqrt 2 (ValueError below)."""
    p = (1 + math.sqrt(1 + c0 * c0)) / (c0 * c0)
    total = c0 * p
    disc = total * total - 4 * p
    if disc < 0:
        raise ValueError(f"no budded limit at c0 = {c0!r} (needs c0 >= 2 sqrt 2)")
    r1, r2 = (total + math.sqrt(disc)) / 2, (total - math.sqrt(disc)) / 2
    return r1**3 + r2**3, (1 - c0 * r1 / 2) ** 2 + (1 - c0 * r2 / 2) ** 2, r1, r2
