"""The shift-invert solve of the assembled second-order check (``verify.second_order``) on lumped
meshes.

The check needs the smallest eigenvalues of H v = mu M v on the tangent space T = {C^T v = 0} (C:
the constraint gradients dA, dB and, on a refined meridian mesh, the solve's pin). Its inverse
operator is the bordered solve

    [[H - s M, C], [C^T, 0]] [v; y] = [b; 0]

done here by the Schur complement on the few columns of C (``Bordered``): one sparse factorisation
of the n x n matrix K = H - s M and k + 1 solves with it, instead of one LU of the bordered matrix
whose dense rows C^T (dA is nonzero at every node) filled it twice as much (measured, 20.3 k-node
refined meridian mesh at eps/R0 = 0.02: fill 8.1 M against 3.0-4.0 M, LU 0.31 s against 0.22 s
CPU). The factorisation of K is the LDL^T of ``verify.ldl`` (QDLDL, its ordering kept per pattern:
0.066 s there) where the optional extra ``ldl`` is installed and its factors pass the test below,
else SuperLU's LU (symmetric mode, minimum degree on K + K^T). Every factorisation is tested by
the bordered residual of a solve with a random right-hand side (``RESIDUAL``): a K that is nearly
singular (s close to an eigenvalue of H on the whole space) or an LDL^T spoilt by a tiny pivot (it
does not pivot) fails it; after the LDL^T the LU is tried, after the LU the caller factorises the
bordered matrix itself. Whichever passes, the check's eigenvalues and error bounds are its own
(residuals with H itself, ``verify.second_order``).

(Tried and dropped: a walk's neighbouring factorisation as LOBPCG's preconditioner from the
neighbour's eigenvectors. The interface moves by ~eps/4 a step at eps/R0 = 0.02 and its modes with
it: the neighbour's least eigenvector has a Rayleigh quotient of 25 mu_ref at the next point against
its 0.005, and 12 iterations ended with error bounds ~1; with this point's own factorisation, 6
iterations, 0.15 s CPU against ARPACK's 0.18 s, for the floor-limited bounds 1.4e-7.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vesicle_opt.verify import ldl as LDL


RESIDUAL = 1e-8  # a bordered test solve's relative residual above this: K too close to singular


@dataclass
class Bordered:
    """(H - s M, C)^{-1}: the bordered solve by the Schur complement on C (module docstring)."""

    lu: object  # K^{-1} for K = H - s M: a ``verify.ldl.Factor`` or SuperLU's LU (``solve``)
    shift: float  # s, physical units (mu_ref times the relative shift)
    C: np.ndarray  # n x m constraint columns
    Z: np.ndarray  # K^{-1} C
    S: np.ndarray  # C^T K^{-1} C (m x m)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """v with [[K, C], [C^T, 0]] [v; y] = [b; 0] (b: n or n x k)."""
        v = self.lu.solve(np.asarray(b, float))
        y = np.linalg.solve(self.S, self.C.T @ v)
        return v - self.Z @ y

    def with_constraints(self, C: np.ndarray) -> "Bordered":
        """The same factorisation bordered by other constraint columns (a neighbouring point's)."""
        Z = self.lu.solve(np.ascontiguousarray(C))
        return Bordered(self.lu, self.shift, C, Z, C.T @ Z)


def _superlu(K: sp.csc_matrix):
    try:
        return spla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options={"SymmetricMode": True})
    except RuntimeError:  # exactly singular
        return None


def _tested(solver, H, M, shift: float, C: np.ndarray) -> Bordered | None:
    """``solver`` (K^{-1}) bordered by C, or None where its bordered test solve misses ``RESIDUAL``."""
    out = Bordered(solver, shift, np.zeros((H.shape[0], 0)), np.zeros((H.shape[0], 0)), np.zeros((0, 0)))
    b = np.random.default_rng(0).standard_normal(H.shape[0])
    with np.errstate(all="ignore"):  # non-finite factors (an LDL^T's zero pivot) fail the test below
        try:
            out = out.with_constraints(C)
            v = out.solve(b)
            y = np.linalg.solve(out.S, C.T @ out.lu.solve(b))
        except np.linalg.LinAlgError:
            return None
        r = H @ v - shift * (M @ v) + C @ y - b
        ok = np.all(np.isfinite(v)) and np.linalg.norm(r) <= RESIDUAL * np.linalg.norm(b) \
            and np.abs(C.T @ v).max() <= RESIDUAL * np.abs(C).sum(axis=0).max() * np.abs(v).max()
    return out if ok else None


def factorise(H: sp.spmatrix, M: sp.spmatrix, shift: float, C: np.ndarray, ldl_first: bool = True) -> Bordered | None:
    """The bordered solve at shift s (physical units): the LDL^T of H - s M (``verify.ldl``, M
    diagonal) where it loads and passes the bordered test solve (``RESIDUAL``), else the LU; None
    where both fail (K nearly singular: module docstring). ``ldl_first=False``: the LU alone."""
    M = sp.csr_matrix(M)
    m = M.diagonal()
    if ldl_first and M.nnz == np.count_nonzero(m):  # a diagonal M (lumped mass)
        factor = LDL.factor(H, m, shift)
        out = _tested(factor, H, M, shift, C) if factor is not None else None
        if out is not None:
            return out
    lu = _superlu((H - shift * M).tocsc())
    return _tested(lu, H, M, shift, C) if lu is not None else None
