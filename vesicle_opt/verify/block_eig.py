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

from vesicle_opt.blas import gemm_rows, subtract_projection

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


def _project(U, Q, overwrite: bool = False):
    """U (rows: vectors) minus its components along the rows of Q (orthonormal); in U itself where
    ``overwrite`` (a block of the caller's own: one in-place BLAS pass, ``blas.subtract_projection``)."""
    if Q is None:
        return U
    return subtract_projection(U if overwrite else U.copy(), Q)


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


def _combine(coefs, blocks):
    """sum_i coefs[i]^T blocks[i] (rows), accumulated in place (no k-row temporary)."""
    out = coefs[0].T @ blocks[0]
    for c, B in zip(coefs[1:], blocks[1:]):
        gemm_rows(1.0, c.T, B, out)
    return out


def _sym(G):
    return (G + G.T) / 2


def lobpcg(apply_a, apply_t, X0: np.ndarray, Q: np.ndarray | None, max_iter: int, stop,
           overwrite: bool = False) -> BlockResult:
    """LOBPCG for the smallest eigenpairs of A on {Q u = 0} from the block X0. Blocks are stored
    as rows (k x N, each vector contiguous: the FFTs and products read whole vectors).

    ``apply_a`` need not project its output onto {Q u = 0}: every product it enters is taken with
    vectors of that space (where A and its projection agree), and the residual is projected.
    Per iteration the search directions Z = [W; P] are orthogonalised against X explicitly (so P
    stays the part of the update outside X), and Rayleigh-Ritz on [X; Z] is done in the small space
    from the Gram matrices of Z (row-scaled, dependent directions dropped, SVQB): the orthonormal
    basis of Z is never formed, only the k new X, A X, P, A P (about 20 k^2 N flops an iteration).
    ``overwrite``: X0 is the caller's to give away: it is projected in place and dropped once X is
    formed, so that a start block passed as the call's only reference (``lobpcg(..., make_block(),
    ..., overwrite=True)``) is not held through the iteration (k rows less at the peak)."""
    k = X0.shape[0]
    X, _ = _orthonormal(_project(X0, Q, overwrite=overwrite))
    del X0
    AX = apply_a(X)
    theta, C = np.linalg.eigh(_sym(X @ AX.T))
    X, AX = C.T @ X, C.T @ AX
    P = AP = None
    history = []
    it = 0
    for it in range(1, max_iter + 1):
        R = _project(AX - theta[:, None] * X, Q, overwrite=True)  # X is in V: the same residual
        res = np.linalg.norm(R, axis=1)
        history.append((float(theta[0]), float(res[0])))
        if stop(theta, res):
            break
        W = _project(apply_t(R), Q, overwrite=True)
        del R
        AW = apply_a(W)
        Z, AZ = [W, P] if P is not None else [W], [AW, AP] if P is not None else [AW]
        del W, AW, P, AP
        for B, AB in zip(Z, AZ):  # one pass against X: SVQB below drops what cancels
            coef = B @ X.T
            gemm_rows(-1.0, coef, X, B)
            gemm_rows(-1.0, coef, AX, AB)
        del B, AB  # else the loop names keep the old P and A P alive to the next iteration (2k rows)
        # Gram matrices of Z and A on [X; Z] (A X X^T = diag(theta): X is a Ritz basis)
        nz = [B.shape[0] for B in Z]
        G = np.block([[Z[i] @ Z[j].T for j in range(len(Z))] for i in range(len(Z))])
        G = _sym(G)
        XAZ = np.hstack([AX @ B.T for B in Z])  # = X A Z^T on the subspace
        ZAZ = _sym(np.block([[Z[i] @ AZ[j].T for j in range(len(Z))] for i in range(len(Z))]))
        d = 1.0 / np.sqrt(np.maximum(np.diag(G), np.finfo(float).tiny))
        w, Vg = np.linalg.eigh(G * d[:, None] * d[None, :])
        keep = w > DROP * max(float(w.max()), np.finfo(float).tiny)
        Cz = d[:, None] * (Vg[:, keep] / np.sqrt(w[keep]))  # Z-coefficients of an orthonormal basis of Z
        Gs = np.block([[np.diag(theta), XAZ @ Cz], [Cz.T @ XAZ.T, _sym(Cz.T @ ZAZ @ Cz)]])
        vals, Y = np.linalg.eigh(Gs)
        theta = vals[:k]
        cx, cz = Y[:k, :k], Cz @ Y[k:, :k]  # new X = cx^T X + cz^T Z
        parts = np.split(cz, np.cumsum(nz)[:-1], axis=0)
        # the new P (the part of the update outside the old X), then X; A P, then A X: at most one
        # k-row temporary beside the blocks
        P = _combine(parts, Z)
        del Z
        X_new = cx.T @ X
        X_new += P
        X = X_new
        AP = _combine(parts, AZ)
        del AZ
        AX_new = cx.T @ AX
        AX_new += AP
        AX = AX_new
        del X_new, AX_new
        if not np.all(np.isfinite(P)):
            P = AP = None
    # exact products for the reported residuals (the carried A X accumulates round-off); the last
    # residual and P, A P are not needed for them (3k rows less at this end's peak)
    R = P = AP = None
    X, _ = _orthonormal(X)
    AX = _project(apply_a(X), Q, overwrite=True)
    theta, C = np.linalg.eigh(_sym(X @ AX.T))
    X, AX = C.T @ X, C.T @ AX
    res = np.linalg.norm(AX - theta[:, None] * X, axis=1)
    return BlockResult(theta, X, AX, res, it, history)


def rayleigh_ritz(apply_a, X0: np.ndarray, Q: np.ndarray | None, k: int, overwrite: bool = False) -> np.ndarray:
    """The k lowest Ritz vectors (rows) of A on the span of X0's rows projected onto {Q u = 0}.
    Only the Gram matrix X A X^T is needed (X in V: A's projection onto V gives the same), so A is
    applied one row at a time: the block and one vector, not the block twice. ``overwrite``: X0 is
    the caller's to give away: the projection and the orthonormal basis are formed in its rows."""
    S = _project(X0, Q, overwrite=overwrite)
    X, _ = _orthonormal(S)
    if overwrite:  # the basis into the block's own rows: the product block below is then all there is
        S[:X.shape[0]] = X
        X = S[:X.shape[0]]
    G = np.empty((X.shape[0], X.shape[0]))
    for j in range(X.shape[0]):
        G[:, j] = X @ apply_a(X[j:j + 1])[0]
    _, C = np.linalg.eigh((G + G.T) / 2)
    return C[:, :k].T @ X
