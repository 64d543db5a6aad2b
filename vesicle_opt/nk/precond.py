"""Preconditioners for cE H_E + cB H_B (+ rho_A dA dA^T): a constant-coefficient model of the Hessian.

In the bulk phi = +-1, so g'(phi) = -2/eps (c0 = 0) and J = eps Delta_h + g' ~ eps Delta_h - 2/eps
= -M_L^{-1} S with S = eps K + (2/eps) M_L (``model.lumped.bulk_stiffness``, Fourier symbol
``model.lumped.bulk_symbol``); the model is

    P = (cE/eps) S M_L^{-1} S + cB S + rho_A m m^T.

* Fourier grids (and the mirror grids of ``mesh.cosine``, in their cosine basis): P is diagonal in Fourier space, with sigma = -symbol(Delta_h) >= 0,
  p(k) = m [ (cE/eps)(eps sigma + 2/eps)^2 + cB (eps sigma + 2/eps) ] (+ rho_A m^2 N at k = 0);
  cB (a multiplier) may be negative, so p is floored at 0.1 times the bending part.
* Sparse (P1 lumped): P^{-1} ~ (eps/cE) S^{-1} M_L S^{-1}; cB and rho_A are left to CG. S^{-1} is
  one of (``SparsePreconditioner.kind``)

  - ``lu``: a sparse LU, on 2D meshes up to ``LU_MAX_NODES`` (cheap there: 64^2 ellipse 1.1 s,
    128^2 11.6 s a solve, as fast as Chebyshev);
  - ``chebyshev``: a fixed Chebyshev polynomial in M_L^{-1} S. S is well conditioned where h
    resolves eps: spec(M_L^{-1} S) lies in [2/eps, 2/eps + eps max_i sum_j |K_ij| / m_i]
    (K >= 0; Gershgorin), kappa = 1 + 6 (eps/h)^2 on the 3D tensor mesh (11 at the 32^3 torus,
    24 at 48^3), so ``CHEB_TOL`` costs 13 (32^3) to 18 (48^3) products with S. The polynomial is
    linear and symmetric with spec(B S) in [1 - CHEB_TOL, 1 + CHEB_TOL] (rigorous), and it commutes
    with every symmetry of the mesh, as the exact S^{-1} does;
  - ``pyamg``: where the polynomial would need more than ``CHEB_MAX_STEPS`` products (h << eps,
    local refinement), smoothed-aggregation-preconditioned CG on S to ``AMG_TOL``.

  Measured on torus-table1-3d (P1 periodic lumped, exact constraints, tol 1e-8, one shared core,
  fresh process, wall time with assembly / Newton / CG / peak memory): 16^3 1.3 s 17 / 443 112 MB,
  24^3 4.2 s 16 / 422 197 MB, 32^3 10 s 17 / 392 369 MB, 40^3 17 s 19 / 348 633 MB, 48^3 40 s
  18 / 346 1.05 GB, 64^3 111 s 17 / 393 2.35 GB (memory mostly the scikit-fem assembly), each at
  the FD backend's energy to <= 1.4e-10 relative (the lumped P1 tensor operator is the FD one).
  The LU took 6.6 s at 16^3 and needs 6 s (24^3) and 91 s plus 2.4 GB (32^3) for its factors.
  Fixed pyamg V-cycles (the earlier choice) are symmetric (|B - B^T| ~ 1e-16 |B|) and accurate
  (spec(B S) in [0.9997, 1] with 3 cycles on the 64^2 ellipse) but break the mesh symmetries
  (|B g v - g B v| ~ 3e-5 |B v| for a grid shift g there); from symmetric starts the iterates then
  slid along soft grid-pinning modes away from the symmetric KKT point that LU, FFT and IPOPT find
  (a saddle: reduced-Hessian eigenvalues -5.5e-3, -1.3e-3 on that ellipse): 116 Newton / 5200 CG
  to E 2.750450 against 22 / 304 to E 2.750541 with LU; 67 / 2733 and 94 s to E 406.41 on the
  24^3 torus. pyamg-CG to 1e-10 follows LU (24^3: 16 Newton / 437 CG, E 407.2106061, 42 s).

``dual_norm(v)`` = sqrt(v^T P0^{-1} v) with the fixed bending-only model P0 (cE = 1, cB = 0) is the
mesh-independent stopping norm of the solver (the L2 norm of a gradient has a round-off floor of
about eps_mach k_max^4; this one does not). With an approximate S^{-1} it is the norm of that fixed
linear operator (Chebyshev), or of S^{-1} to ``AMG_TOL`` (pyamg).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vesicle_opt.model.lumped import bulk_shift, bulk_stiffness, bulk_symbol

FLOOR = 0.1  # the model never drops below 10% of its (positive) bending part
LU_MAX_NODES = {2: 100_000, 3: 0}  # exact S^{-1} by LU up to here; in 3D the LU fills in (24^3: 6 s
# and 23 ms a solve against 5 ms for Chebyshev; 32^3: 91 s, 200 ms, 2.4 GB), so it never wins there
CHEB_TOL = 1e-3  # spec(B S) within 1e-3 of 1: the same Newton / CG counts as 1e-6 (32^3: 17 / 392 vs
# 17 / 389; 48^3 18 / 346 vs 18 / 345) and LU (16^3, 1e-6: 17 / 424 vs 17 / 426), 22% less time
CHEB_MAX_STEPS = 150  # one pyamg-CG S^{-1} to AMG_TOL costs ~190 Chebyshev steps (measured at 32^3 and
# 48^3: 66 vs 0.35 ms, 289 vs 1.25 ms), so the polynomial is used up to 150 steps (kappa ~ 430)
AMG_TOL = 1e-10  # pyamg-CG on S to this relative residual: symmetric and mesh-symmetric to ~1e-10
# (measured 3e-12, 7e-11 on a 32^2 mesh; three plain V-cycles, 3e-5, left the symmetric KKT point)
AMG_MAXITER = 100  # ~6 CG iterations are needed at 32^3-48^3 (V-cycle contraction 0.01-0.05)


class FourierPreconditioner:
    def __init__(self, fourier, m: float, epsilon: float):
        self.f = fourier
        self.m = float(m)
        self.eps = float(epsilon)
        self._q = bulk_symbol(fourier, self.eps)  # symbol of M_L^{-1} S
        self._p0 = self.m / self.eps * self._q**2
        self._p0_inv = 1.0 / self._p0
        if not hasattr(fourier, "quadratic_form"):  # the rfft layout (mirror grids: ``dual_norm``)
            # Parseval for rfft: interior half-spectrum columns count twice; one weight per real
            # and imaginary part, so the dual norm is one pass over the spectrum's real view (einsum)
            w = np.full(self._p0_inv.shape[-1], 2.0)
            w[0] = 1.0
            if fourier.shape[-1] % 2 == 0:
                w[-1] = 1.0
            self._dual_weights = np.repeat((w * self._p0_inv / fourier.size).ravel(), 2)

    def symbol(self, cE: float, cB: float = 0.0, rho_A: float = 0.0) -> np.ndarray:
        bend = cE * self._p0
        p = np.maximum(bend + cB * self.m * self._q, FLOOR * bend)
        if rho_A:
            p = p.copy()
            p.flat[0] += rho_A * self.m**2 * self.f.size
        return p

    def inverse(self, cE: float, cB: float = 0.0, rho_A: float = 0.0):
        inv = self.f.multiplier(1.0 / self.symbol(cE, cB, rho_A))
        return lambda r: self.f.apply_symbol(r, inv)

    def dual_norm(self, v: np.ndarray) -> float:
        if hasattr(self.f, "quadratic_form"):  # mirror grids (mesh.cosine): orthonormal DCT, Parseval
            return float(np.sqrt(max(self.f.quadratic_form(v, self._p0_inv), 0.0)))
        re_im = self.f.fft(v).view(np.float64).ravel()
        val = float(np.einsum("i,i,i->", re_im, re_im, self._dual_weights))
        return float(np.sqrt(max(val, 0.0)))


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


def _amg_solver(S: sp.csr_matrix):
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


class SparsePreconditioner:
    """The model above for P1 lumped meshes; ``kind`` (lu, chebyshev, pyamg) picks S^{-1}, by
    default LU up to ``LU_MAX_NODES``, else Chebyshev up to ``CHEB_MAX_STEPS``, else pyamg-CG."""

    def __init__(self, K: sp.spmatrix, m: np.ndarray, epsilon: float, dim: int = 2,
                 kind: str | None = None):
        self.m = np.asarray(m, float)
        self.eps = float(epsilon)
        S = bulk_stiffness(K, self.m, self.eps)
        self.S = S
        lo, hi = chebyshev_bounds(K, self.m, self.eps)
        self.steps = chebyshev_steps(lo, hi, CHEB_TOL)
        if kind is None:
            kind = "lu" if S.shape[0] <= LU_MAX_NODES[dim] else \
                "chebyshev" if self.steps <= CHEB_MAX_STEPS else "pyamg"
        self.kind = kind
        if kind == "lu":
            self._S_inv = spla.splu(sp.csc_matrix(S)).solve
        elif kind == "chebyshev":
            self._S_inv = chebyshev_inverse(S, self.m, lo, hi, self.steps)
        elif kind == "pyamg":
            ml = _amg_solver(S)
            self._S_inv = lambda r: ml.solve(r, tol=AMG_TOL, maxiter=AMG_MAXITER, accel="cg")
        else:
            raise ValueError(f"unknown S^-1 kind {kind!r}")

    def _p0_inv(self, r: np.ndarray) -> np.ndarray:
        return self.eps * self._S_inv(self.m * self._S_inv(r))

    def inverse(self, cE: float, cB: float = 0.0, rho_A: float = 0.0):
        return lambda r: self._p0_inv(r) / cE

    def model(self, cE: float):
        """v -> cE P0 v = (cE/eps) S M_L^{-1} S v, exactly (sparse products; SPD)."""
        return lambda v: cE / self.eps * (self.S @ ((self.S @ v) / self.m))

    def dual_norm(self, v: np.ndarray) -> float:
        return float(np.sqrt(max(float(v @ self._p0_inv(v)), 0.0)))
