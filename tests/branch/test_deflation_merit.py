"""The deflation operator M of ``branch.deflation`` (``multiplier``), the merit of the bordered
Newton's line search, against the step factor (``factor``): Sherman-Morrison's factor is
1 / (1 - <grad log M, d>), so log M's directional derivative by central differences must give it."""

import numpy as np

from vesicle_opt.branch import deflation


def test_the_merit_is_the_operator_whose_log_gradient_the_factor_uses():
    rng = np.random.default_rng(0)
    n = 50
    w = rng.uniform(0.5, 2.0, n)
    known = [rng.standard_normal(n) for _ in range(3)]
    phi, d = rng.standard_normal(n), rng.standard_normal(n)
    h = 1e-5
    slope = (np.log(deflation.multiplier(phi + h * d, known, w))
             - np.log(deflation.multiplier(phi - h * d, known, w))) / (2 * h)
    f = deflation.factor(phi, d, known, w)
    assert abs(1.0 / (1.0 - slope) - f) < 1e-8 * abs(f)  # central differences: O(h^2) = 1e-10 relative
    # far from every known root M -> (sigma)^k = 1; at a known root it is infinite (the root is removed)
    assert abs(deflation.multiplier(1e8 * phi, known, w) - 1.0) < 1e-12  # |phi - r|^-2 ~ 1e-16 * 3 terms
    assert deflation.multiplier(known[1], known, w) == np.inf
