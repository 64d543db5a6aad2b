"""A plain Newton solver for F(x) = 0 with a sparse Jacobian (SuperLU), physics-free.

The Jacobian may be given in bordered form (J0, U, V, D), meaning [[J0, U], [V^T, D]] with J0
sparse n x n and U, V n x b dense (b = 1, 2 scalar unknowns such as multipliers): then only J0 is
factorised (SuperLU, minimum-degree ordering on J0 + J0^T) and the border goes through the b x b
Schur complement D - V^T J0^{-1} U, which keeps dense rows/columns out of the sparse factor.

On matrix-free grids the Jacobian comes as a :class:`KrylovBordered` (J0 a product, plus an
approximate inverse P ~ J0^{-1}); the bordered system is solved by GMRES (restart ``RESTART``,
relative tolerance ``GMRES_RTOL``) preconditioned by the block-LU inverse built from P:
z = P r, y = S^{-1}(s - V^T z), x = (z - P U y, y) with S = D - V^T P U, which is the exact inverse
when P = J0^{-1}.

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


GMRES_RTOL = 1e-11  # linear solves this accurate keep the Newton convergence test (dx <= 1e-12)
# meaningful: the inexact Newton error contracts by ~this factor per step
RESTART = 80
GMRES_MAXITER = 4  # restarts (at most 320 products a solve; a Newton that needs more is rejected)


@dataclass(frozen=True)
class KrylovBordered:
    """[[J0, U], [V^T, D]] with J0 given as a product and P an approximate J0^{-1}."""

    J0: Callable[[np.ndarray], np.ndarray]
    U: np.ndarray
    V: np.ndarray
    D: np.ndarray
    P: Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class NewtonResult:
    x: np.ndarray
    converged: bool
    iterations: int
    residual: float  # ||F(x)||_inf at the returned x (before the last update's effect is known)
    message: str
    linear_iterations: int = 0  # GMRES iterations summed over the Newton steps (0: direct solves)


def newton(F: Callable[[np.ndarray], np.ndarray], J: Callable[[np.ndarray], sp.spmatrix],
           x0: np.ndarray, xtol: float = 1e-12, max_iter: int = 25, blowup: float = 1e3,
           watch: slice = slice(None)) -> NewtonResult:
    """Solve F(x) = 0 from x0. ``watch`` selects the entries (the field, not auxiliary scalars
    such as multipliers) tested against ``xtol`` and ``blowup``."""
    x = np.array(x0, float)
    res = np.inf
    lin = [0]
    for it in range(1, max_iter + 1):
        try:
            with np.errstate(all="raise"):
                r = F(x)
                res = float(np.max(np.abs(r)))
                dx = _solve(J(x), -r, lin)
        except (FloatingPointError, RuntimeError) as exc:  # overflow, singular factor
            return NewtonResult(x, False, it, res, f"newton failed: {exc}", lin[0])
        if not np.all(np.isfinite(dx)):
            return NewtonResult(x, False, it, res, "newton failed: non-finite update", lin[0])
        x = x + dx
        if np.max(np.abs(x[watch])) > blowup:
            return NewtonResult(x, False, it, res, "newton diverged", lin[0])
        if np.max(np.abs(dx[watch])) <= xtol:
            with np.errstate(all="ignore"):
                res = float(np.max(np.abs(F(x))))
            return NewtonResult(x, np.isfinite(res), it, res, "converged", lin[0])
    return NewtonResult(x, False, max_iter, res, f"newton: no convergence in {max_iter} iterations", lin[0])


def _solve_krylov(jac: KrylovBordered, rhs: np.ndarray, count: list) -> np.ndarray:
    n, b = jac.U.shape
    PU = np.column_stack([jac.P(jac.U[:, j]) for j in range(b)])
    S = np.atleast_2d(jac.D) - jac.V.T @ PU

    def A(x):
        return np.concatenate([jac.J0(x[:n]) + jac.U @ x[n:], jac.V.T @ x[:n] + jac.D @ x[n:]])

    def prec(r):
        z = jac.P(r[:n])
        y = np.linalg.solve(S, r[n:] - jac.V.T @ z)
        return np.concatenate([z - PU @ y, y])

    N = n + b
    op = spla.LinearOperator((N, N), matvec=A, dtype=float)
    Mop = spla.LinearOperator((N, N), matvec=prec, dtype=float)

    def tick(_):
        count[0] += 1

    x, info = spla.gmres(op, rhs, rtol=GMRES_RTOL, atol=0.0, restart=RESTART, maxiter=GMRES_MAXITER, M=Mop,
                         callback=tick, callback_type="pr_norm")
    if info != 0:
        raise RuntimeError(f"GMRES did not reach {GMRES_RTOL:g} (info {info})")
    return x


def _solve(jac, rhs: np.ndarray, count: list) -> np.ndarray:
    if isinstance(jac, KrylovBordered):
        return _solve_krylov(jac, rhs, count)
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
