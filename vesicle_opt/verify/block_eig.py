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
    vectors: np.ndarray  # orthonormal Ritz vectors (rows, in V)
    a_vectors: np.ndarray  # A applied to them (recomputed exactly at the end)
    residuals: np.ndarray  # |A x - theta x| per pair (exact products)
    iterations: int
    history: list  # (theta_0, residual_0) per iteration


def _project(U, Q):
    """U (rows: vectors) minus its components along the rows of Q (orthonormal)."""
    return U if Q is None else U - (U @ Q.T) @ Q


def _orthonormal(S, *against):
    """Orthonormal rows spanning the rows of S with the components along the (orthonormal) rows of
    ``against`` removed, twice (classical Gram-Schmidt, then SVQB with dropping of dependent
    directions); returns (basis, coefficients) with basis = coefficients @ S (up to the removed
    components)."""
    for _ in range(2):
        for B in against:
            S = S - (S @ B.T) @ B
    G = S @ S.T
    w, V = np.linalg.eigh((G + G.T) / 2)
    keep = w > DROP * max(w.max(), np.finfo(float).tiny)
    C = (V[:, keep] / np.sqrt(w[keep])).T
    return C @ S, C


def lobpcg(apply_a, apply_t, X0: np.ndarray, Q: np.ndarray | None, max_iter: int, stop) -> BlockResult:
    """LOBPCG for the smallest eigenpairs of A on {Q u = 0} from the block X0. Blocks are stored
    as rows (k x N, each vector contiguous: the FFTs and products read whole vectors)."""
    k = X0.shape[0]
    X, _ = _orthonormal(_project(X0, Q))
    AX = _project(apply_a(X), Q)
    theta, C = np.linalg.eigh((X @ AX.T + AX @ X.T) / 2)
    X, AX = C.T @ X, C.T @ AX
    P = AP = None
    history = []
    it = 0
    for it in range(1, max_iter + 1):
        R = AX - theta[:, None] * X
        res = np.linalg.norm(R, axis=1)
        history.append((float(theta[0]), float(res[0])))
        if stop(theta, res):
            break
        W = _project(apply_t(R), Q)
        del R
        AW = _project(apply_a(W), Q)
        # S = [W; P] orthonormalised against X, A S by linearity from [A W; A P]
        S = W if P is None else np.vstack([W, P])
        AS = AW if P is None else np.vstack([AW, AP])
        del W, AW, P, AP
        coef = S @ X.T  # one pass: X is orthonormal and SVQB below drops what cancels
        S -= coef @ X
        AS -= coef @ AX
        G = S @ S.T
        w, Vg = np.linalg.eigh((G + G.T) / 2)
        keep = w > DROP * max(float(w.max()), np.finfo(float).tiny)
        C = (Vg[:, keep] / np.sqrt(w[keep])).T
        S, AS = C @ S, C @ AS
        # Rayleigh-Ritz on [X; S] from its blocks (no copies of the whole basis)
        XAS = (X @ AS.T + AX @ S.T) / 2
        SAS = S @ AS.T
        G = np.block([[np.diag(theta), XAS], [XAS.T, (SAS + SAS.T) / 2]])
        vals, Y = np.linalg.eigh(G)
        Y1, Y2 = Y[:k, :k], Y[k:, :k]
        theta = vals[:k]
        P, AP = Y2.T @ S, Y2.T @ AS  # the new P: the part of the update outside the old X
        del S, AS
        X = Y1.T @ X + P
        AX = Y1.T @ AX + AP
        if P.shape[0] == 0 or not np.all(np.isfinite(P)):
            P = AP = None
    # exact products for the reported residuals (the carried A X accumulates round-off)
    X, _ = _orthonormal(X)
    AX = _project(apply_a(X), Q)
    theta, C = np.linalg.eigh((X @ AX.T + AX @ X.T) / 2)
    X, AX = C.T @ X, C.T @ AX
    res = np.linalg.norm(AX - theta[:, None] * X, axis=1)
    return BlockResult(theta, X, AX, res, it, history)


def rayleigh_ritz(apply_a, X0: np.ndarray, Q: np.ndarray | None, k: int) -> np.ndarray:
    """The k lowest Ritz vectors (rows) of A on the span of X0's rows projected onto {Q u = 0}."""
    X, _ = _orthonormal(_project(X0, Q))
    AX = _project(apply_a(X), Q)
    _, C = np.linalg.eigh((X @ AX.T + AX @ X.T) / 2)
    return C[:, :k].T @ X
