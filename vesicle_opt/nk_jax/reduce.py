"""Sums that give the same bits on any number of devices: the reductions behind E (6), A (7),
B (8) and every inner product of the Newton-CG loop (issue 15: two devices give the one-device
answer).

A plain ``jnp.sum`` of a field split across D devices is a local reduction per device and a
cross-device add, so its order (and its last bits) depend on D; those bits steer the line search,
the CG recurrences and the multiplier updates, and the runs drift apart (measured before this
module: raw E of the 16^3 torus 1.9e-12 apart, phi 5.5e-12, one device against two). XLA's own
reduction kernel is not a fixed order either: its CPU code for a batch of rows depends on the batch
(row sums of 8 and of 16 rows of 256 differed by 2e-14, measured; so did a matrix-vector product
with ones). Here a sum over a field is

1. ``row_sums``: the plain sum of each row (a whole slice along the split axis, held by one device)
   by its own reduction of shape (R,) (``lax.map``): the same kernel on every layout, so the same
   row sums;
2. ``neumaier_sum``: the row sums combined in row order, the rounding error of every add carried
   (Neumaier's compensated summation with the error-free ``fast_two_sum``), so the combine adds no
   round-off of its own beyond the final u |sum|.

The accuracy is that of the row sums (a plain sum of R terms each) plus u |sum|: compensated
across rows, not within them; the point is the fixed order. The cost, measured on the 32^3 torus
(load ~10 on 2 cores): XLA compilation 5.7 s against 2.6 s with plain sums (the row loops), run time
~1.9x (a loop step per row instead of one vectorised reduction).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def fast_two_sum(a, b):
    """(s, e) with s = fl(a + b) and a + b = s + e exactly: Dekker's Fast2Sum on the pair sorted by
    magnitude (exact in round-to-nearest when |big| >= |small|). The selects also keep it exact
    where a or b is a product in the same fused program: XLA's CPU backend always lets LLVM contract
    a multiply feeding an add into an FMA (Knuth's two-sum on the products of a dot, in a pairwise tree
    of slices, lost its error terms that way: 1e-14 from math.fsum, measured), and an add of selects is not contracted. A tie |a| = |b| gives
    big = a, small = b; NaN and inf propagate (inf + finite leaves a NaN error term)."""
    big = jnp.where(jnp.abs(a) >= jnp.abs(b), a, b)
    small = jnp.where(jnp.abs(b) > jnp.abs(a), a, b)  # not the negated test: LLVM folds
    # select(c, a, b) + select(c, b, a) into a + b, and a + b of two products into an FMA
    s = jnp.where(jnp.isnan(a), a, big + small)  # a NaN a is in neither select: kept here
    return s, small - (s - big)


def row_sums(rows):
    """Plain sums of the rows of a 2D array, one row at a time (``lax.map``): every reduction has
    the shape (R,), whatever the number of rows, so its kernel and its order are the same on every
    layout (a batched ``jnp.sum(rows, axis=1)`` is not: XLA's CPU kernel for 16 rows and for 8 rows
    of 256 gave row sums 2e-14 apart, measured; so did a matrix-vector product with ones)."""
    return jax.lax.map(jnp.sum, rows)


def _accumulate(carry, value):
    s, e = carry
    s, d = fast_two_sum(s, value)
    return s, e + d


def neumaier_sum(v):
    """Sum of a short 1D vector in index order, the error of every add carried (Neumaier's
    compensated sum, the adds by ``fast_two_sum``)."""
    zero = jnp.zeros((), v.dtype)
    s, e = jax.lax.fori_loop(0, v.shape[0], lambda i, c: _accumulate(c, v[i]), (zero, zero))
    return s + e


def rows_total(rows):
    """``neumaier_sum(row_sums(rows))`` in one loop (the same operations in the same order: the
    one-device form, one compiled loop fewer than the two)."""
    zero = jnp.zeros((), rows.dtype)
    s, e = jax.lax.fori_loop(0, rows.shape[0], lambda i, c: _accumulate(c, jnp.sum(rows[i])), (zero, zero))
    return s + e
