"""The natural metric of the problem: the bulk model of the Hessian of E_h at phi = +-1, its
inverse and its dual norm, the one norm every certificate measures stationarity in.

In the bulk phi = +-1 (c0 = 0) the Jacobian of f_c (12) is J = eps Delta_h - 2/eps = -M_L^{-1} S with
S = eps K + (2/eps) M_L (``model.lumped.bulk_stiffness``), so the Hessian of E_h (6) there is

    P0 = (1/eps) S M_L^{-1} S,                   |v|_nat = sqrt(v^T P0^{-1} v)

for a nodal-integral vector v (a gradient). It is SPD, and it is the Newton-Krylov preconditioner's
fixed bending model (``nk.precond``, which builds on this module). On Fourier grids (spectral, FD
by FFT, the mirror grids of ``mesh.cosine``) P0 is diagonal in Fourier space with symbol
p0(k) = (m/eps) q(k)^2, q = eps sigma + 2/eps (sigma = -symbol of Delta_h); on meshes P0^{-1} is
eps S^{-1} M_L S^{-1} with S^{-1} one of (``SparseMetric.kind``):

* ``lu``: a sparse LU, on 2D meshes up to ``LU_MAX_NODES``;
* ``chebyshev``: a fixed Chebyshev polynomial in M_L^{-1} S (linear, symmetric, spec(B S) within
  ``CHEB_TOL`` of 1, rigorous: Gershgorin bounds), where it needs at most ``CHEB_MAX_STEPS`` products;
* ``pyamg``: smoothed-aggregation-preconditioned CG on S to ``AMG_TOL`` otherwise.

(The measurements behind these choices are in ``nk.precond``'s docstring.)

Why this norm. The relative L2 norm of a gradient carries the round-off of phi amplified by the
highest Fourier mode to the fourth power (|sigma|^2 ~ h^-4): its floor grows like h^-4 and refused
right answers on fine grids. In the natural norm white noise delta phi (round-off, |delta phi_i| ~ u)
costs |P0 delta phi|_nat = (delta phi^T P0 delta phi)^(1/2) ~ u (tr P0)^(1/2) ~ u h^-2 |Omega|^(1/2)
(``roundoff``; tr P0 = sum_i (P0)_ii, ``diagonal``): its floor grows like h^-2 only. And to first
order it bounds Newton's error in the energy norm: where the Hessian H of the Lagrangian is spectrally
equivalent to P0 (c P0 <= H <= C P0 on the tangent space), |phi - phi*|_H = |H^{-1} r|_H =
|r|_{H^{-1}} <= c^{-1/2} |r|_nat.
"""

from __future__ import annotations

import math
import weakref

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vesicle_opt.mesh.spectral import fourier_grid
from vesicle_opt.model.lumped import bulk_shift, bulk_stiffness, bulk_symbol

LU_MAX_NODES = {2: 100_000, 3: 0}  # exact S^{-1} by LU up to here; in 3D the LU fills in (24^3: 6 s
# and 23 ms a solve against 5 ms for Chebyshev; 32^3: 91 s, 200 ms, 2.4 GB), so it never wins there
CHEB_TOL = 1e-3  # spec(B S) within 1e-3 of 1: the same Newton / CG counts as 1e-6 (32^3: 17 / 392 vs
# 17 / 389; 48^3 18 / 346 vs 18 / 345) and LU (16^3, 1e-6: 17 / 424 vs 17 / 426), 22% less time
CHEB_MAX_STEPS = 150  # one pyamg-CG S^{-1} to AMG_TOL costs ~190 Chebyshev steps (measured at 32^3 and
# 48^3: 66 vs 0.35 ms, 289 vs 1.25 ms), so the polynomial is used up to 150 steps (kappa ~ 430)
AMG_TOL = 1e-10  # pyamg-CG on S to this relative residual: symmetric and mesh-symmetric to ~1e-10
# (measured 3e-12, 7e-11 on a 32^2 mesh; three plain V-cycles, 3e-5, left the symmetric KKT point)
AMG_MAXITER = 100  # ~6 CG iterations are needed at 32^3-48^3 (V-cycle contraction 0.01-0.05)


