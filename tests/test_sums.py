"""``vesicle_opt.sums.total`` against ``math.fsum`` (the correctly rounded sum) on fields built to
cancel: the bound of the module docstring, u |sum| + u^2 log2(N)^2 sum |x|, must hold."""

import math

import numpy as np
import pytest

from vesicle_opt.sums import total

U = 2.0**-53  # unit round-off of float64


@pytest.mark.parametrize("n", [0, 1, 2, 3, 1000, 4097, 2**18 + 5])
def test_total_is_as_exact_as_fsum(rng, n):
    big = rng.standard_normal(n) * 10.0 ** rng.uniform(-8, 8, n)  # 16 decades of magnitude
    x = np.concatenate([big, -big[::-1] * (1 + 1e-12), rng.standard_normal(n) * 1e-9])  # cancels to ~1e-12
    rng.shuffle(x)
    exact = math.fsum(x.tolist() + [3.5])
    bound = U * abs(exact) + U**2 * max(math.log2(max(x.size, 2)), 1.0) ** 2 * float(np.sum(np.abs(x)))
    assert abs(total(x, 3.5) - exact) <= bound
    plain = float(np.sum(x)) + 3.5
    if n >= 1000:  # the cancellation is real: a plain sum misses by far more than the bound
        assert abs(plain - exact) > 10 * bound


def test_total_of_scalars_and_arrays():
    assert total() == 0.0
    assert total(np.array([1e16, 1.0, -1e16]), -1.0) == 0.0  # a plain left-to-right sum gives -1.0
