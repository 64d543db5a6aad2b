"""The 2D closed elastica: minimise the bending energy  integral kappa^2 ds  of a closed curve of
perimeter S that encloses the area V, i.e. at reduced area nu = 4 pi V / S^2 (the sharp-interface
limit of the phase-field problem (6)-(8) in 2D, whose energy tends to (sqrt 2/3) integral kappa^2 ds).

Discretisation (spectral, in the tangent angle). With the perimeter scaled to 2 pi (arc length t in
[0, 2 pi)), the tangent angle of a curve with n-fold rotational and mirror symmetry is

    theta(t) = t + sum_{j=1..N} b_j sin(k_j t),   k_j = n j   (n >= 2: the symmetry order),

so z'(t) = exp(i theta) is a unit tangent, the curve closes automatically (its n rotated sectors sum
to zero) and every constraint but the area is built in. The two functionals are exact in b:

    reduced energy  e(b) = integral theta'^2 dt / (4 pi^2 / 2 pi) = 1 + (1/2) sum k_j^2 b_j^2,
    reduced area    nu(b) = sum_k |f_k|^2 / k,   f_k the Fourier coefficients of exp(i theta)

(the area (1/2) Im integral conj(z) z' dt by Parseval, z_k = f_k/(i k)); f_k come from an FFT of
exp(i theta) on M >> k_N points, whose aliasing error decays like the coefficients (exponentially).
The reduced energy is scale-free: the circle has 1, and e is the phase-field ``reduced_energy`` in
the limit eps -> 0 (integral kappa^2 over the circle's 4 pi^2 / S).

Solve: SLSQP from the one-mode trial curve (b_1 from the exact one-mode formula ``one_mode_nu``),
then Newton on the KKT system (exact gradients and Hessians of e and nu), to a KKT residual at
round-off. n = 2 is the elastica branch of the ground state (ellipse-like, then peanut-like); n >= 3
are the symmetric branches through saddles (n = 4: the square-symmetric shape a phase-field solve
reaches from a circle start on a square grid).

Checks (``tests/sharp/test_elastica.py``): nu -> 1, where e = 1 + (n^2 - 1)(1 - nu) + O((1 - nu)^2)
(``small_deformation_slope``, from the one-mode formula: nu = sum_m J_m(b)^2/(1 + m n), e = 1 +
n^2 b^2/2); the one-mode energy bounds e from above; spectral convergence in N; the Euler-Lagrange
equation 2 kappa'' + kappa^3 - sigma kappa - p = 0 of the sharp problem, met by the computed curve
(``euler_lagrange_residual``, an identity the discretisation does not use); and the second-order
check in the full Fourier space (``full_space_check``: all modes, not only the symmetric ones, with
the closure constraints explicit and the reparametrisation mode removed).

numpy and scipy only: shares no code with the phase-field path.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import optimize
from scipy.special import jv


@dataclasses.dataclass(frozen=True)
class Elastica:
    """A computed elastica: reduced area ``nu``, reduced energy ``reduced_energy``, the symmetry
    order ``symmetry``, the sine coefficients ``b`` of theta - t at wavenumbers ``k``, the area
    multiplier ``lam`` (de/dnu = lam along the branch: the envelope identity), the relative KKT
    residual, and the verdicts of the second-order checks (symmetric subspace; full space)."""
    nu: float
    reduced_energy: float
    symmetry: int
    k: np.ndarray
    b: np.ndarray
    lam: float
    kkt_residual: float
    min_eigenvalue_symmetric: float
    converged: bool

    def curve(self, perimeter: float = 2 * math.pi, m: int = 512) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) at m equispaced arc-length points of the curve with this perimeter, centred."""
        t = 2 * math.pi * np.arange(m) / m
        theta = t + np.sin(np.outer(t, self.k)) @ self.b
        f = np.exp(1j * theta)
        F = np.fft.fft(f) / m
        kk = np.fft.fftfreq(m, 1.0 / m)
        Z = np.where(kk != 0, F / (1j * np.where(kk != 0, kk, 1)), 0)
        z = np.fft.ifft(Z * m) * perimeter / (2 * math.pi)
        return z.real, z.imag


def _grid(kmax: int) -> int:
    """Quadrature points: a power of two >= 16 kmax (so exp(i theta)'s spectrum is resolved)."""
    return int(2 ** math.ceil(math.log2(max(256, 16 * kmax))))


