"""Preconditioned conjugate gradients on a subspace, for inexact Newton steps.

``projected_pcg`` solves H x = b for x in V = {x : C^T x = 0} (C a few columns: the translation
modes on periodic boxes, weighted by m so that V is L2-orthogonal to them) with the constraint
preconditioner of Gould, Hribar and Nocedal: z = P^{-1} r - U (C^T U)^{-1} C^T P^{-1} r,
U = P^{-1} C, which keeps every iterate in V. Stopping is on the preconditioned residual
sqrt(r^T z), the dual norm of the residual, relative to its initial value (forcing term eta).
Nonpositive curvature p^T H p <= 0 ends the iteration (truncated CG, Steihaug): the iterate so far
is a descent direction; at the first iteration the preconditioned gradient direction is returned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class CGResult:
    x: np.ndarray
    iterations: int
    status: str  # "converged" | "max_iter" | "negative_curvature"
    rel_residual: float


class SubspacePreconditioner:
    """z = P^{-1} r projected onto {C^T z = 0} along U = P^{-1} C (see module docstring).
    ``apply_pinv`` returns a new array (every preconditioner of ``nk.precond`` does): the projection
    updates it in place, so an ``apply_pinv`` that returned r itself would overwrite the caller's r."""

    def __init__(self, apply_pinv, C: np.ndarray | None):
        self.apply_pinv = apply_pinv
        self.C = None if C is None or C.shape[1] == 0 else C
        if self.C is not None:
            self.U = np.column_stack([apply_pinv(c) for c in self.C.T])
            self.S = self.C.T @ self.U

    def __call__(self, r: np.ndarray) -> np.ndarray:
        z = self.apply_pinv(r)
        if self.C is not None:
            z -= self.U @ np.linalg.solve(self.S, self.C.T @ z)
        return z


def projected_pcg(hvp, b: np.ndarray, precond: SubspacePreconditioner, eta: float,
                  max_iter: int) -> CGResult:
    x = np.zeros_like(b)
    r = b.copy()
    z = precond(r)
    rz = float(r @ z)
    if rz <= 0.0:
        return CGResult(x, 0, "converged", 0.0)
    rz0 = rz
    p = z.copy()
    for it in range(1, max_iter + 1):
        Hp = hvp(p)
        curv = float(p @ Hp)
        if curv <= 0.0:
            if it == 1:
                return CGResult(z, it, "negative_curvature", 1.0)
            return CGResult(x, it, "negative_curvature", float(np.sqrt(rz / rz0)))
        a = rz / curv
        x += a * p
        r -= a * Hp
        z = precond(r)
        rz_new = float(r @ z)
        rel = float(np.sqrt(max(rz_new, 0.0) / rz0))
        if rel <= eta:
            return CGResult(x, it, "converged", rel)
        p *= rz_new / rz  # p = z + (rz_new / rz) p, in place (the same bits: + commutes)
        p += z
        rz = rz_new
    return CGResult(x, max_iter, "max_iter", rel)