def chebyshev_bounds(K: sp.spmatrix, m: np.ndarray, epsilon: float) -> tuple[float, float]:
    """[lo, hi] containing spec(M^{-1} S), S = eps K + (2/eps) M, M = diag(m): K >= 0 gives lo = 2/eps,
    Gershgorin's discs of M^{-1} K give hi."""
    lo = bulk_shift(epsilon)
    row = np.asarray(abs(sp.csr_matrix(K)).sum(axis=1)).ravel()
    return lo, lo + epsilon * float(np.max(row / m))


def chebyshev_steps(lo: float, hi: float, tol: float) -> int:
    """Steps after which |1 - lambda p(lambda)| <= 2 q^k <= tol on [lo, hi], q = (sqrt k - 1)/(sqrt k + 1)."""
    kappa = hi / lo
    if kappa <= 1 + 1e-12:
        return 0
    q = (np.sqrt(kappa) - 1) / (np.sqrt(kappa) + 1)
    return int(np.ceil(np.log(tol / 2) / np.log(q)))


def chebyshev_inverse(S: sp.csr_matrix, m: np.ndarray, lo: float, hi: float, steps: int):
    """b -> p(M^{-1} S) M^{-1} b: ``steps`` Chebyshev iterations for S x = b from x = 0 with the
    diagonal preconditioner M = diag(m), spec(M^{-1} S) in [lo, hi] (Saad, Iterative Methods,
    Alg. 12.1). A fixed polynomial: linear, and symmetric as M^{-1} (S M^{-1})^j is."""
    theta, delta = (hi + lo) / 2, (hi - lo) / 2
    minv = 1.0 / np.asarray(m, float)

    def apply(b: np.ndarray) -> np.ndarray:
        r = np.array(b, float)
        d = minv * r / theta
        x = d.copy()
        if steps == 0:
            return x
        sigma = theta / delta
        rho = 1 / sigma
        for _ in range(steps):
            r -= S @ d
            rho_new = 1 / (2 * sigma - rho)
            d *= rho_new * rho
            d += (2 * rho_new / delta) * (minv * r)
            x += d
            rho = rho_new
        return x
    return apply


def amg_solver(S: sp.csr_matrix):
    """pyamg's smoothed aggregation; its setup estimates spectral radii from a random start
    (np.random), seeded here (the global state restored) so that runs are reproducible: at saddles
    of coarse meshes differences of 1e-10 in S^{-1} decide which KKT point the iterates reach."""
    import pyamg
    state = np.random.get_state()
    np.random.seed(0)
    try:
        return pyamg.smoothed_aggregation_solver(S, symmetry="symmetric")
    finally:
        np.random.set_state(state)


class FourierMetric:
    """P0 on a Fourier (or mirror) grid: the diagonal symbol p0 = (m/eps) q^2 (module docstring)."""

    def __init__(self, fourier, m: float, epsilon: float):
        self.f, self.m, self.eps = fourier, float(m), float(epsilon)
        self.q = bulk_symbol(fourier, self.eps)  # symbol of M_L^{-1} S
        self.p0 = self.m / self.eps * self.q**2
        self.p0_inv = 1.0 / self.p0
        mirror = hasattr(fourier, "quadratic_form")  # mesh.cosine: orthonormal DCT, Parseval
        # the rfft layout: interior half-spectrum columns count twice (Parseval; their conjugates)
        w = np.ones(self.p0.shape[-1]) if mirror else np.full(self.p0.shape[-1], 2.0)
        if not mirror:
            w[0] = 1.0
            if fourier.shape[-1] % 2 == 0:
                w[-1] = 1.0
            # one weight per real and imaginary part: the dual norm is one pass over the spectrum's
            # real view (einsum)
            self._dual_weights = np.repeat((w * self.p0_inv / fourier.size).ravel(), 2)
        self._mult = w  # multiplicity of each stored coefficient in the full spectrum
        self.kind = "fourier"

    def dual_norm(self, v: np.ndarray) -> float:
        if hasattr(self.f, "quadratic_form"):
            return float(np.sqrt(max(self.f.quadratic_form(v, self.p0_inv), 0.0)))
        re_im = self.f.fft(v).view(np.float64).ravel()
        val = float(np.einsum("i,i,i->", re_im, re_im, self._dual_weights))
        return float(np.sqrt(max(val, 0.0)))

    def diagonal(self, mass: bool = False) -> np.ndarray:
        """diag(P0) (``mass``: diag(S M_L^{-1} S P0^{-1} ... ) = eps m, i.e. of eps M_L): on a
        circulant grid every node has the mean of the symbol over the full spectrum."""
        if mass:
            return np.full(self.f.size, self.eps * self.m)
        total = float(np.sum(self.p0 * self._mult))
        return np.full(self.f.size, total / self.f.size)