class _Functionals:
    """e, nu and their exact derivatives for theta = t + sum b_j sin(k_j t)."""

    def __init__(self, k: np.ndarray):
        self.k = np.asarray(k, float)
        self.m = _grid(int(self.k.max()))
        self.t = 2 * math.pi * np.arange(self.m) / self.m
        self.S = np.sin(np.outer(self.t, self.k))  # (m, N)
        kk = np.fft.fftfreq(self.m, 1.0 / self.m)
        self.inv_k = np.where(kk != 0, 1.0 / np.where(kk != 0, kk, 1), 0.0)

    def energy(self, b):
        return 1 + 0.5 * np.sum(self.k**2 * b**2)

    def energy_grad(self, b):
        return self.k**2 * b

    def energy_hess(self, b):
        return np.diag(self.k**2)

    def _f(self, b):
        return np.exp(1j * (self.t + self.S @ b))

    def nu(self, b):
        F = np.fft.fft(self._f(b)) / self.m
        return float(np.sum(np.abs(F) ** 2 * self.inv_k))

    def nu_grad(self, b):
        f = self._f(b)
        F = np.fft.fft(f) / self.m
        dF = np.fft.fft(1j * self.S * f[:, None], axis=0) / self.m  # d f / d b_j = i sin(k_j t) f
        return 2 * np.real(np.conj(F)[:, None] * dF).T @ self.inv_k

    def nu_hess(self, b):
        return _nu_hess(self._f(b), self.S, self.inv_k)


