"""The levels of the matrix-free second-order check (``verify.lobpcg``): which coarser Fourier grids
start it (``coarse_shape``) and when a level's LOBPCG iteration ends (``settled``, ``coarse_stop``;
the fine level's rule, which also waits for a decided verdict, is ``lobpcg.spectrum``'s). The
constants are the check's tuning, each with what was measured to choose it.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.mesh.spectral import even_fft_size

TOL = 1e-4  # every pair's error bound (mu_ref units) below this also ends a level
EIG_TOL = 1e-6  # the fine level stops once the verdict is decided and the Ritz values but the guard have
# settled to EIG_TOL max(1, |mu|) (``settled``): a tenth of the 1e-5 agreement with the assembled check
COARSE_EIG_TOL = 1e-6  # the coarse level that starts the fine one settles to 1e-6 too (its vectors only start it)
LOWER_EIG_TOL = 1e-5  # a level below that one (it starts a coarse level, not the fine one) settles to 1e-5.
# Measured (check CPU s, 1e-6 -> 1e-5 here, the level that starts the fine one at 1e-6 either way, fine
# iterations unchanged, 4-5): Table-1 torus 64^3 1.97 -> 1.72 (26^3 level 79 -> 50 iterations); octant
# prolate 205 k nodes warm 2.04 -> 1.73, cold 2.32 -> 1.91; 525 k nodes cold 12.0 -> 8.7 (72 x 22 x 22
# level 251 -> 177). Not 1e-4 (torus: its 40^3 level 17 -> 42 iterations, 2.3 s). The level that starts the
# fine one stays at 1e-6: looser there, the fine level pays (torus, 1e-4 on both levels: 40 fine iterations,
# 4.6 s; 1e-5 there and 1e-4 below: 32, 5.5 s), as its stop waits for its Ritz values to settle to EIG_TOL
Q_MAX = 0.9  # the step ratio assumed at most (remaining distance <= 9 x the last step)
RATE_WINDOW = 3  # step ratios looked at
SETTLED_RUN = 2  # iterations in a row the estimate must hold
DECIDED_EXTRA = 60  # and at most this many iterations after the verdict is first decided: the rest
# only sharpens the number (measured, 96^3 torus from its 48^3 start: decided early, then 234
# iterations creeping 1e-8 per step to mu_min 0.1452083 with error bound 5.4e-3, 7.3x the solve)
ACCURATE = 1.5  # a coarse level whose eigenvectors start the next one well has eps / h >= this
# (coarse_shape); eps / h >= 1 (resolving) is enough for the coarsest, whose start is the interface block
COARSE_RATIO = 0.75  # a coarse level is worth its setup only when at most this fraction of n per side
MIN_COARSE_N = 16  # no coarse level below 16 per side (nor any with h > eps: under-resolved interface)


def even_at_least(x: float, smooth: bool) -> int:
    """The least even integer >= x (with ``smooth``: whose prime factors are 2, 3, 5: fast FFTs)."""
    return max(even_fft_size(x) if smooth else 2 * int(np.ceil(x / 2)), MIN_COARSE_N)


def coarse_shape(disc, epsilon: float):
    """The next coarser Fourier grid (``verify.lobpcg``'s docstring), or None. Per side, with eps / h the points
    per interface width: n/2 where that is even and keeps eps / h >= ``ACCURATE``; else the least
    even 5-smooth size with eps / h >= ``ACCURATE`` where it is <= ``COARSE_RATIO`` n; else the
    least even size that still resolves the interface (eps / h >= 1) where it is <= ``COARSE_RATIO``
    n; else none. Measured on the Table-1 torus (eps / h = 2.6 at 64^3): from 32^3 (eps / h = 1.3,
    mu_min 0.14044 there against 0.14521) the 64^3 level needed 19 iterations, from 40^3 (fed by
    26^3) 4; the 48^3 level from its random-mixed start 238-300, from 26^3 22."""
    fourier = getattr(disc, "fourier", None)
    if fourier is None:
        return None
    n = np.array(disc.grid_shape)
    per_width = epsilon / fourier.lengths  # eps / h = per_width * n
    if np.all(n % 2 == 0) and np.all(n // 2 >= MIN_COARSE_N) and np.all(per_width * (n // 2) >= ACCURATE):
        return tuple(int(k) for k in n // 2)
    for need, smooth in ((ACCURATE, True), (1.0, False)):
        k = np.array([even_at_least(need / w, smooth) for w in per_width])
        if np.all(k <= COARSE_RATIO * n):
            return tuple(int(v) for v in k)
    return None


def settled(tol):
    """stop rule: the Ritz values but the last (the guard) are within ``tol`` max(1, |theta|) of their
    limits, estimated from their last steps: d q / (1 - q) with d the last step and q the largest of
    the last ``RATE_WINDOW`` step ratios, capped at ``Q_MAX`` (a linearly converging sequence's
    remaining distance), on ``SETTLED_RUN`` iterations in a row (one lucky short step is not enough).
    Returns how many iterations in a row it has held."""
    steps, prev, run = [], [None], [0]

    def settled(theta) -> int:
        lead = slice(0, max(len(theta) - 1, 1))
        old, prev[0] = prev[0], theta[lead].copy()
        if old is None or len(old) != len(prev[0]):
            steps.clear()
            run[0] = 0
            return 0
        steps.append(np.abs(prev[0] - old))
        del steps[:-RATE_WINDOW - 1]
        if len(steps) < 2:
            return 0
        ratios = [s1 / np.maximum(s0, np.finfo(float).tiny) for s0, s1 in zip(steps[:-1], steps[1:])]
        q = np.minimum(np.max(ratios, axis=0), Q_MAX)
        remaining = steps[-1] * q / (1.0 - q)
        ok = bool(np.all(remaining <= tol * np.maximum(1.0, np.abs(prev[0]))))
        run[0] = run[0] + 1 if ok else 0
        return run[0]
    return settled


def coarse_stop(n_settled: int, res) -> bool:
    """A coarse level ends when its Ritz values have settled (``settled``: to ``COARSE_EIG_TOL`` on the
    level that starts the fine one, to ``LOWER_EIG_TOL`` below it) or every
    pair's error bound is below ``TOL``: its eigenvectors only start the next level, which corrects
    what is left."""
    return n_settled >= SETTLED_RUN or bool(np.all(res <= TOL))