class SparseMetric:
    """P0 on a mesh: P0^{-1} = eps S^{-1} M_L S^{-1} with S^{-1} by ``kind`` (module docstring)."""

    def __init__(self, K: sp.spmatrix, m: np.ndarray, epsilon: float, dim: int = 2, kind: str | None = None):
        self.m = np.asarray(m, float)
        self.eps = float(epsilon)
        self.S = S = bulk_stiffness(K, self.m, self.eps)
        lo, hi = chebyshev_bounds(K, self.m, self.eps)
        self.steps = chebyshev_steps(lo, hi, CHEB_TOL)
        if kind is None:
            kind = "lu" if S.shape[0] <= LU_MAX_NODES[dim] else \
                "chebyshev" if self.steps <= CHEB_MAX_STEPS else "pyamg"
        self.kind = kind
        if kind == "lu":
            self.S_inv = spla.splu(sp.csc_matrix(S)).solve
        elif kind == "chebyshev":
            self.S_inv = chebyshev_inverse(S, self.m, lo, hi, self.steps)
        elif kind == "pyamg":
            ml = amg_solver(S)
            self.S_inv = lambda r: ml.solve(r, tol=AMG_TOL, maxiter=AMG_MAXITER, accel="cg")
        else:
            raise ValueError(f"unknown S^-1 kind {kind!r}")

    def p0_inv(self, r: np.ndarray) -> np.ndarray:
        return self.eps * self.S_inv(self.m * self.S_inv(r))

    def dual_norm(self, v: np.ndarray) -> float:
        return float(np.sqrt(max(float(v @ self.p0_inv(v)), 0.0)))

    def diagonal(self, mass: bool = False) -> np.ndarray:
        """diag(P0) = (1/eps) sum_j S_ij^2 / m_j (``mass``: eps m, the diagonal of S P0^{-1} S)."""
        if mass:
            return self.eps * self.m
        S = sp.csr_matrix(self.S)
        return np.asarray(S.multiply(S) @ (1.0 / self.m)).ravel() / self.eps


_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def natural_metric(disc, epsilon: float):
    """The metric of a discretisation at eps (cached per discretisation): Fourier grids by their
    symbol, periodic FD grids through their FFT twin (``mesh.spectral.fourier_grid(kind='fd')``, the
    same operator to round-off, same node order), every other mesh by ``SparseMetric``."""
    per = _CACHE.setdefault(disc, {})
    key = float(epsilon)
    if key not in per:
        fourier = getattr(disc, "fourier", None)
        if fourier is None and disc.kind == "fd" and disc.grid_shape is not None:
            fourier = fourier_grid(disc.box, disc.grid_shape, "fd").fourier
        if fourier is not None:
            per[key] = FourierMetric(fourier, disc.weights[0], key)
        else:
            per[key] = SparseMetric(disc.K, disc.weights, key, disc.dim)
    return per[key]


def roundoff(metric, phi: np.ndarray, rigidity: float, lam_B: float) -> float:
    """|delta(rig dE - lam_B dB)|_nat for the round-off of phi, delta phi_i = u |phi_i| xi_i (xi
    independent, unit variance): with H_E ~ P0 and H_B ~ S in the bulk,
    E|P0 d|_nat^2 = sum_i (P0)_ii d_i^2 and E|S d|_nat^2 = sum_i eps m_i d_i^2, so (triangle
    inequality) u [rig (sum (P0)_ii phi_i^2)^(1/2) + |lam_B| (sum eps m_i phi_i^2)^(1/2)]."""
    u = np.finfo(float).eps
    phi2 = np.square(np.asarray(phi, float))
    bend = math.sqrt(float(metric.diagonal() @ phi2))
    area = math.sqrt(float(metric.diagonal(mass=True) @ phi2))
    return u * (abs(rigidity) * bend + abs(lam_B) * area)