def _nu_hess(f: np.ndarray, basis: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Hessian of nu = sum_k w_k |F_k|^2, F = fft(f)/m, f = exp(i theta), d theta = basis @ db:
    2 Re(dF^H W dF) + basis^T diag(-2 Re(f conj h)) basis, h = ifft(w F) (the second-derivative
    term -basis_i basis_j f contracted with conj(F) W by Parseval, without forming it per pair)."""
    m = len(f)
    F = np.fft.fft(f) / m
    dF = np.fft.fft(1j * basis * f[:, None], axis=0) / m
    h = np.fft.ifft(w * F)
    H = 2 * np.real((np.conj(dF) * w[:, None]).T @ dF)
    return H + basis.T @ (basis * (-2 * np.real(f * np.conj(h)))[:, None])


def one_mode_nu(b: float, n: int, terms: int = 40) -> float:
    """Reduced area of theta = t + b sin(n t), exactly: sum_m J_m(b)^2 / (1 + m n)."""
    m = np.arange(-terms, terms + 1)
    with np.errstate(under="ignore"):  # J_m(b)^2 of high m underflows to 0: far below the sum's round-off
        return float(np.sum(jv(m, b) ** 2 / (1 + m * n)))


def one_mode_energy(nu: float, n: int = 2) -> float:
    """Reduced energy 1 + n^2 b^2 / 2 of the one-mode curve of reduced area nu: an upper bound on
    the elastica's (it is a trial curve in the same class)."""
    return 1 + n**2 * _one_mode_b(nu, n) ** 2 / 2


def _one_mode_b(nu: float, n: int) -> float:
    return optimize.brentq(lambda b: one_mode_nu(b, n) - nu, 0.0, 1.2 / n * 2)


def small_deformation_slope(n: int = 2) -> float:
    """de/dnu at nu = 1 for the n-fold branch: -(n^2 - 1) (from nu = 1 - (b^2/2) n^2/(n^2 - 1) + O(b^4)
    and e = 1 + n^2 b^2/2 of the one-mode curve, which is the branch to first order)."""
    return -(n**2 - 1.0)


def solve(nu: float, n_modes: int = 24, symmetry: int = 2, start: np.ndarray | None = None,
          tol: float = 1e-13) -> Elastica:
    """The n-fold symmetric elastica of reduced area ``nu`` with ``n_modes`` sine modes."""
    if not 0 < nu < 1:
        raise ValueError(f"nu must lie in (0, 1), got {nu!r}")
    if symmetry < 2:
        raise ValueError(f"symmetry must be >= 2 (closure), got {symmetry!r}")
    k = symmetry * np.arange(1, n_modes + 1)
    fn = _Functionals(k)
    b = np.zeros(n_modes)
    if start is not None:
        b[: min(len(start), n_modes)] = start[:n_modes]
    else:
        b[0] = _one_mode_b(nu, symmetry)
    cons = {"type": "eq", "fun": lambda x: fn.nu(x) - nu, "jac": lambda x: fn.nu_grad(x)[None, :]}
    opt = optimize.minimize(fn.energy, b, jac=fn.energy_grad, constraints=[cons], method="SLSQP",
                            options={"ftol": 1e-14, "maxiter": 500})
    b = opt.x
    g, a = fn.energy_grad(b), fn.nu_grad(b)
    lam = float(g @ a / (a @ a))
    for _ in range(30):  # Newton on grad e - lam grad nu = 0, nu = nu0
        g, a = fn.energy_grad(b), fn.nu_grad(b)
        r = np.concatenate([g - lam * a, [fn.nu(b) - nu]])
        if _kkt(g, a, lam, fn.nu(b) - nu) < tol:
            break
        H = fn.energy_hess(b) - lam * fn.nu_hess(b)
        K = np.block([[H, -a[:, None]], [a[None, :], np.zeros((1, 1))]])
        d = np.linalg.solve(K, -r)
        b, lam = b + d[:-1], lam + d[-1]
    g, a = fn.energy_grad(b), fn.nu_grad(b)
    kkt = _kkt(g, a, lam, fn.nu(b) - nu)
    H = fn.energy_hess(b) - lam * fn.nu_hess(b)
    mu = _reduced_min_eig(H, a[None, :])
    return Elastica(nu, float(fn.energy(b)), symmetry, k, b, lam, kkt, mu, bool(kkt < 1e-10))


def _kkt(g, a, lam, c) -> float:
    """max(|grad e - lam grad nu| / (|grad e| + |lam grad nu|), |nu - nu0|)."""
    return float(max(np.linalg.norm(g - lam * a) / (np.linalg.norm(g) + abs(lam) * np.linalg.norm(a)),
                     abs(c)))


def _reduced_min_eig(H: np.ndarray, J: np.ndarray) -> float:
    """Smallest eigenvalue of H on the null space of the constraint Jacobian J."""
    _, s, Vt = np.linalg.svd(J)
    Z = Vt[int(np.sum(s > 1e-12 * s.max())):].T
    return float(np.linalg.eigvalsh(Z.T @ H @ Z).min())


def full_space_check(el: Elastica, n_full: int | None = None) -> dict:
    """First- and second-order check of ``el`` among ALL curves, not only the symmetric ones.

    theta = t + sum_{k=1..K} (a_k cos k t + b_k sin k t) (K = n_full, default 2 k_max of ``el``),
    constraints nu = nu0 and closure Re f_0 = Im f_0 = 0 explicit. Returns ``kkt`` (least-squares
    multipliers, relative residual), ``min_eigenvalue`` of the Lagrangian's Hessian on the tangent
    space of the three constraints with the reparametrisation mode (a shift t -> t + c, then a
    rotation; a null mode) removed, and ``minimum`` (min_eigenvalue > 0)."""
    K = n_full or 2 * int(el.k.max())
    kk = np.arange(1, K + 1)
    m = _grid(K)
    t = 2 * math.pi * np.arange(m) / m
    basis = np.hstack([np.cos(np.outer(t, kk)), np.sin(np.outer(t, kk))])  # (m, 2K)
    x = np.zeros(2 * K)
    for kj, bj in zip(el.k, el.b):
        x[K + int(kj) - 1] = bj
    w = 1.0 / np.where(np.fft.fftfreq(m, 1.0 / m) != 0, np.fft.fftfreq(m, 1.0 / m), np.inf)
    f = np.exp(1j * (t + basis @ x))
    F = np.fft.fft(f) / m
    dF = np.fft.fft(1j * basis * f[:, None], axis=0) / m
    grad_e = np.concatenate([kk**2 * x[:K], kk**2 * x[K:]])
    hess_e = np.diag(np.concatenate([kk**2, kk**2]))
    grad_nu = 2 * np.real(np.conj(F)[:, None] * dF).T @ w
    hess_nu = _nu_hess(f, basis, w)
    # closure: f_0 = mean exp(i theta); gradient dF[0], Hessian -basis^T diag(f) basis / m
    d2F0 = basis.T @ (basis * (-f / m)[:, None])
    G = np.vstack([grad_nu, dF[0].real, dF[0].imag])  # (3, 2K)
    mult, *_ = np.linalg.lstsq(G.T, grad_e, rcond=None)
    kkt = float(np.linalg.norm(grad_e - G.T @ mult) / np.linalg.norm(grad_e))
    H = hess_e - mult[0] * hess_nu - mult[1] * d2F0.real - mult[2] * d2F0.imag
    # the reparametrisation mode: d/dc [theta(t + c) - c] = theta'(t) - 1, in the basis
    shift = np.concatenate([kk * x[K:], -kk * x[:K]])
    J = np.vstack([G, shift[None, :] / max(np.linalg.norm(shift), 1e-300)])
    mu = _reduced_min_eig(H, J)
    closure = float(abs(F[0]))
    return {"kkt": kkt, "min_eigenvalue": mu, "minimum": bool(mu > 0), "closure": closure,
            "lam": float(mult[0])}


def euler_lagrange_residual(el: Elastica, m: int = 1024) -> dict:
    """The sharp Euler-Lagrange equation of the elastica at fixed length and area,
    2 kappa_ss + kappa^3 - sigma kappa - p = 0, on the computed curve (perimeter 2 pi, s = t):
    sigma and p by least squares; returns them and the residual over |2 kappa_ss| + |kappa^3|."""
    t = 2 * math.pi * np.arange(m) / m
    kappa = 1 + np.cos(np.outer(t, el.k)) @ (el.k * el.b)
    kappa_ss = -np.cos(np.outer(t, el.k)) @ (el.k**3 * el.b)
    lhs = 2 * kappa_ss + kappa**3
    A = np.stack([kappa, np.ones(m)], axis=1)
    (sigma, p), *_ = np.linalg.lstsq(A, lhs, rcond=None)
    res = lhs - sigma * kappa - p
    scale = np.linalg.norm(2 * kappa_ss) + np.linalg.norm(kappa**3)
    return {"sigma": float(sigma), "p": float(p), "residual": float(np.linalg.norm(res) / scale)}


def branch(nus, n_modes: int = 24, symmetry: int = 2) -> list[Elastica]:
    """The branch at the reduced areas ``nus`` (in the given order), each solve warm-started from
    the previous one."""
    out, start = [], None
    for nu in nus:
        el = solve(float(nu), n_modes, symmetry, start=start)
        out.append(el)
        start = el.b
    return out
