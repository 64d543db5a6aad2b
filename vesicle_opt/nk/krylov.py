"""Preconditioned conjugate gradients on a subspace, for inexact Newton steps.

``projected_pcg`` solves H x = b for x in V = {x : C^T x = 0} (C a few columns: the translation
modes on periodic boxes, weighted by m so that V is L2-orthogonal to them) with the constraint
preconditioner of Gould, Hribar and Nocedal: z = P^{-1} r - U (C^T U)^{-1} C^T P^{-1} r,
U = P^{-1} C, which keeps every iterate in V, applied with their residual update (the residual
is replaced by r - C (C^T U)^{-1} U^T r, which tends to 0: ``SubspacePreconditioner``). Stopping
is on the preconditioned residual sqrt(r^T z), the dual norm of the residual, relative to its
initial value (forcing term eta).
Nonpositive curvature p^T H p <= 0 ends the iteration (truncated CG, Steihaug): the iterate so far
is a descent direction; at the first iteration the preconditioned gradient direction is returned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vesicle_opt.blas import axpy, gemv


@dataclass
class CGResult:
    x: np.ndarray
    iterations: int
    status: str  # "converged" | "max_iter" | "negative_curvature"
    rel_residual: float


class SubspacePreconditioner:
    """z = P^{-1} r projected onto {C^T z = 0} along U = P^{-1} C (see module docstring), in the
    residual-update form of Gould, Hribar and Nocedal (2001): with y = S^{-1} U^T r (= S^{-1} C^T
    P^{-1} r, P symmetric), z = P^{-1} r - U y = P^{-1} (r - C y), and **r is replaced in place by
    the reduced residual r - C y**. CG is the same in exact arithmetic (r.z is unchanged, C^T z = 0);
    in floating point it is not: without the update r tends to C lambda, not to 0, and z is the small
    difference of two O(|r|) vectors, so the relative residual stalled near 1e-9 and the iterates
    then left the subspace (measured on random 40 x 40 problems: 7 of 20 seeds, |C^T x| up to 0.2;
``tests/nk/test_solve.py``), while r - C y tends to 0.
    ``apply_pinv`` returns a new array (every preconditioner of ``nk.precond`` does).

    C and U are held as rows (k x N, C order: ``C.T`` of an (N, k) view of rows costs no copy, as
    ``nk.setup``'s translations are given), so U^T r is one pass over contiguous rows and the update
    r -= C y one in-place BLAS gemv (no temporary the size of r)."""

    def __init__(self, apply_pinv, C: np.ndarray | None, writes_into: bool = False):
        self.apply_pinv = apply_pinv
        self.writes_into = writes_into  # apply_pinv(r, out) writes into a given array (``__call__``)
        self.C = None if C is None or C.shape[1] == 0 else np.asarray(C, dtype=float)
        if self.C is not None:
            C_rows = np.ascontiguousarray(self.C.T)
            self.C = C_rows.T  # (N, k), Fortran order: what gemv reads without a copy
            self.U_rows = [apply_pinv(c) for c in C_rows]
            # U^T C = C^T P^{-1} C, k x k (k <= 3), and its inverse: y is then a k x k product
            # (np.linalg.solve costs ~70 us a call, a tenth of a 64^3 iteration's vector work)
            self.S = np.array([[u @ c for c in C_rows] for u in self.U_rows])
            self.S_inv = np.linalg.inv(self.S)

    def __call__(self, r: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """z = P^{-1} (r - C y), r replaced by r - C y (class docstring). U^T r is k dot products:
        a dgemv on k contiguous rows runs at a third of their speed (64^3, k = 3: 0.21 against
        0.08 ms, measured; OpenBLAS's thin transposed kernel). ``out``: an array z may be written
        into (a spent CG direction), used where ``writes_into``."""
        if self.C is not None:
            gemv(-1.0, self.C, self.S_inv @ np.array([u @ r for u in self.U_rows]), r)
        if self.writes_into and out is not None:
            return self.apply_pinv(r, out)
        return self.apply_pinv(r)


def projected_pcg(hvp, b: np.ndarray, precond: SubspacePreconditioner, eta: float,
                  max_iter: int) -> CGResult:
    x = np.zeros_like(b)
    r = b.copy()
    z = precond(r)
    rz = float(r @ z)
    if rz <= 0.0:
        return CGResult(x, 0, "converged", 0.0)
    rz0 = rz
    p = z  # (z is rebound, never written, before p is first updated)
    spare = None  # the spent direction's array, which the next z may be written into
    for it in range(1, max_iter + 1):
        Hp = hvp(p)
        curv = float(p @ Hp)
        if curv <= 0.0:
            if it == 1:
                return CGResult(z, it, "negative_curvature", 1.0)
            return CGResult(x, it, "negative_curvature", float(np.sqrt(rz / rz0)))
        a = rz / curv
        axpy(a, p, x)  # x += a p
        axpy(-a, Hp, r)  # r -= a Hp
        z = precond(r, spare)
        rz_new = float(r @ z)
        rel = float(np.sqrt(max(rz_new, 0.0) / rz0))
        if rel <= eta:
            return CGResult(x, it, "converged", rel)
        axpy(rz_new / rz, p, z)  # p = z + (rz_new / rz) p, formed in z (one pass; z is not needed again)
        p, spare = z, p
        rz = rz_new
    return CGResult(x, max_iter, "max_iter", rel)
