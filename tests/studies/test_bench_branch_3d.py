"""``studies.bench_branch_3d``'s summary: the medians over the warm points and the exponents in the
node count (np.polyfit on log-log), on rows with a known power law."""

import math

import pytest

from vesicle_opt.studies import bench_branch_3d as bb


def _rows(eps, nodes, cpu):
    """A level's rows as the CSV gives them back (strings): a cold start and a natural point that the
    summary must leave out (100x the cost), then three warm points."""
    rows = []
    for point, scale, acc in ((0, 100.0, "True"), (1, 100.0, "True"), (2, 1.0, "True"), (3, 1.1, "True"),
                              (4, 0.9, "True"), (5, 50.0, "False")):
        rows.append({"epsilon": str(eps), "nodes": str(nodes), "point": str(point), "accepted": acc,
                     "target": str(0.71 - 0.01 * point), **{q: str(scale * cpu) for q in bb.QUANTITIES},
                     "load_average": "3.0"})
    return rows


def test_summary_fits_the_exponent_of_a_power_law_over_the_warm_points():
    cases = [{"epsilon": e} for e in (0.14, 0.07, 0.05)]
    nodes = (31104, 98304, 204800)
    rows = [r for c, n in zip(cases, nodes) for r in _rows(c["epsilon"], n, 2e-5 * n**1.3)]
    info = bb.summary(rows, cases)
    assert set(info["levels"]) == {"0.14", "0.07", "0.05"}
    lv = info["levels"]["0.07"]
    assert lv["warm_points"] == 3 and lv["cpu_s"] == pytest.approx(2e-5 * 98304**1.3)  # the median: scale 1.0
    # a unit of v: the warm points' CPU (1.0 + 1.1 + 0.9 of it) over v from point 1 to point 4 (0.03)
    assert lv["cpu_s_per_v"] == pytest.approx(3.0 * 2e-5 * 98304**1.3 / 0.03)
    assert info["exponents"]["cpu_s_per_v"] == pytest.approx(1.3, abs=1e-9)
    for q in bb.QUANTITIES:  # a pure power law: polyfit recovers its exponent to round-off
        assert info["exponents"][q] == pytest.approx(1.3, abs=1e-9)
        assert info["exponents_two_largest"][q] == pytest.approx(1.3, abs=1e-9)


def test_exponents_need_two_levels():
    assert math.isnan(bb.exponents([1000], [1.0]))
    assert bb.exponents([1e3, 1e4], [1.0, 10.0**1.15]) == pytest.approx(1.15)
