"""Preconditioners for cE H_E + cB H_B (+ rho_A dA dA^T): a constant-coefficient model of the Hessian.

In the bulk phi = +-1, so g'(phi) = -2/eps (c0 = 0) and J = eps Delta_h + g' ~ eps Delta_h - 2/eps
= -M_L^{-1} S with S = eps K + (2/eps) M_L; the model is

    P = (cE/eps) S M_L^{-1} S + cB S + rho_A m m^T.

* Fourier grids: P is diagonal in Fourier space, with sigma = -symbol(Delta_h) >= 0,
  p(k) = m [ (cE/eps)(eps sigma + 2/eps)^2 + cB (eps sigma + 2/eps) ] (+ rho_A m^2 N at k = 0);
  cB (a multiplier) may be negative, so p is floored at 0.1 times the bending part.
* Sparse (P1 lumped): P^{-1} ~ (eps/cE) S^{-1} M_L S^{-1} with S^{-1} by a sparse LU (pyamg
  V-cycles on large meshes); cB and rho_A are left to CG.

``dual_norm(v)`` = sqrt(v^T P0^{-1} v) with the fixed bending-only model P0 (cE = 1, cB = 0) is the
mesh-independent stopping norm of the solver (the L2 norm of a gradient has a round-off floor of
about eps_mach k_max^4; this one does not).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

FLOOR = 0.1  # the model never drops below 10% of its (positive) bending part
AMG_CYCLES = 3  # V-cycles per S^{-1} (a fixed symmetric operator) on meshes above LU_MAX_NODES
LU_MAX_NODES = {2: 100_000, 3: 20_000}  # exact S^{-1} by LU up to here: with pyamg (1 or 3
# V-cycles) the 64^2 P1 ellipse took 79-112 Newton / 4000-5200 CG against 22 / 305 with the LU;
# in 3D the LU fills in (32^3: 300 s a solve), so pyamg takes over there (measured: 24^3 torus with
# one V-cycle 32 Newton / 1550 CG / 50 s, against LU 16 / 422 / 75 s)


class FourierPreconditioner:
    def __init__(self, fourier, m: float, epsilon: float):
        self.f = fourier
        self.m = float(m)
        self.eps = float(epsilon)
        sigma = -fourier.symbol
        self._q = self.eps * sigma + 2 / self.eps  # symbol of M_L^{-1} S
        self._p0 = self.m / self.eps * self._q**2
        self._p0_inv = 1.0 / self._p0

    def symbol(self, cE: float, cB: float = 0.0, rho_A: float = 0.0) -> np.ndarray:
        bend = cE * self._p0
        p = np.maximum(bend + cB * self.m * self._q, FLOOR * bend)
        if rho_A:
            p = p.copy()
            p.flat[0] += rho_A * self.m**2 * self.f.size
        return p

    def inverse(self, cE: float, cB: float = 0.0, rho_A: float = 0.0):
        inv = 1.0 / self.symbol(cE, cB, rho_A)
        return lambda r: self.f.apply_symbol(r, inv)

    def dual_norm(self, v: np.ndarray) -> float:
        vh = self.f.fft(v)
        # Parseval for rfft: interior half-spectrum columns count twice
        w = np.full(vh.shape[-1], 2.0)
        w[0] = 1.0
        if self.f.shape[-1] % 2 == 0:
            w[-1] = 1.0
        val = float(np.sum(w * self._p0_inv * np.abs(vh) ** 2)) / self.f.size
        return float(np.sqrt(max(val, 0.0)))


class SparsePreconditioner:
    """The model above for P1 lumped meshes: S^{-1} by a sparse LU (S is a second-order operator,
    so its fill-in is modest) up to ``LU_MAX_NODES``, by pyamg V-cycles beyond."""

    def __init__(self, K: sp.spmatrix, m: np.ndarray, epsilon: float, dim: int = 2):
        self.m = np.asarray(m, float)
        self.eps = float(epsilon)
        S = sp.csr_matrix(self.eps * K + sp.diags(2 / self.eps * self.m))
        if S.shape[0] <= LU_MAX_NODES[dim]:
            lu = spla.splu(sp.csc_matrix(S))
            self._S_inv = lu.solve
            self.kind = "lu"
        else:
            import pyamg
            ml = pyamg.smoothed_aggregation_solver(S, symmetry="symmetric")
            self._S_inv = lambda r: ml.solve(r, tol=1e-30, maxiter=AMG_CYCLES, cycle="V", accel=None)
            self.kind = "pyamg"

    def _p0_inv(self, r: np.ndarray) -> np.ndarray:
        return self.eps * self._S_inv(self.m * self._S_inv(r))

    def inverse(self, cE: float, cB: float = 0.0, rho_A: float = 0.0):
        return lambda r: self._p0_inv(r) / cE

    def dual_norm(self, v: np.ndarray) -> float:
        return float(np.sqrt(max(float(v @ self._p0_inv(v)), 0.0)))
