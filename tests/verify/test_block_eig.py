"""The hand-rolled LOBPCG (``verify.block_eig``) against numpy's dense eigh on the same projected
operator: a reference that shares no code with it."""

import numpy as np

from vesicle_opt.verify import block_eig


def _problem(n=400, m=3, seed=1):
    rng = np.random.default_rng(seed)
    Qf, _ = np.linalg.qr(rng.standard_normal((n, n)))
    lam = np.concatenate([[-2.0, -2.0, 0.5], np.linspace(1.0, 50.0, n - 3)])  # a degenerate pair at the bottom
    A = (Qf * lam) @ Qf.T
    C, _ = np.linalg.qr(rng.standard_normal((n, m)))  # m excluded directions (orthonormal columns)
    Pi = np.eye(n) - C @ C.T
    ref = np.linalg.eigh(Pi @ A @ Pi)[0]
    # the projected operator has m zero eigenvalues along C: the reference on {C^T u = 0} drops them
    ref = np.sort(np.delete(ref, np.argsort(np.abs(ref))[:m]))
    return A, C.T.copy(), ref


def test_lowest_eigenpairs_on_the_subspace_match_dense_eigh():
    A, Q, ref = _problem()
    diag = np.diag(A).copy()
    apply_a = lambda U: U @ A  # noqa: E731 (rows are vectors; A symmetric)
    apply_t = lambda R: R / np.maximum(np.abs(diag), 1.0)  # noqa: E731 (a Jacobi preconditioner)
    X0 = np.random.default_rng(2).standard_normal((3, A.shape[0]))
    out = block_eig.lobpcg(apply_a, apply_t, X0, Q, 500, lambda th, res: bool(np.all(res <= 1e-9)))
    # residual 1e-9 and gap >= 0.5: the Ritz values are within 1e-9^2 / 0.5 of the eigenvalues
    # (Kato-Temple), the rest is round-off of the 400 x 400 products (~1e-13 relative)
    assert np.allclose(out.values, ref[:3], atol=1e-10), (out.values, ref[:3])
    assert np.all(out.residuals <= 1e-8)  # the exact final residuals (recomputed products)
    assert np.abs(out.vectors @ Q.T).max() <= 1e-12  # the vectors lie in {Q u = 0}
    assert np.allclose(out.vectors @ out.vectors.T, np.eye(3), atol=1e-12)  # orthonormal


def test_rayleigh_ritz_start_is_the_lowest_ritz_pairs_of_the_block():
    A, Q, _ = _problem(n=200, m=2, seed=3)
    X0 = np.random.default_rng(4).standard_normal((8, 200))
    X = block_eig.rayleigh_ritz(lambda U: U @ A, X0, Q, 3)
    given = X0.copy()  # overwrite: the same Ritz vectors (the same arithmetic, to round-off), in its rows
    assert np.allclose(block_eig.rayleigh_ritz(lambda U: U @ A, given, Q, 3, overwrite=True), X, atol=1e-12)
    assert np.abs(given[:3] @ Q.T).max() <= 1e-12  # its rows now hold the projected basis
    Pi = np.eye(200) - Q.T @ Q
    B = np.linalg.qr((X0 @ Pi).T)[0]  # orthonormal basis of the projected block
    ritz = np.linalg.eigvalsh(B.T @ A @ B)[:3]
    # the same Ritz values from a dense reference (round-off of 200 x 200 products)
    assert np.allclose(np.sort(np.einsum("ij,jk,ik->i", X, A, X)), ritz, atol=1e-10)


def test_running_past_convergence_stays_in_the_subspace_and_above_the_spectrum():
    """No stop rule at all: the iteration must end at its own attainable floor (``FLOOR`` eps ||A||
    sqrt(N)), long before the cap, with orthonormal vectors in {Q u = 0} and every Ritz value of the
    history at or above the least eigenvalue (exact Rayleigh-Ritz cannot go below it; the old
    iteration, under OpenBLAS's Haswell kernel, reached -5.9e3 against -2)."""
    A, Q, ref = _problem()
    diag = np.diag(A).copy()
    X0 = np.random.default_rng(2).standard_normal((3, A.shape[0]))
    out = block_eig.lobpcg(lambda U: U @ A, lambda R: R / np.maximum(np.abs(diag), 1.0), X0, Q, 2000,
                           lambda th, res: False)
    assert out.iterations < 400, out.iterations  # measured 170-181 under five kernels: the floor ends it
    assert out.reason == ""
    assert np.all(out.residuals <= 2 * out.floor)  # ended at the floor (measured 1.9e-12 <= 2.1e-12)
    theta0 = np.array([h[0] for h in out.history])
    assert theta0.min() >= ref[0] - 1e-12  # round-off of the 400 x 400 Rayleigh quotients (~1e-14 measured)
    assert np.abs(out.vectors @ Q.T).max() <= 1e-12
    assert np.allclose(out.vectors @ out.vectors.T, np.eye(3), atol=1e-12)
    # the error bounds hold against the dense reference (and are not vacuous: at most the floor)
    assert np.all(np.abs(out.values - ref[:3]) <= out.errors), (out.values - ref[:3], out.errors)
    assert np.all(out.errors <= out.floor)


