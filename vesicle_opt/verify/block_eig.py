"""A small preconditioned block eigensolver (LOBPCG, Knyazev 2001) on a subspace, hand-rolled.

Smallest eigenpairs of a symmetric operator A on V = {u : Q u = 0} (Q orthonormal rows, the
excluded directions), standard metric: the caller has put its mass metric into the variables
(``verify.lobpcg`` works in u = M^{1/2} v). Each iteration applies A and the preconditioner T to the
k new directions only (A X and A P are carried along by linearity), orthonormalises the search space
[X, W, P] (at most 3k columns: a few N x 3k products, no dense N x N algebra), and does
Rayleigh-Ritz on it. ``stop(theta, res)`` is asked after every iteration (Ritz values ascending and
their residual norms |A x - theta x|), so that the caller ends the iteration as soon as its
question is answered. scipy's ``lobpcg`` did the same iteration with N x (3k + constraints) Gram and
B-orthogonalisation work each step, which dominated its time on grids of 10^5-10^6 nodes.

Robustness (the iteration must not depend on how a BLAS kernel rounds; it once did: under OpenBLAS's
Haswell/Zen/Prescott kernels its iterates left V, lost orthonormality and reported Ritz values below
the spectrum):

* every block (X, W, P and their A-products) is projected onto V after it is formed, so round-off
  along Q is removed each iteration instead of accumulating (A itself need not be projected);
* the search directions are orthogonalised against X twice (block classical Gram-Schmidt, CGS2),
  their basis is an SVQB basis (Stathopoulos & Wu 2002) of the scaled Gram matrix with directions
  below ``DROP`` dropped, and where P is among the dropped (an ill-conditioned Gram matrix) the
  iteration restarts without P (Knyazev's remedy; scipy's ``lobpcg`` does the same);
* X is re-orthonormalised every iteration (Cholesky-QR, twice where the first pass left an error
  above ``REORTH``; SVQB where Cholesky fails) and Rayleigh-Ritz is done on its explicit Gram
  matrix X A X^T, not on the carried diagonal;
* the iteration also stops at its attainable floor: residuals below ``FLOOR`` eps ||A|| sqrt(N)
  (||A|| estimated by the largest Ritz value of the search spaces seen) cannot decrease further;
* the result is re-checked independently at the end (projected, orthonormalised, A applied afresh,
  Rayleigh-Ritz; ``BlockResult.reason`` says where the vectors were not orthonormal or not in V),
  and each Ritz value gets an error bound (``error_bounds``): the residual norm (Krylov-Weinstein,
  Bauer-Fike for symmetric A), sharpened by Kato-Temple r^2 / gap where the next Ritz interval is
  separated from it, never below the floor (the Ritz values' own round-off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scipy.linalg.blas import dtrsm

from vesicle_opt.blas import gemm_rows, subtract_projection

EPS = np.finfo(float).eps
DROP = 1e-8  # search directions whose scaled Gram eigenvalue is below DROP times the largest are dropped
# (numerically dependent: the converged residuals of LOBPCG are such directions). SVQB's basis then
# has an orthonormality error ~ eps / DROP ~ 2e-8 (was 1e-10: up to 2e-6, where the kernels diverged)
REORTH = 1e-10  # X's orthonormality error |X X^T - I| above which Cholesky-QR runs a second pass
FLOOR = 10.0  # the attainable residual: FLOOR eps ||A|| sqrt(N) (round-off of a length-N product with
# A's scale ||A||; measured on the 400 x 400 test, spectrum to 50: final residuals 2e-14..5e-13)
ACCEPT = 1e-8  # the final check: vectors with |X X^T - I| or |X Q^T| above this are reported (reason)


@dataclass
class BlockResult:
    values: np.ndarray  # Ritz values, ascending
    vectors: np.ndarray  # orthonormal Ritz vectors (rows, in V)
    a_vectors: np.ndarray  # A applied to them (recomputed exactly at the end, projected onto V)
    residuals: np.ndarray  # |A x - theta x| per pair (exact products)
    iterations: int
    history: list  # (theta_0, residual_0) per iteration
    errors: np.ndarray | None = None  # error bound per Ritz value (``error_bounds``)
    floor: float = 0.0  # the attainable residual (``FLOOR`` eps ||A|| sqrt(N))
    reason: str = ""  # why the result cannot be trusted ('' where the final check passed)


def _project(U, Q, overwrite: bool = False):
    """U (rows: vectors) minus its components along the rows of Q (orthonormal); in U itself where
    ``overwrite`` (a block of the caller's own: one in-place BLAS pass, ``blas.subtract_projection``)."""
    if Q is None:
        return U
    return subtract_projection(U if overwrite else U.copy(), Q)


def _sym(G):
    return (G + G.T) / 2


def _svqb(G):
    """Coefficients C (rows) with C G C^T = I on the directions of G kept (scaled Gram eigenvalues
    above ``DROP`` times the largest): SVQB."""
    d = 1.0 / np.sqrt(np.maximum(np.diag(G), np.finfo(float).tiny))
    w, V = np.linalg.eigh(_sym(G) * d[:, None] * d[None, :])
    keep = w > DROP * max(float(w.max()), np.finfo(float).tiny)
    return (V[:, keep] / np.sqrt(w[keep])).T * d[None, :], keep


def _cholesky_pass(X, *also) -> bool:
    """One Cholesky-QR pass in place: X <- L^{-1} X with L L^T = X X^T (BLAS dtrsm on the
    transposes, no copy), the blocks ``also`` alike (A X: linear); False where X X^T is not
    numerically positive definite (nothing changed)."""
    try:
        L = np.linalg.cholesky(_sym(X @ X.T))
    except np.linalg.LinAlgError:
        return False
    for B in (X, *also):
        out = dtrsm(1.0, L, B.T, side=1, lower=1, trans_a=1, overwrite_b=1)
        if not np.shares_memory(out, B):
            B[...] = out.T
    return True


def _orthonormal(S, *against):
    """Orthonormal rows spanning the rows of S with the components along the (orthonormal) rows of
    ``against`` removed, twice (classical Gram-Schmidt), then SVQB with dropping of dependent
    directions and a Cholesky-QR pass in place (orthonormal to round-off whatever S's condition);
    returns (basis, coefficients) with basis = coefficients @ S up to the removed components and
    the second pass (whose factor is within round-off of the identity)."""
    for _ in range(2):
        for B in against:
            S = S - (S @ B.T) @ B
    C, _ = _svqb(S @ S.T)
    X = C @ S
    if np.abs(_sym(X @ X.T) - np.eye(X.shape[0])).max() > REORTH:
        _cholesky_pass(X)
    return X, C


def _reorthonormalise(X, AX):
    """X, A X with X's rows orthonormalised in place (Cholesky-QR, a second pass where the first
    left an error above ``REORTH``; SVQB where Cholesky fails); A X transformed alike (linear)."""
    k = X.shape[0]
    for _ in range(2):
        G = _sym(X @ X.T)
        if np.abs(G - np.eye(k)).max() <= REORTH:
            break
        if not _cholesky_pass(X, AX):
            C, keep = _svqb(G)
            if not keep.all():
                raise np.linalg.LinAlgError("the Ritz block lost its rank")
            X, AX = C @ X, C @ AX
    return X, AX


def _combine(coefs, blocks):
    """sum_i coefs[i]^T blocks[i] (rows), accumulated in place (no k-row temporary)."""
    out = coefs[0].T @ blocks[0]
    for c, B in zip(coefs[1:], blocks[1:]):
        gemm_rows(1.0, c.T, B, out)
    return out


def _ritz(X, AX):
    """Rayleigh-Ritz in span(X) (orthonormal rows in V): (theta, X, A X) rotated to the Ritz basis."""
    theta, C = np.linalg.eigh(_sym(X @ AX.T))
    return theta, C.T @ X, C.T @ AX


def error_bounds(theta, res):
    """An error bound per Ritz value: each interval [theta_i - e_i, theta_i + e_i] holds an
    eigenvalue of A on V. e_i = r_i (Krylov-Weinstein: a symmetric A has an eigenvalue within the
    residual norm of any Rayleigh quotient), and the quadratic bound |R_C|_F^2 / delta where smaller
    (Kato-Temple; for a cluster C of Ritz values whose intervals [theta_j - r_j, theta_j + r_j]
    overlap, Mathias 1998 with the block residual R_C, |R_C|_F^2 = sum r_j^2 over C), delta the
    distance from the cluster's Ritz values to the neighbouring clusters' intervals (above; and below
    but for the lowest). It assumes no other eigenvalue between the cluster and those neighbours,
    i.e. that the block holds the least eigenvalues (the same trust as the Ritz values themselves);
    the cluster holding the block's largest value has no neighbour above and keeps r."""
    theta, res = np.asarray(theta, float), np.asarray(res, float)
    err = res.copy()
    k = len(theta)
    clusters, start = [], 0
    for i in range(1, k + 1):  # runs of overlapping intervals (theta ascending)
        if i == k or theta[i] - res[i] > theta[i - 1] + res[i - 1]:
            clusters.append(range(start, i))
            start = i
    for c, idx in enumerate(clusters[:-1]):
        nxt = clusters[c + 1]
        gaps = [min(theta[j] - res[j] for j in nxt) - theta[idx[-1]]]
        if c > 0:
            prev = clusters[c - 1]
            gaps.append(theta[idx[0]] - max(theta[j] + res[j] for j in prev))
        delta = min(gaps)
        if delta > 0:
            quad = float(np.sum(res[idx] ** 2)) / delta
            for j in idx:
                err[j] = min(res[j], quad)
    return err


def lobpcg(apply_a, apply_t, X0: np.ndarray, Q: np.ndarray | None, max_iter: int, stop,
           overwrite: bool = False) -> BlockResult:
    """LOBPCG for the smallest eigenpairs of A on {Q u = 0} from the block X0. Blocks are stored
    as rows (k x N, each vector contiguous: the FFTs and products read whole vectors).

    ``apply_a`` need not project its output onto {Q u = 0}: every product it returns is projected
    here (module docstring, robustness). Per iteration the search directions Z = [W; P] are
    orthogonalised against X twice (so P stays the part of the update outside X), and Rayleigh-Ritz
    on [X; Z] is done in the small space from the Gram matrices of Z (row-scaled, dependent directions
    dropped, SVQB; without P where P was among them): the orthonormal basis of Z is never formed,
    only the k new X, A X, P, A P. ``overwrite``: X0 is the caller's to give away: it is projected
    in place and dropped once X is formed, so that a start block passed as the call's only reference
    (``lobpcg(..., make_block(), ..., overwrite=True)``) is not held through the iteration."""
    k, n = X0.shape
    X, _ = _orthonormal(_project(X0, Q, overwrite=overwrite))
    del X0
    AX = _project(apply_a(X), Q, overwrite=True)
    theta, X, AX = _ritz(X, AX)
    anorm = float(np.abs(theta).max())
    P = AP = None
    history = []
    it = 0
    floor = 0.0
    for it in range(1, max_iter + 1):
        R = _project(AX - theta[:, None] * X, Q, overwrite=True)
        res = np.linalg.norm(R, axis=1)
        history.append((float(theta[0]), float(res[0])))
        floor = FLOOR * EPS * anorm * np.sqrt(n)
        if stop(theta, res) or bool(np.all(res <= floor)):
            break
        W = _project(apply_t(R), Q, overwrite=True)
        del R
        AW = _project(apply_a(W), Q, overwrite=True)
        Z, AZ = [W, P] if P is not None else [W], [AW, AP] if P is not None else [AW]
        del W, AW, P, AP
        for B, AB in zip(Z, AZ):  # against X twice (CGS2); A Z alike (linear)
            for _ in range(2):
                coef = B @ X.T
                gemm_rows(-1.0, coef, X, B)
                gemm_rows(-1.0, coef, AX, AB)
        del B, AB  # else the loop names keep the old P and A P alive to the next iteration (2k rows)
        for _ in range(2):
            nz = [B.shape[0] for B in Z]
            G = _sym(np.block([[Z[i] @ Z[j].T for j in range(len(Z))] for i in range(len(Z))]))
            Cz, keep = _svqb(G)
            if len(Z) == 1 or keep[nz[0]:].all():
                break
            Z, AZ = Z[:1], AZ[:1]  # P nearly dependent on [X, W]: restart without it
        Cz = Cz.T  # Z-coefficients of an orthonormal basis of Z (columns)
        XAZ = np.hstack([AX @ B.T for B in Z])  # = X A Z^T on V
        ZAZ = _sym(np.block([[Z[i] @ AZ[j].T for j in range(len(Z))] for i in range(len(Z))]))
        XAX = _sym(X @ AX.T)
        Gs = _sym(np.block([[XAX, XAZ @ Cz], [Cz.T @ XAZ.T, Cz.T @ ZAZ @ Cz]]))
        vals, Y = np.linalg.eigh(Gs)
        anorm = max(anorm, float(np.abs(vals).max()))
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
        if not (np.all(np.isfinite(P)) and np.all(np.isfinite(AP))):
            P = AP = None
        X = _project(X, Q, overwrite=True)
        X, AX = _reorthonormalise(X, AX)
        theta, X, AX = _ritz(X, AX)
    # the final check, independent of the carried products: X projected and orthonormalised, A
    # applied afresh, Rayleigh-Ritz; the last residual and P, A P are not needed (3k rows less)
    R = P = AP = None
    X = _project(X, Q, overwrite=True)
    X, _ = _orthonormal(X)
    AX = _project(apply_a(X), Q, overwrite=True)
    theta, X, AX = _ritz(X, AX)
    res = np.linalg.norm(AX - theta[:, None] * X, axis=1)
    anorm = max(anorm, float(np.abs(theta).max()))
    floor = FLOOR * EPS * anorm * np.sqrt(n)
    reason = ""
    orth = float(np.abs(X @ X.T - np.eye(X.shape[0])).max())
    off = 0.0 if Q is None else float(np.abs(X @ Q.T).max())
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(res))):
        reason = "lobpcg: non-finite Ritz values or residuals"
    elif X.shape[0] < k:
        reason = f"lobpcg: the block lost its rank ({X.shape[0]} of {k} vectors)"
    elif orth > ACCEPT or off > ACCEPT:
        reason = f"lobpcg: final vectors not orthonormal in V (|X X^T - I| = {orth:.1e}, |X Q^T| = {off:.1e})"
    # no bound below the floor: the Ritz values themselves are rounded at that level
    err = np.maximum(error_bounds(theta, np.maximum(res, floor)), floor)
    return BlockResult(theta, X, AX, res, it, history, err, floor, reason)


def rayleigh_ritz(apply_a, X0: np.ndarray, Q: np.ndarray | None, k: int, overwrite: bool = False) -> np.ndarray:
    """The k lowest Ritz vectors (rows) of A on the span of X0's rows projected onto {Q u = 0}.
    The orthonormal basis is never formed: with C its SVQB coefficients (X = C S, S the projected
    rows), X A X^T = C (S A S^T) C^T, and S A S^T needs A on one row at a time (S in V: A's
    projection onto V gives the same), so only S, one vector and the k output rows are held. The
    start of an iteration, not its result: ``lobpcg`` orthonormalises what it is given.
    ``overwrite``: X0 is the caller's to give away: it is projected in place."""
    S = _project(X0, Q, overwrite=overwrite)
    C, _ = _svqb(S @ S.T)
    G = np.empty((S.shape[0], S.shape[0]))
    for j in range(S.shape[0]):
        G[:, j] = S @ apply_a(S[j:j + 1])[0]
    _, Y = np.linalg.eigh(_sym(C @ _sym(G) @ C.T))
    return (C.T @ Y[:, :k]).T @ S
