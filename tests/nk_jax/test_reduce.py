"""nk_jax.reduce: the error-free two-sum (also on products inside one compiled program, where XLA
contracts multiply-adds into FMAs), the compensated combine, NaN/inf propagation, and the row-wise
sum of a field against exact rational arithmetic."""

import math
from fractions import Fraction

import numpy as np
import pytest

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from vesicle_opt.nk_jax import ops as _ops  # noqa: E402,F401  (float64: jax_enable_x64)
from vesicle_opt.nk_jax.layout import GridLayout  # noqa: E402
from vesicle_opt.nk_jax.reduce import fast_two_sum, neumaier_sum  # noqa: E402

U = 2.0**-53  # unit round-off of float64


def test_two_sum_is_error_free_on_products_in_one_program(rng):
    """s + e = fl(x y) + fl(z w) exactly (rational arithmetic), the products formed in the same jit,
    over 16 decades of magnitude."""
    x, y, z, w = (rng.standard_normal(512) * 10.0 ** rng.integers(-8, 8, 512) for _ in range(4))
    s, e = jax.jit(lambda x, y, z, w: fast_two_sum(x * y, z * w))(x, y, z, w)
    s, e = np.asarray(s), np.asarray(e)
    p, q = x * y, z * w  # numpy: one rounding per product
    bad = [i for i in range(512) if Fraction(s[i]) + Fraction(e[i]) != Fraction(p[i]) + Fraction(q[i])]
    assert not bad, bad[:5]


def test_neumaier_sum_is_compensated(rng):
    """Condition ~1e16 (terms +-1e8 cancelling to ~1): the combine gives the correctly rounded sum
    up to its bound u |s| + 2 n u^2 sum |v| (Neumaier); numpy's pairwise sum misses by ~1e-8."""
    big = rng.standard_normal(1000) * 1e8
    v = rng.permutation(np.concatenate([big, -big, rng.standard_normal(5)]))
    exact = math.fsum(v.tolist())
    got = float(jax.jit(neumaier_sum)(jnp.asarray(v)))
    bound = U * abs(exact) + 2 * v.size * U**2 * float(np.sum(np.abs(v)))
    assert abs(got - exact) <= bound, (got, exact, bound)
    assert abs(float(np.sum(v)) - exact) > 1e3 * bound  # the data do need the compensation


def test_total_is_the_rows_combined_and_propagates_nan(rng):
    """A field's total is within the plain-row bound of the exact sum (each row a plain sum of R
    terms: |err| <= (R - 1) u sum |x|, the combine u |sum| more), and non-finite values survive."""
    shape = (12, 10, 9)
    x = rng.standard_normal(shape)
    layout = GridLayout(shape, jax.devices()[:1])
    total = jax.jit(layout.total)
    exact = math.fsum(x.ravel().tolist())
    R = 10 * 9
    assert abs(float(total(layout.put(x.ravel()))) - exact) <= (R - 1) * U * np.sum(np.abs(x)) + U * abs(exact)
    y = x.copy()
    y[7, 3, 2] = np.nan
    assert math.isnan(float(total(layout.put(y.ravel()))))
    y[7, 3, 2] = np.inf
    assert not math.isfinite(float(total(layout.put(y.ravel()))))