def test_error_bounds_kato_temple_where_separated_residual_otherwise():
    """``error_bounds`` against the closed forms: r^2 / gap for a separated value, (r_1^2 + r_2^2) /
    gap for a cluster of overlapping intervals, r where the quadratic bound is larger or there is
    no gap, r for the cluster at the top of the block (no neighbour above)."""
    theta, res = np.array([0.0, 1.0, 1.001, 3.0]), np.array([1e-3, 1e-2, 1e-2, 1e-1])
    err = block_eig.error_bounds(theta, res)
    assert np.isclose(err[0], 1e-6 / (1.0 - 1e-2))  # gap to the next interval's lower end 0.99
    # the cluster {1, 1.001}: gaps 1 - (0 + 1e-3) below, 3 - 0.1 - 1.001 above
    assert np.allclose(err[1:3], 2e-4 / 0.999)
    assert err[3] == 1e-1
    err = block_eig.error_bounds(np.array([0.0, 0.5, 3.0]), np.array([0.3, 0.3, 0.1]))
    assert np.allclose(err, [0.075, 0.075, 0.1])  # one cluster below the top one: 0.18 / 2.4 < 0.3 ...
    err = block_eig.error_bounds(np.array([0.0, 0.5, 1.0]), np.array([0.3, 0.3, 0.1]))
    assert np.allclose(err, [0.3, 0.3, 0.1])  # ... but here 0.18 / 0.4 > 0.3: r stays


def test_kato_temple_bound_holds_on_a_diagonal_operator():
    """A perturbed eigenvector of diag(0, 1, 2, ...): the Ritz value's true error is below the
    Kato-Temple bound and far below the residual (its square over the gap)."""
    n = 50
    lam = np.arange(n, dtype=float)
    rng = np.random.default_rng(5)
    X = np.eye(n)[:2] + 1e-5 * rng.standard_normal((2, n))
    X = np.linalg.qr(X.T)[0].T
    AX = X * lam
    theta, C = np.linalg.eigh(X @ AX.T)
    X, AX = C.T @ X, C.T @ AX
    res = np.linalg.norm(AX - theta[:, None] * X, axis=1)
    err = block_eig.error_bounds(theta, res)
    assert np.all(np.abs(theta - lam[:2]) <= err)
    assert err[0] < 1e-2 * res[0]  # r^2 / gap with r ~ 2e-3 (lam up to 49), gap ~ 1: far below r


def test_dependent_directions_and_restarts_keep_the_result_exact(monkeypatch):
    """An exact shifted-inverse preconditioner on the subspace converges in a few steps, after which
    W and P are numerically dependent on X: the SVQB drops directions and the iteration restarts
    without P (counted here), yet it ends at its floor with the dense reference's values."""
    A, Q, ref = _problem()
    Pi = np.eye(A.shape[0]) - Q.T @ Q
    T = np.linalg.pinv(Pi @ (A + 3 * np.eye(A.shape[0])) @ Pi)  # (A + 3)^{-1} on the subspace
    drops = []
    svqb = block_eig._svqb

    def counted(G):
        C, keep = svqb(G)
        drops.append(not keep.all())
        return C, keep
    monkeypatch.setattr(block_eig, "_svqb", counted)
    X0 = np.random.default_rng(2).standard_normal((3, A.shape[0]))
    out = block_eig.lobpcg(lambda U: U @ A, lambda R: R @ T, X0, Q, 200, lambda th, res: False)
    assert sum(drops) >= 5  # measured 25 of the iteration's Gram matrices had dependent directions
    assert out.iterations < 100 and out.reason == ""  # measured 43: the floor ends it
    assert np.all(np.abs(out.values - ref[:3]) <= out.errors)  # measured 1e-14 against bounds 1.6e-12
    assert np.abs(out.vectors @ Q.T).max() <= 1e-12
    assert np.allclose(out.vectors @ out.vectors.T, np.eye(3), atol=1e-12)
