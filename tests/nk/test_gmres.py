"""``nk.gmres`` against scipy's GMRES (another implementation: modified Gram-Schmidt, its own
Givens code), against dense solves, and on closed forms (the minimal polynomial's degree)."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from vesicle_opt.nk.gmres import gmres


def _system(seed, n=80):
    rng = np.random.default_rng(seed)
    A = np.eye(n) + 0.4 * rng.standard_normal((n, n)) / np.sqrt(n)  # nonsymmetric, cond ~ 3
    return A, rng.standard_normal(n)


def _scipy(A, b, iterations):
    """scipy's iterate after exactly ``iterations`` Arnoldi steps (one cycle, tolerance unreachable)."""
    x, _ = spla.gmres(A, b, rtol=1e-300, atol=0.0, restart=iterations, maxiter=1)
    return x


@pytest.mark.parametrize("k", [1, 3, 7, 15])
def test_the_iterates_are_scipys(k):
    """GMRES's k-th iterate is unique (the least residual on K_k): ours and scipy's agree to 1e-12
    (cond(A) ~ 3, both orthogonalise to round-off; measured <= 4e-16 relative)."""
    A, b = _system(k)
    out = gmres(lambda v: A @ v, b, 1e-300, k, k)
    ref = _scipy(A, b, k)
    assert out.iterations == k and not out.converged
    assert np.linalg.norm(out.x - ref) <= 1e-12 * np.linalg.norm(ref)


def test_the_residual_estimate_is_the_true_residual():
    """At the stop the Givens estimate is |b - A x| / |b| itself to round-off, and below rtol: they
    differ by 1e-13 of |b| at most (n eps cond(A) = 80 x 2.2e-16 x 3.3 = 6e-14; measured 1.4e-17)."""
    A, b = _system(5)
    out = gmres(lambda v: A @ v, b, 1e-8, 200, 200)
    true = np.linalg.norm(b - A @ out.x) / np.linalg.norm(b)
    assert out.converged and true <= 1e-8
    assert abs(true - out.residual) <= 1e-13


def test_restarts_reach_the_tolerance():
    """Cycles of 5 on a system that needs 23 unrestarted steps (measured; 24 restarted): still
    converged, the true residual below rtol, no fewer steps than unrestarted (restarted GMRES
    minimises over smaller spaces)."""
    A, b = _system(6)
    full = gmres(lambda v: A @ v, b, 1e-10, 400, 400)
    cut = gmres(lambda v: A @ v, b, 1e-10, 400, 5)
    assert full.converged and cut.converged
    assert np.linalg.norm(b - A @ cut.x) <= 1e-10 * np.linalg.norm(b)
    assert cut.iterations >= full.iterations


def test_exact_in_as_many_steps_as_distinct_eigenvalues():
    """A diagonalisable A with 3 distinct eigenvalues: its minimal polynomial has degree 3, so
    K_3 holds the solution: 3 iterations (a breakdown or the estimate at round-off), LU's x to 1e-12."""
    rng = np.random.default_rng(7)
    S = np.eye(40) + 0.1 * rng.standard_normal((40, 40))
    A = S @ np.diag(np.repeat([1.0, 2.5, -0.7], [10, 20, 10])) @ np.linalg.inv(S)
    b = rng.standard_normal(40)
    out = gmres(lambda v: A @ v, b, 1e-12, 40, 40)
    assert out.converged and out.iterations == 3
    ref = np.linalg.solve(A, b)
    assert np.linalg.norm(out.x - ref) <= 1e-10 * np.linalg.norm(ref)  # cond(S)^2 ~ 10 x the 1e-12 stop


def test_zero_right_hand_side_and_the_budget():
    A, b = _system(8)
    zero = gmres(lambda v: A @ v, np.zeros(80), 1e-8, 50, 50)
    assert zero.converged and zero.iterations == 0 and not zero.x.any()
    short = gmres(lambda v: A @ v, b, 1e-14, 4, 50)  # 4 steps leave 0.026 of |b| (measured), far above 1e-14
    assert short.iterations == 4 and not short.converged and short.residual > 1e-14


def test_a_non_finite_product_ends_the_solve_unconverged():
    """A NaN from the operator (a diverged linearisation) ends GMRES at once, not converged, instead of
    running its budget on NaNs (the caller reports the step as non-finite)."""
    calls = []

    def bad(v):
        calls.append(1)
        return np.full_like(v, np.nan) if len(calls) > 2 else 2.0 * v + np.roll(v, 1)
    with np.errstate(invalid="ignore"):
        out = gmres(bad, np.ones(20) + np.arange(20.0), 1e-12, 400, 200)
    assert not out.converged and out.iterations == 3 and len(calls) == 3
