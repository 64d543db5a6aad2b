"""3D axisymmetric vesicles of the spontaneous-curvature (Helfrich) model at c0 = 0: the prolate and
oblate branches and their crossing, the sharp-interface reference of the 3D phase-field problem
(whose energy (3) tends to (sqrt 2/3) integral (k1 + k2)^2 dA).

Method: spectral DIRECT MINIMISATION of the axisymmetric bending energy at fixed reduced volume (not
shooting the shape equations). The meridian, from the north pole (s = 0) to the south pole (s = pi),
has arc length pi (the energy is scale-free, so the length is fixed and only the reduced volume is
constrained) and tangent angle

    psi(s) = s + sum_{j=1..N} a_j sin(2 j s),     r' = cos psi,  z' = -sin psi,

so psi(0) = 0 and psi(pi) = pi (smooth poles), and the even wavenumbers make the shape mirror-
symmetric about the equator, which closes it (r(pi) = 0) by construction: prolate and oblate
(discocyte) shapes have this symmetry; stomatocytes do not and are outside this class. On the doubled
interval [0, 2 pi) every quantity is a smooth periodic function (psi - s is odd and 2 pi-periodic, r
odd, sin psi / r even), so the FFT on M equispaced points gives them spectrally, r = integral cos psi
by the Fourier antiderivative, and integrals over [0, pi] by exact term-wise integration
(``_half_integral``). With k1 = psi' (meridional), k2 = sin psi / r (= psi' at the poles):

    W = 2 pi integral_0^pi (k1 + k2)^2 r ds,   area = 2 pi integral r ds,   V = pi integral r^2 sin psi ds,
    reduced energy e = W / (16 pi) (the sphere: 1),  reduced volume v = V / ((4 pi/3) (area/4 pi)^(3/2)).

Minimise e(a) subject to v(a) = v0 by SLSQP, gradients by the complex step (exact to round-off; the
FFTs, sin, cos and the division are analytic), from the one-mode start a_1 > 0 (prolate: sharper poles)
or a_1 < 0 (oblate); a branch warm-starts each point from the previous one. The second-order check is
the smallest eigenvalue of the Lagrangian's Hessian (finite differences of the complex-step gradient)
on the tangent space of the constraint, within this symmetric axisymmetric class.

Checks (``tests/sharp/test_axisymmetric.py``): the sphere (a = 0) gives e = v = 1 exactly; v -> 1,
where both branches tend to 1 with e - 1 = 2 (1 - v) + O((1 - v)^2) (the l = 2 mode of a quasi-sphere, see
``small_deformation_slope``); spectral convergence in N and M; the literature crossing.

numpy and scipy only: shares no code with the phase-field path.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
from scipy import optimize

CS_STEP = 1e-30  # complex step: derivative = Im f(x + i h) / h, exact to round-off for any small h


@dataclasses.dataclass(frozen=True)
class Axisymmetric:
    """A computed axisymmetric vesicle: reduced volume ``v``, ``reduced_energy``, ``branch``
    (prolate|oblate), the coefficients ``a`` of psi - s at wavenumbers 2, 4, ..., 2N, the volume
    multiplier ``lam`` (de/dv = lam along the branch), the relative KKT residual, the smallest
    reduced-Hessian eigenvalue, and the shape's aspect ``aspect`` = height / width (> 1 prolate)."""
    v: float
    reduced_energy: float
    branch: str
    a: np.ndarray
    lam: float
    kkt_residual: float
    min_eigenvalue: float
    aspect: float
    converged: bool

    def meridian(self, m: int = 512) -> tuple[np.ndarray, np.ndarray]:
        """(r, z) of the meridian on [0, pi] (m + 1 points), for the surface of area 4 pi."""
        g = _Geometry(len(self.a), max(m, _grid(len(self.a))))
        r, z, _, _ = g.shape(self.a)
        scale = math.sqrt(4 * math.pi / g.area(self.a).real)
        half = g.m // 2 + 1
        return scale * r[:half].real, scale * (z[:half] - z[:half].mean()).real


def _grid(n_modes: int) -> int:
    return int(2 ** math.ceil(math.log2(max(128, 16 * 2 * n_modes))))


