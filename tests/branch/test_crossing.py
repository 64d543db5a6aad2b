"""branch.crossing: the crossing of two branches against a closed form, its eps -> 0 extrapolation
against an exact quadratic sequence."""

import numpy as np
import pytest

from vesicle_opt.branch.crossing import crossing, extrapolate_crossing


def test_crossing_of_curved_branches_matches_the_closed_form():
    """e = 1/v and e = 2.5 - v cross at v = 0.5, e = 2; the splines through points 0.02 apart (and
    on different grids) find it to their O(dv^4) error (~3e-7 here: dv^4 max|f''''| / 384)."""
    va = np.arange(0.40, 0.61, 0.02)
    vb = np.arange(0.41, 0.60, 0.03)
    x = crossing(va, 1 / va, vb, 2.5 - vb)
    assert x["reduced_volume"] == pytest.approx(0.5, abs=1e-6)
    assert x["reduced_energy"] == pytest.approx(2.0, abs=1e-6)
    assert crossing(va, 1 / va, va, 10 + va) is None  # no crossing on the overlap
    assert crossing(va[:1], 1 / va[:1], vb, 2.5 - vb) is None  # too few points


def test_crossing_of_two_lines_is_where_they_meet():
    """e = 1 + v and e = 2 - v cross at v = 0.5, e = 1.5: a not-a-knot spline reproduces a line, so
    the root is exact up to brentq's xtol 1e-14, also on different v grids."""
    va, vb = np.linspace(0.2, 0.9, 8), np.linspace(0.1, 0.95, 5)
    x = crossing(va, 1 + va, vb, 2 - vb)
    assert abs(x["reduced_volume"] - 0.5) < 1e-12 and abs(x["reduced_energy"] - 1.5) < 1e-12  # round-off
    assert crossing(va, 1 + va, [0.3, 0.6], [5.3, 5.6]) is None  # parallel: no crossing


@pytest.mark.parametrize("eps", [(0.2, 0.14, 0.1), (0.07, 0.06, 0.05, 0.035)])
def test_extrapolation_recovers_a_quadratic_limit(eps):
    """y = y0 + c eps^2 exactly: every extrapolation gives y0 to round-off, the free order 2."""
    per_eps = {e: {"reduced_volume": 0.65 + 3 * e**2, "reduced_energy": 1.8 - 2 * e**2} for e in eps}
    ex = extrapolate_crossing(per_eps)
    for key, y0 in (("reduced_volume", 0.65), ("reduced_energy", 1.8)):
        for how in ("_richardson", "_p2", "_lsq_p2"):
            assert ex[key + how] == pytest.approx(y0, abs=1e-12), key + how  # round-off of O(1) sums
        assert ex["order_" + key] == pytest.approx(2.0, abs=1e-6)  # brentq's tolerance on p
        assert ex[key + "_lsq_p2_rms"] < 1e-13  # an exact line in eps^2: round-off


def test_two_levels_give_the_fixed_order_only():
    ex = extrapolate_crossing({0.1: {"reduced_volume": 0.66, "reduced_energy": 1.8},
                               0.05: {"reduced_volume": 0.655, "reduced_energy": 1.81}})
    assert ex["reduced_volume_p2"] == pytest.approx(0.655 - (0.66 - 0.655) / 3, abs=1e-14)  # closed form
    assert np.isnan(ex["reduced_volume_richardson"]) and "reduced_volume_lsq_p2" not in ex
