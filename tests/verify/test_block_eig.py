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
