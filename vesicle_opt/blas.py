"""In-place vector updates for the matrix-free hot loops (a bottom layer: numpy and scipy only).

numpy's ``y += a * x`` forms ``a * x`` in a temporary the size of the field and then adds it:
two passes over memory and a fresh allocation. BLAS daxpy does it in one pass, in place. On the
64^3 grids of the Newton-Krylov solve, whose fields (2 MB each) do not stay in cache between
uses, each pass saved is memory traffic saved (``studies.bench_3d``: the solve against its FFT
floor). Rounding may differ from numpy's in the last bit (a kernel may fuse the multiply-add).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import daxpy, dgemm, dgemv


def _blas_vector(v: np.ndarray) -> bool:
    return v.dtype == np.float64 and v.ndim == 1 and v.flags.c_contiguous and v.flags.writeable


def axpy(a: float, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """y += a x in place (one pass with BLAS daxpy for contiguous float64 vectors); returns y."""
    if _blas_vector(x) and _blas_vector(y) and x.size == y.size:
        out = daxpy(x, y, a=a)
        if out is not y:  # f2py copied y (it never does for these arrays): keep the contract
            y[...] = out
    else:
        y += a * x
    return y


def gemv(alpha: float, A: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """y += alpha A x in place (BLAS dgemv; A of shape (N, k), best in Fortran order, which gemv
    reads without a copy: the transpose of k contiguous rows); returns y."""
    if _blas_vector(y) and A.dtype == np.float64:
        out = dgemv(alpha, A, np.asarray(x, np.float64), beta=1.0, y=y, overwrite_y=True)
        if out is not y:
            y[...] = out
    else:
        y += alpha * (A @ x)
    return y


def gemm_rows(alpha: float, C: np.ndarray, B: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out += alpha C B in place (out: k x N rows, C: k x m, B: m x N rows), one BLAS dgemm on the
    transposes (N x m and N x k, Fortran order: no copy of a block) instead of a k x N product and
    a k x N sum; returns out."""
    if (out.dtype == np.float64 and B.dtype == np.float64 and out.flags.c_contiguous and out.flags.writeable
            and B.flags.c_contiguous):
        res = dgemm(alpha, B.T, np.asarray(C, np.float64).T, beta=1.0, c=out.T, overwrite_c=True)
        if not np.shares_memory(res, out):
            out[...] = res.T
    else:
        out += alpha * (C @ B)
    return out


def subtract_projection(U: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """U -= (U Q^T) Q in place (U: k x N rows, Q: q x N orthonormal rows): the rows of U minus their
    components along the rows of Q (``gemm_rows``); returns U."""
    return gemm_rows(-1.0, U @ Q.T, Q, U)
