"""GMRES on BLAS: Arnoldi by classical Gram-Schmidt with selective reorthogonalisation.

Solves A x = b for a linear map ``matvec`` (Saad & Schultz, SIAM J. Sci. Stat. Comput. 7 (1986)):
x_j minimises |b - A x|_2 over the Krylov space K_j(A, b), x0 = 0, restarted every ``restart``
iterations from the true residual. The Arnoldi basis is orthogonalised by classical Gram-Schmidt,
two BLAS gemv passes over the basis (h = V w, w -= V^T h). One pass loses orthogonality as
eps kappa^2 of the Krylov matrix [b, A V] (Giraud, Langou & Rozloznik, Comput. Math. Appl. 50 (2005)),
and GMRES's Krylov matrix has kappa ~ |b| / |r_j| (Paige & Strakos): while the residual estimate is
above ``ONE_PASS_DOWN_TO`` = 1e-4 |b| the loss stays below 2.2e-16 x 1e8 = 2e-8 and one pass is
kept (PETSc's GMRES default: classical Gram-Schmidt, no refinement). Below it a second pass is made
where the new vector lost more than 1 - 1/sqrt(2) of its norm (Daniel, Gragg, Kaufman & Stewart,
Math. Comp. 30 (1976): "twice is enough"), which keeps the basis orthonormal to round-off and the
residual estimate |g_j| (Givens rotations of the Hessenberg matrix) the true residual's norm.

Why not ``scipy.sparse.linalg.gmres``: the same iterates, but its modified Gram-Schmidt is a Python
loop of a dot and a temporary-forming axpy per basis vector, and every cycle ends with one more
product to test the true residual. On the bordered systems of ``branch.krylov_bordered`` at 525 k
nodes (the octant prolate walk of ``studies.bench_branch_3d``, ~21 iterations a solve) that loop
took 17 ms an iteration against 45 ms for the operator itself (profiled: 8.0 of 52 CPU s), and it
grows as nodes x iterations^2. On 525 k unknowns, 23 iterations to 1e-6 (``tests/nk/test_gmres.py``'s
kind of system, a cheap operator): 0.31-0.35 CPU s of orthogonalisation in scipy's, 0.13-0.15 in one
pass, 0.24-0.28 with the second pass everywhere. ``tests/nk/test_gmres.py`` checks the iterates
against scipy's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular
from scipy.linalg.lapack import dlartg

from vesicle_opt.blas import gemv

REORTHOGONALISE = 1.0 / np.sqrt(2.0)  # DGKS: a second pass where |w| fell below this share of its norm
ONE_PASS_DOWN_TO = 1e-4  # the residual estimate (relative) down to which one pass is kept (module docstring)


@dataclass(frozen=True)
class GmresResult:
    x: np.ndarray
    iterations: int  # products with A inside the Arnoldi cycles (the restarts' residuals not counted)
    converged: bool  # the residual estimate reached rtol |b|
    residual: float  # the last residual estimate |b - A x|_2 / |b|_2


def gmres(matvec, b: np.ndarray, rtol: float, max_iter: int, restart: int) -> GmresResult:
    """x with |b - A x|_2 <= rtol |b|_2 (module docstring), at most ``max_iter`` products in cycles of
    ``restart``; x = 0 where b = 0."""
    b = np.asarray(b, float)
    n = b.size
    bnorm = float(np.linalg.norm(b))
    x = np.zeros(n)
    if bnorm == 0.0:
        return GmresResult(x, 0, True, 0.0)
    m = max(1, min(int(restart), int(max_iter), n))
    V = np.empty((m + 1, n))
    H = np.zeros((m + 1, m))
    its, r, est = 0, b, 1.0
    while its < max_iter:
        beta = float(np.linalg.norm(r))
        if beta <= rtol * bnorm:
            return GmresResult(x, its, True, beta / bnorm)
        np.multiply(r, 1.0 / beta, out=V[0])
        est = beta / bnorm
        g = np.zeros(m + 1)
        g[0] = beta
        rot = np.zeros((m, 2))
        H[:] = 0.0
        j, done = 0, False
        while j < m and its < max_iter:
            w = V[j + 1]  # the new basis vector, orthogonalised and normalised in place
            w[:] = matvec(V[j])
            its += 1
            before = float(np.linalg.norm(w))
            h = V[:j + 1] @ w
            gemv(-1.0, V[:j + 1].T, h, w)
            after = float(np.linalg.norm(w))
            if est < ONE_PASS_DOWN_TO and after < REORTHOGONALISE * before:
                h2 = V[:j + 1] @ w
                gemv(-1.0, V[:j + 1].T, h2, w)
                h += h2
                after = float(np.linalg.norm(w))
            if not np.isfinite(after):  # a non-finite product: no solution in this space
                return GmresResult(x, its, False, float("nan"))
            H[:j + 1, j] = h
            H[j + 1, j] = after
            breakdown = after <= np.finfo(float).eps * max(before, np.finfo(float).tiny)
            if not breakdown:
                w *= 1.0 / after
            for i in range(j):  # the previous rotations on the new column
                c, s = rot[i]
                H[i, j], H[i + 1, j] = c * H[i, j] + s * H[i + 1, j], -s * H[i, j] + c * H[i + 1, j]
            c, s, rho = dlartg(H[j, j], H[j + 1, j])
            rot[j] = c, s
            H[j, j], H[j + 1, j] = rho, 0.0
            g[j], g[j + 1] = c * g[j], -s * g[j]
            j += 1
            est = abs(g[j]) / bnorm
            if est <= rtol or breakdown:
                done = True
                break
        k = j
        if k and H[k - 1, k - 1] == 0.0:  # a singular A on the space: the least-squares step drops it
            k -= 1
        if k:
            y = solve_triangular(H[:k, :k], g[:k], lower=False, check_finite=False)
            gemv(1.0, V[:k].T, y, x)
        if done or its >= max_iter:
            return GmresResult(x, its, est <= rtol, est)
        r = b - np.asarray(matvec(x), float)  # restart from the true residual
    return GmresResult(x, its, est <= rtol, est)
