"""A plain Newton solver for F(x) = 0 with a sparse Jacobian (SuperLU), physics-free.

The Jacobian may be given in bordered form (J0, U, V, D), meaning [[J0, U], [V^T, D]] with J0
sparse n x n and U, V n x b dense (b = 1, 2 scalar unknowns such as multipliers): then only J0 is
factorised (SuperLU, minimum-degree ordering on J0 + J0^T) and the border goes through the b x b
Schur complement D - V^T J0^{-1} U, which keeps dense rows/columns out of the sparse factor.

Convergence: the Newton update satisfies ||dx||_inf <= xtol (the error after a quadratically
convergent step is O(dx^2), far below the energy-law residuals the schemes check). Failure modes
(reported, never returned as a solution): a singular or non-finite Jacobian solve, a non-finite
residual, an iterate leaving |x| <= blowup, or no convergence within max_iter.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


@dataclass(frozen=True)
class NewtonResult:
    x: np.ndarray
    converged: bool
    iterations: int
    residual: float  # ||F(x)||_inf at the returned x (before the last update's effect is known)
    message: str


def newton(F: Callable[[np.ndarray], np.ndarray], J: Callable[[np.ndarray], sp.spmatrix],
           x0: np.ndarray, xtol: float = 1e-12, max_iter: int = 25, blowup: float = 1e3,
           watch: slice = slice(None)) -> NewtonResult:
    """Solve F(x) = 0 from x0. ``watch`` selects the entries (the field, not auxiliary scalars
    such as multipliers) tested against ``xtol`` and ``blowup``."""
    x = np.array(x0, float)
    res = np.inf
    for it in range(1, max_iter + 1):
        try:
            with np.errstate(all="raise"):
                r = F(x)
                res = float(np.max(np.abs(r)))
                dx = _solve(J(x), -r)
        except (FloatingPointError, RuntimeError) as exc:  # overflow, singular factor
            return NewtonResult(x, False, it, res, f"newton failed: {exc}")
        if not np.all(np.isfinite(dx)):
            return NewtonResult(x, False, it, res, "newton failed: non-finite update")
        x = x + dx
        if np.max(np.abs(x[watch])) > blowup:
            return NewtonResult(x, False, it, res, "newton diverged")
        if np.max(np.abs(dx[watch])) <= xtol:
            with np.errstate(all="ignore"):
                res = float(np.max(np.abs(F(x))))
            return NewtonResult(x, np.isfinite(res), it, res, "converged")
    return NewtonResult(x, False, max_iter, res, f"newton: no convergence in {max_iter} iterations")


def _solve(jac, rhs: np.ndarray) -> np.ndarray:
    if not isinstance(jac, tuple):
        return spla.splu(sp.csc_matrix(jac), permc_spec="MMD_AT_PLUS_A").solve(rhs)
    J0, U, V, D = jac
    n = J0.shape[0]
    lu = spla.splu(sp.csc_matrix(J0), permc_spec="MMD_AT_PLUS_A")
    Z = lu.solve(np.column_stack([rhs[:n], U]))  # J0^{-1} [r, U]
    z_r, Z_u = Z[:, 0], Z[:, 1:]
    S = np.atleast_2d(D) - V.T @ Z_u
    y = np.linalg.solve(S, rhs[n:] - V.T @ z_r)
    return np.concatenate([z_r - Z_u @ y, y])
