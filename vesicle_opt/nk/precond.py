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

* Sparse, interface-aware (``SparsePreconditioner.gauss_newton``, where S^{-1} is the LU: 2D meshes
  up to ``LU_MAX_NODES``): the bending Hessian's Gauss-Newton part with the field's own g'(phi),

      P_GN = (cE/eps) J M_L^{-1} J + max(cB, 0) S + GN_DELTA (cE/eps) S M_L^{-1} S,   J = -eps K + M_L diag(g'),

  so that cE H_E = (cE/eps) J M_L^{-1} J + cE diag(m r g''/eps) (``model.lumped.PhaseField.hvp_operator``:
  the identity holds to round-off, a test). In the interface band g' ranges over [-2/eps, 1/eps], where
  the bulk model takes -2/eps: P^{-1} H then has an outlier per resolved shape mode, whose number grows
  as eps falls (module docstring of ``branch.krylov_bordered``); P_GN holds J's near-null shape modes.
  A sparse LU, factored on first use (``branch.nk_free.VesicleKKT.pinv`` keeps it while the field moves
  little). Measured on the bordered Newton-Krylov walk of
  the eps 0.03 meridian cup (19.5 k nodes): the bulk model's GMRES hit its cap of 400 and the first
  point failed; with P_GN every point converged, at most 34 GMRES iterations a Newton step.

``dual_norm(v)`` = sqrt(v^T P0^{-1} v) with the fixed bending-only model P0 (cE = 1, cB = 0) is the
mesh-independent stopping norm of the solver (the L2 norm of a gradient has a round-off floor of
about eps_mach k_max^4; this one does not). With an approximate S^{-1} it is the norm of that fixed
linear operator (Chebyshev), or of S^{-1} to ``AMG_TOL`` (pyamg). P0, S^{-1} and this norm are
``model.metric``'s (the natural metric the certificate measures stationarity in, on every backend);
the preconditioners here add the cB and rho_A terms.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vesicle_opt.model.band_coarse import GN_DELTA  # the bulk model's share in P_GN (defined there)
from vesicle_opt.model.metric import (AMG_MAXITER, AMG_TOL, CHEB_MAX_STEPS, CHEB_TOL, LU_MAX_NODES,  # noqa: F401
                                      FourierMetric, SparseMetric, amg_solver, chebyshev_bounds,
                                      chebyshev_inverse, chebyshev_steps)

FLOOR = 0.1  # the model never drops below 10% of its (positive) bending part


class FourierPreconditioner:
    def __init__(self, fourier, m: float, epsilon: float):
        self.metric = FourierMetric(fourier, m, epsilon)
        self.f, self.m, self.eps = fourier, self.metric.m, self.metric.eps
        self._q = self.metric.q  # symbol of M_L^{-1} S
        self._p0 = self.metric.p0
        self._p0_inv = self.metric.p0_inv

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
        return self.metric.dual_norm(v)


class SparsePreconditioner:
    """The model above for P1 lumped meshes; ``kind`` (lu, chebyshev, pyamg) picks S^{-1}, by
    default LU up to ``LU_MAX_NODES``, else Chebyshev up to ``CHEB_MAX_STEPS``, else pyamg-CG
    (``model.metric.SparseMetric``)."""

    def __init__(self, K, m: np.ndarray, epsilon: float, dim: int = 2, kind: str | None = None):
        self.metric = SparseMetric(K, m, epsilon, dim, kind)
        self.m, self.eps, self.S = self.metric.m, self.metric.eps, self.metric.S
        self.steps, self.kind, self._S_inv = self.metric.steps, self.metric.kind, self.metric.S_inv
        self.K = K  # as given (no copy: only ``gauss_newton`` reads it, on 2D meshes)
        self._bulk = None  # (1/eps) S M_L^{-1} S, formed on first use (``gauss_newton``)

    def gauss_newton_matrix(self, g_prime: np.ndarray, cE: float, cB: float = 0.0) -> sp.csc_matrix:
        """P_GN (module docstring) at the field whose g'(phi) is ``g_prime`` (``State.s``), sparse."""
        Mi = sp.diags(1.0 / self.m)
        if self._bulk is None:
            S = sp.csc_matrix(self.S)
            self._bulk = sp.csc_matrix(S @ Mi @ S) / self.eps
        J = sp.csc_matrix(-self.eps * self.K + sp.diags(self.m * np.asarray(g_prime, float)))
        P = (cE / self.eps) * (J @ Mi @ J) + (GN_DELTA * cE) * self._bulk
        if cB > 0:
            P = P + cB * sp.csc_matrix(self.S)
        return sp.csc_matrix(P)

    def gauss_newton(self, g_prime: np.ndarray, cE: float, cB: float = 0.0):
        """r -> P_GN^{-1} r by sparse LU, factored on the first call (a Newton step's trial points
        whose system is never solved cost nothing)."""
        lu: list = []

        def solve(r: np.ndarray) -> np.ndarray:
            if not lu:
                lu.append(spla.splu(self.gauss_newton_matrix(g_prime, cE, cB)))
            return lu[0].solve(np.asarray(r, float))
        return solve

    def _p0_inv(self, r: np.ndarray) -> np.ndarray:
        return self.metric.p0_inv(r)

    def inverse(self, cE: float, cB: float = 0.0, rho_A: float = 0.0):
        return lambda r: self._p0_inv(r) / cE

    def model(self, cE: float):
        """v -> cE P0 v = (cE/eps) S M_L^{-1} S v, exactly (sparse products; SPD)."""
        return lambda v: cE / self.eps * (self.S @ ((self.S @ v) / self.m))

    def dual_norm(self, v: np.ndarray) -> float:
        return self.metric.dual_norm(v)
