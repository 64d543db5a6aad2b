"""``vesicle_opt.blas``: the in-place BLAS updates equal numpy's, in place, with numpy's fallback
for arrays BLAS cannot take without a copy."""

import numpy as np

from vesicle_opt.blas import axpy, gemm_rows, gemv, subtract_projection

ROUNDOFF = 4 * np.finfo(float).eps  # one multiply-add per entry (fused or not): <= 1 ulp each


def test_axpy_updates_in_place(rng):
    x, y = rng.standard_normal(1000), rng.standard_normal(1000)
    want = y + 0.3 * x
    out = axpy(0.3, x, y)
    assert out is y and np.max(np.abs(y - want)) <= ROUNDOFF * np.max(np.abs(want))
    strided = rng.standard_normal(2000)[::2]  # not contiguous: the numpy fallback, still in place
    want = strided + 2.0 * x
    axpy(2.0, x, strided)
    assert np.max(np.abs(strided - want)) <= ROUNDOFF * np.max(np.abs(want))


def test_gemv_updates_in_place(rng):
    rows = rng.standard_normal((3, 500))
    a, y = rng.standard_normal(3), rng.standard_normal(500)
    want = y - rows.T @ a
    out = gemv(-1.0, rows.T, a, y)
    assert out is y and np.max(np.abs(y - want)) <= 8 * ROUNDOFF * np.max(np.abs(want))  # 3 terms


def test_subtract_projection_removes_the_components_in_place(rng):
    Q = np.linalg.qr(rng.standard_normal((300, 4)))[0].T.copy()  # 4 orthonormal rows
    U = rng.standard_normal((3, 300))
    want = U - (U @ Q.T) @ Q
    out = subtract_projection(U, Q)
    assert out is U and np.max(np.abs(U - want)) <= 16 * ROUNDOFF * np.max(np.abs(want))  # 4-term sums
    assert np.max(np.abs(U @ Q.T)) <= 16 * ROUNDOFF * np.max(np.abs(U))  # orthogonal to Q to round-off


def test_gemm_rows_accumulates_in_place(rng):
    B, C, out = rng.standard_normal((4, 300)), rng.standard_normal((3, 4)), rng.standard_normal((3, 300))
    want = out + 0.5 * C @ B
    res = gemm_rows(0.5, C, B, out)
    assert res is out and np.max(np.abs(out - want)) <= 16 * ROUNDOFF * np.max(np.abs(want))  # 4-term sums
    strided = rng.standard_normal((3, 600))[:, ::2]  # not contiguous: the numpy fallback, still in place
    want = strided + C @ B
    gemm_rows(1.0, C, B, strided)
    assert np.max(np.abs(strided - want)) <= 16 * ROUNDOFF * np.max(np.abs(want))
