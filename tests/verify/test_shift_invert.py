"""The bordered shift-invert solve by the Schur complement (``verify.shift_invert``) against the LU of
the bordered matrix itself, and the assembled check's eigenvalues through it against dense
eigenvalues of the reduced matrix on T (a small SPD + indefinite test matrix with dense rows)."""

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vesicle_opt.verify import shift_invert as SI


def _problem(n=300, seed=0):
    rng = np.random.default_rng(seed)
    lap = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    H = (lap @ lap * n**2 - 50 * sp.eye(n)).tocsr()  # a bi-Laplacian with a few negative modes off T
    m = 1 + rng.random(n)
    C = np.column_stack([m, rng.standard_normal(n), m * np.linspace(-1, 1, n)])  # dense rows, as dA, dB, pin
    return H, m, C


def test_schur_bordered_solve_matches_the_bordered_lu():
    H, m, C = _problem()
    M = sp.diags(m)
    b = SI.factorise(H, M, -10.0, C)
    assert b is not None
    K = sp.bmat([[H + 10.0 * M, sp.csr_matrix(C)], [sp.csr_matrix(C.T), None]], format="csc")
    rhs = np.random.default_rng(1).standard_normal((300, 2))
    ref = spla.splu(K).solve(np.vstack([rhs, np.zeros((3, 2))]))[:300]
    v = b.solve(rhs)
    # two backward-stable solves of one system, condition ~1e6 here: 1e-9 relative
    assert np.abs(v - ref).max() < 1e-9 * np.abs(ref).max()
    assert np.abs(C.T @ v).max() < 1e-10 * np.abs(C).max() * np.abs(v).max()  # in T to round-off


def test_shift_invert_eigenvalues_on_the_tangent_space():
    H, m, C = _problem()
    Z = sla.null_space(C.T)  # dense reference: H on T = null(C^T) in the mass metric
    ref = sla.eigh(Z.T @ H.toarray() @ Z, Z.T @ (m[:, None] * Z), eigvals_only=True)[:4]
    sigma = ref[0] - 1.0  # below the spectrum on T, as the check's shift
    b = SI.factorise(H, sp.diags(m), sigma, C)
    op = spla.LinearOperator(H.shape, matvec=b.solve, dtype=float)
    mu = np.sort(spla.eigsh(H, k=4, M=sp.diags(m), sigma=sigma, OPinv=op, v0=np.ones(300), tol=1e-12)[0])
    assert np.allclose(mu, ref, rtol=1e-8)  # ARPACK tol 1e-12 against dense eigh (condition ~1e6)


def test_a_singular_shift_is_refused():
    H, m, C = _problem(n=50)
    w, V = sla.eigh(H.toarray(), np.diag(m))
    assert SI.factorise(H, sp.diags(m), float(w[3]), C) is None  # H - s M singular to round-off
