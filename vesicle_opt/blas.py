"""In-place vector updates for the matrix-free hot loops (a bottom layer: numpy and scipy only).

numpy's ``y += a * x`` forms ``a * x`` in a temporary the size of the field and then adds it:
two passes over memory and a fresh allocation. BLAS daxpy does it in one pass, in place. On the
64^3 grids of the Newton-Krylov solve, whose fields (2 MB each) do not stay in cache between
uses, each pass saved is memory traffic saved (``studies.bench_3d``: the solve against its FFT
floor). Rounding may differ from numpy's in the last bit (a kernel may fuse the multiply-add).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import daxpy, dgemv


def _blas_vector(v: np.ndarray) -> bool:
    return v.dtype == np.float64 and v.ndim == 1 and v.flags.c_contiguous


def axpy(a: float, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """y += a x in place (one pass with BLAS daxpy for contiguous float64 vectors); returns y."""
    if _blas_vector(x) and _blas_vector(y) and x.size == y.size:
        daxpy(x, y, a=a)
    else:
        y += a * x
    return y


def gemv(alpha: float, A: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """y += alpha A x in place (BLAS dgemv; A of shape (N, k), best in Fortran order, which gemv
    reads without a copy: the transpose of k contiguous rows); returns y."""
    if _blas_vector(y) and A.dtype == np.float64:
        dgemv(alpha, A, np.asarray(x, np.float64), beta=1.0, y=y, overwrite_y=True)
    else:
        y += alpha * (A @ x)
    return y
