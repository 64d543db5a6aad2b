"""A small preconditioned block eigensolver (LOBPCG, Knyazev 2001) on a subspace, hand-rolled.

Smallest eigenpairs of a symmetric operator A on V = {u : Q^T u = 0} (Q orthonormal columns, the
excluded directions), standard metric: the caller has put its mass metric into the variables
(``verify.lobpcg`` works in u = M^{1/2} v). Each iteration applies A and the preconditioner T to the
k new directions only (A X and A P are carried along by linearity), orthonormalises the search space
[X, W, P] (at most 3k columns: a few N x 3k products, no dense N x N algebra), and does
Rayleigh-Ritz on it. ``stop(theta, res)`` is asked after every iteration (Ritz values ascending and
their residual norms |A x - theta x|), so that the caller ends the iteration as soon as its
question is answered. scipy's ``lobpcg`` did the same iteration with N x (3k + constraints) Gram and
B-orthogonalisation work each step, which dominated its time on grids of 10^5-10^6 nodes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DROP = 1e-10  # search directions whose Gram eigenvalue is below DROP times the largest are dropped
# (numerically dependent: the converged residuals of LOBPCG are such directions)


@dataclass
class BlockResult:
    values: np.ndarray  # Ritz values, ascending
    vectors: np.ndarray  # orthonormal Ritz vectors (columns, in V)
    a_vectors: np.ndarray  # A applied to them (recomputed exactly at the end)
    residuals: np.ndarray  # |A x - theta x| per pair (exact products)
    iterations: int
    history: list  # (theta_0, residual_0) per iteration


def _project(U, Q):
    return U if Q is None else U - Q @ (Q.T @ U)


def _orthonormal(S, *against):
    """Orthonormal basis of span(S) with the components along the (orthonormal) ``against`` blocks
    removed, twice (classical Gram-Schmidt, then SVQB with dropping of dependent directions);
    returns (basis, coefficients) with basis = S @ coefficients (up to the removed components)."""
    for _ in range(2):
        for B in against:
            S = S - B @ (B.T @ S)
    G = S.T @ S
    w, V = np.linalg.eigh(G)
    keep = w > DROP * max(w.max(), np.finfo(float).tiny)
    C = V[:, keep] / np.sqrt(w[keep])
    return S @ C, C


def lobpcg(apply_a, apply_t, X0: np.ndarray, Q: np.ndarray | None, max_iter: int, stop) -> BlockResult:
    """LOBPCG for the smallest eigenpairs of A on {Q^T u = 0} from the block X0 (columns)."""
    k = X0.shape[1]
    X, _ = _orthonormal(_project(X0, Q))
    AX = _project(apply_a(X), Q)
    theta, C = np.linalg.eigh(X.T @ AX)
    X, AX = X @ C, AX @ C
    P = AP = None
    history = []
    it = 0
    for it in range(1, max_iter + 1):
        R = AX - X * theta
        res = np.linalg.norm(R, axis=0)
        history.append((float(theta[0]), float(res[0])))
        if stop(theta, res):
            break
        W = _project(apply_t(R), Q)
        blocks = [W] if P is None else [W, P]
        # W and P orthonormalised against X; [W, P] as one block (A on W exact, on P by linearity)
        S_raw = np.hstack(blocks)
        S, Cs = _orthonormal(S_raw, X)
        AW = _project(apply_a(W), Q)
        AS_raw = AW if P is None else np.hstack([AW, AP])
        # A (S_raw - X X^T S_raw) applied twice-projected: A S = (A S_raw - A X (X^T S_raw)) C
        S_raw_x = S_raw
        for _ in range(2):
            coef = X.T @ S_raw_x
            AS_raw = AS_raw - AX @ coef
            S_raw_x = S_raw_x - X @ coef
        AS = AS_raw @ Cs
        basis = np.hstack([X, S])
        a_basis = np.hstack([AX, AS])
        G = basis.T @ a_basis
        G = (G + G.T) / 2
        vals, Y = np.linalg.eigh(G)
        Y = Y[:, :k]
        theta = vals[:k]
        X_new, AX_new = basis @ Y, a_basis @ Y
        # the new P: the part of the update outside the old X
        P, AP = S @ Y[k:], AS @ Y[k:]
        X, AX = X_new, AX_new
        if P.shape[1] == 0 or not np.all(np.isfinite(P)):
            P = AP = None
    # exact products for the reported residuals (the carried A X accumulates round-off)
    X, _ = _orthonormal(X)
    AX = _project(apply_a(X), Q)
    theta, C = np.linalg.eigh((X.T @ AX + (X.T @ AX).T) / 2)
    X, AX = X @ C, AX @ C
    res = np.linalg.norm(AX - X * theta, axis=0)
    return BlockResult(theta, X, AX, res, it, history)


def rayleigh_ritz(apply_a, X0: np.ndarray, Q: np.ndarray | None, k: int) -> np.ndarray:
    """The k lowest Ritz vectors of A on span(X0) projected onto {Q^T u = 0} (a start block)."""
    X, _ = _orthonormal(_project(X0, Q))
    AX = _project(apply_a(X), Q)
    G = X.T @ AX
    _, C = np.linalg.eigh((G + G.T) / 2)
    return X @ C[:, :k]