class _Geometry:
    """The functionals of psi = s + sum a_j sin(2 j s) on the doubled grid (complex-safe)."""

    def __init__(self, n_modes: int, m: int | None = None):
        self.n = n_modes
        self.m = m or _grid(n_modes)
        self.s = 2 * math.pi * np.arange(self.m) / self.m
        self.kj = 2.0 * np.arange(1, n_modes + 1)
        self.SIN = np.sin(np.outer(self.s, self.kj))
        self.COS = np.cos(np.outer(self.s, self.kj))
        k = np.fft.fftfreq(self.m, 1.0 / self.m)
        self.ik = 1j * k
        self.inv_ik = np.where(k != 0, 1 / np.where(k != 0, self.ik, 1), 0)
        # integral over [0, pi] of exp(i k s): pi (k = 0), ((-1)^k - 1)/(i k) otherwise
        self.half_w = np.where(k == 0, math.pi, ((-1.0) ** np.abs(k) - 1) * self.inv_ik)
        self.poles = np.array([0, self.m // 2])

    def _half_integral(self, g: np.ndarray):
        """integral_0^pi g ds of smooth 2 pi-periodic functions given on the grid (axis 0; term-wise,
        exact for their resolved Fourier modes). Real and imaginary parts are integrated apart, so
        a complex step passes through."""
        def one(x):
            G = np.fft.fft(x, axis=0) / self.m
            w = self.half_w.reshape((-1,) + (1,) * (x.ndim - 1))
            return np.sum(G.real * w.real - G.imag * w.imag, axis=0)
        return one(g.real) + 1j * one(g.imag) if np.iscomplexobj(g) else one(g)

    def _antiderivative(self, f: np.ndarray):
        """Zero-mean f (axis 0) -> its periodic antiderivative vanishing at s = 0 (real and imaginary
        parts apart)."""
        def one(x):
            y = np.fft.ifft(np.fft.fft(x, axis=0) * self.inv_ik.reshape((-1,) + (1,) * (x.ndim - 1)),
                            axis=0).real
            return y - y[0]
        return one(f.real) + 1j * one(f.imag) if np.iscomplexobj(f) else one(f)

    def shape(self, a):
        """(r, z, psi, psi') on the grid; a of shape (N,) or (N, batch)."""
        ka = (self.kj * a.T).T
        psi = (self.s if a.ndim == 1 else self.s[:, None]) + _matmul(self.SIN, a)
        dpsi = 1 + _matmul(self.COS, ka)
        r = self._antiderivative(np.cos(psi))
        z = self._antiderivative(-np.sin(psi))
        return r, z, psi, dpsi

    def _k2(self, r, psi, dpsi):
        safe = r.copy()
        safe[self.poles] = 1.0
        k2 = np.sin(psi) / safe
        k2[self.poles] = dpsi[self.poles]  # sin psi / r -> psi' at the poles (L'Hopital)
        return k2

    def area(self, a):
        r, _, _, _ = self.shape(a)
        return 2 * math.pi * self._half_integral(r)

    def all(self, a):
        """(reduced energy, reduced volume) of a (real or complex; (N,) or a batch (N, B))."""
        r, _, psi, dpsi = self.shape(a)
        k2 = self._k2(r, psi, dpsi)
        W = 2 * math.pi * self._half_integral((dpsi + k2) ** 2 * r)
        area = 2 * math.pi * self._half_integral(r)
        V = math.pi * self._half_integral(r**2 * np.sin(psi))
        return W / (16 * math.pi), V / (4 * math.pi / 3 * (area / (4 * math.pi)) ** 1.5)

    def grads(self, a):
        """Gradients of (e, v) by the complex step, all N directions in one batch."""
        X = a[:, None] + 1j * CS_STEP * np.eye(self.n)
        e, v = self.all(X)
        return e.imag / CS_STEP, v.imag / CS_STEP

    def aspect(self, a) -> float:
        r, z, _, _ = self.shape(a)
        half = self.m // 2 + 1
        return float((z[:half].real.max() - z[:half].real.min()) / (2 * r[:half].real.max()))


def _matmul(real_matrix: np.ndarray, x: np.ndarray) -> np.ndarray:
    """real_matrix @ x with x real or complex (a real-by-complex matmul has no BLAS path: 100x slower)."""
    if np.iscomplexobj(x):
        return real_matrix @ x.real + 1j * (real_matrix @ x.imag)
    return real_matrix @ x


def _one_mode_start(v0: float, branch: str, n_modes: int) -> np.ndarray:
    g = _Geometry(1)
    sign = 1.0 if branch == "prolate" else -1.0
    hi = 0.05
    while g.all(np.array([sign * hi]))[1] > v0 and hi < 0.45:
        hi += 0.05
    a1 = optimize.brentq(lambda x: g.all(np.array([sign * x]))[1] - v0, 0.0, hi)
    a = np.zeros(n_modes)
    a[0] = sign * a1
    return a


def solve(v: float, which: str = "prolate", n_modes: int = 16, start: np.ndarray | None = None,
          m: int | None = None, second_order: bool = True) -> Axisymmetric:
    """The up-down symmetric axisymmetric vesicle of reduced volume ``v`` on the branch ``which``
    (prolate|oblate); without ``start``, below v = 0.9 the branch is walked down from 0.9.
    ``second_order=False`` skips the Hessian check (min_eigenvalue nan), for intermediate points.
    Without ``start`` the result is a function of the arguments alone and is kept (``_kept``)."""
    if start is None:
        return _copy(_kept_solve(float(v), which, n_modes, m, second_order))
    return _solve(v, which, n_modes, start, m, second_order)


def _copy(sol: Axisymmetric) -> Axisymmetric:
    return dataclasses.replace(sol, a=sol.a.copy())  # a kept result's coefficients stay the kept ones


@functools.lru_cache(maxsize=256)
def _kept_solve(v: float, which: str, n_modes: int, m: int | None, second_order: bool) -> Axisymmetric:
    """``solve`` from no start, kept per process: the ``phase_diagram`` study's cases (one worker process
    runs many) asked for the same sharp shapes at every eps, 30 % of a far case's CPU (12.9 of 43.5 s at
    eps 0.04, measured)."""
    return _solve(v, which, n_modes, None, m, second_order)


def _solve(v: float, which: str, n_modes: int, start: np.ndarray | None, m: int | None,
           second_order: bool) -> Axisymmetric:
    branch_name = which
    if which not in ("prolate", "oblate"):
        raise ValueError(f"which must be 'prolate' or 'oblate', got {which!r}")
    if not 0 < v < 1:
        raise ValueError(f"v must lie in (0, 1), got {v!r}")
    g = _Geometry(n_modes, m)
    a = np.zeros(n_modes)
    if start is not None:
        a[: min(len(start), n_modes)] = start[:n_modes]
    elif v < 0.9:  # the one-mode start reaches only near-spheres: walk down the branch from 0.9
        steps = np.linspace(0.9, v, int(math.ceil((0.9 - v) / 0.05)) + 1)[:-1]
        a = branch(steps, branch_name, n_modes, second_order=False)[-1].a
    else:
        a = _one_mode_start(v, branch_name, n_modes)
    cache = {}

    def ev(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = (g.all(x), g.grads(x))
        return cache[key]

    cons = {"type": "eq", "fun": lambda x: ev(x)[0][1] - v, "jac": lambda x: ev(x)[1][1][None, :]}
    opt = optimize.minimize(lambda x: ev(x)[0][0], a, jac=lambda x: ev(x)[1][0], constraints=[cons],
                            method="SLSQP", options={"ftol": 1e-15, "maxiter": 1000})
    a = opt.x
    (e, vv), (ge, gv) = ev(a)
    lam = float(ge @ gv / (gv @ gv))
    kkt = float(max(np.linalg.norm(ge - lam * gv) / (np.linalg.norm(ge) + abs(lam) * np.linalg.norm(gv)),
                    abs(vv - v)))
    mu = _reduced_min_eig(g, a, lam, gv) if second_order else math.nan
    return Axisymmetric(v, float(e), which, a, lam, kkt, mu, g.aspect(a), bool(kkt < 1e-7))


def _reduced_min_eig(g: _Geometry, a, lam, gv, h: float = 1e-6) -> float:
    """Smallest eigenvalue of the Hessian of e - lam v (central differences of the complex-step
    gradients, step h) on the null space of grad v."""
    n = len(a)
    H = np.empty((n, n))
    for j in range(n):
        d = np.zeros(n)
        d[j] = h
        gp, gm = g.grads(a + d), g.grads(a - d)
        H[:, j] = ((gp[0] - lam * gp[1]) - (gm[0] - lam * gm[1])) / (2 * h)
    H = (H + H.T) / 2
    _, s, Vt = np.linalg.svd(gv[None, :])
    Z = Vt[1:].T
    return float(np.linalg.eigvalsh(Z.T @ H @ Z).min())


def branch(vs, which: str = "prolate", n_modes: int = 16, second_order: bool = True) -> list[Axisymmetric]:
    """The branch at the reduced volumes ``vs`` (in order, each warm-started from the previous; kept
    per process as ``solve`` from no start is)."""
    return [_copy(sol) for sol in _kept_branch(tuple(float(v) for v in vs), which, n_modes, second_order)]


@functools.lru_cache(maxsize=64)
def _kept_branch(vs: tuple, which: str, n_modes: int, second_order: bool) -> tuple:
    out, start = [], None
    for v in vs:
        sol = solve(v, which, n_modes, start=start, second_order=second_order)
        out.append(sol)
        start = sol.a
    return tuple(out)


def small_deformation_slope() -> float:
    """de/dv at v = 1 on both branches: -2. Quasi-spherical shapes r = R(1 + sum u_lm Y_lm) at fixed
    area: bending energy 8 pi + (1/2) sum (l-1) l (l+1) (l+2) |u_lm|^2 and excess area
    Delta = (1/2) sum (l-1)(l+2) |u_lm|^2, so an l = 2 shape has W - 8 pi = l (l+1) Delta = 6 Delta,
    and 1 - v = 3 Delta / (8 pi) to first order: e - 1 = 6 Delta / (16 pi) = 2 (1 - v)."""
    return -2.0


def crossing(n_modes: int = 16, bracket: tuple[float, float] = (0.6, 0.7)) -> tuple[float, float]:
    """(v*, reduced energy) where the prolate and oblate branches cross: a root of
    e_prolate(v) - e_oblate(v) in ``bracket`` (brentq on fresh solves warm-started along the way)."""
    starts = {"prolate": None, "oblate": None}

    def diff(v):
        e = {}
        for b in ("prolate", "oblate"):
            sol = solve(v, b, n_modes, start=starts[b], second_order=False)
            starts[b] = sol.a
            e[b] = sol.reduced_energy
        return e["prolate"] - e["oblate"]

    vstar = optimize.brentq(diff, *bracket, xtol=1e-10)
    return float(vstar), float(solve(vstar, "prolate", n_modes, start=starts["prolate"]).reduced_energy)
