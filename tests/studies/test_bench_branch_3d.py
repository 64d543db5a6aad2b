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


def test_the_steady_window_takes_the_points_after_the_warm_ones():
    """Points 2-5 make ``levels``, points 6 on ``steady`` (each level's own power law: 1.3 in the warm
    window, 1.1 after it), so the two fits recover their own exponents."""
    cases = [{"epsilon": e} for e in (0.14, 0.05)]
    rows = []
    for c, n in zip(cases, (31104, 204800)):
        for point in range(10):
            cpu = (2e-5 * n**1.3 if point < bb.STEADY_FROM else 3e-5 * n**1.1) * (100.0 if point < 2 else 1.0)
            rows.append({"epsilon": str(c["epsilon"]), "nodes": str(n), "point": str(point), "accepted": "True",
                         "target": str(0.71 - 0.01 * point), **{q: str(cpu) for q in bb.QUANTITIES},
                         "load_average": "1.0"})
    info = bb.summary(rows, cases)
    assert info["levels"]["0.05"]["warm_points"] == bb.WARM
    assert info["steady"]["0.05"]["warm_points"] == 10 - bb.STEADY_FROM
    assert info["exponents"]["cpu_s"] == pytest.approx(1.3, abs=1e-9)
    assert info["exponents_steady"]["cpu_s"] == pytest.approx(1.1, abs=1e-9)
    # a unit of v after the warm window: the steady points' CPU over v from point 5 to point 9 (0.04)
    assert info["steady"]["0.14"]["cpu_s_per_v"] == pytest.approx(4 * 3e-5 * 31104**1.1 / 0.04)


def test_cases_walk_every_level_once_a_round_before_the_next_round():
    """Interleaved repeats: round r walks every level before round r + 1; names unique (the resumable
    CSV keys its rows by case); the quick run walks once."""
    todo = bb.cases(False, 3)
    assert [c["epsilon"] for c in todo] == list(bb.LEVELS) * 3
    assert [c["repeat"] for c in todo] == [r for r in range(3) for _ in bb.LEVELS]
    assert len({c["case"] for c in todo}) == len(todo)
    assert [c["case"] for c in todo[:len(bb.LEVELS)]] == [f"eps{e:g}" for e in bb.LEVELS]  # round 0: the old names
    assert [c["repeat"] for c in bb.cases(True, 3)] == [0] * len(bb.QUICK_LEVELS)


def _level(eps, nodes, repeat, cpu):
    return [{"repeat": str(repeat), "epsilon": str(eps), "nodes": str(nodes), "point": str(point), "accepted": "True",
             "target": str(0.71 - 0.01 * point), **{q: str(cpu * (100.0 if point < 2 else 1.0)) for q in bb.QUANTITIES},
             "load_average": "1.0"} for point in range(10)]


def test_each_repeat_keeps_its_own_exponent_and_the_spread_brackets_them():
    """Three repeats, each a pure power law with its own exponent (1.0, 1.1, 1.3): ``by_repeat``
    recovers each, ``exponent_spread`` gives their least, median and largest, and the pooled medians
    lie between the repeats' (the median of three costs at each level: the 1.1 repeat's)."""
    cases = [{"epsilon": e} for e in (0.14, 0.05)]
    powers = {0: 1.0, 1: 1.3, 2: 1.1}
    rows = [r for rep, k in powers.items() for c, n in zip(cases, (31104, 204800))
            for r in _level(c["epsilon"], n, rep, 2e-5 * n**k)]
    info = bb.summary(rows, cases)
    for rep, k in powers.items():
        for window in bb.WINDOWS:  # a pure power law: polyfit recovers it to round-off
            assert info["by_repeat"][str(rep)][window] == pytest.approx(k, abs=1e-9)
    spread = info["exponent_spread"]["all_warm"]
    assert (spread["min"], spread["median"], spread["max"], spread["repeats"]) == pytest.approx((1.0, 1.1, 1.3, 3))
    assert info["all_warm"]["0.05"]["warm_points"] == 3 * (10 - bb.WARM_FROM)
    assert info["exponents_all_warm"]["cpu_s"] == pytest.approx(1.1, abs=1e-9)
    # a unit of v pooled: every repeat's warm CPU over the sum of their stretches (points 1-9: 0.08 of v each)
    total = sum(8 * 2e-5 * 31104**k for k in powers.values())
    assert info["all_warm"]["0.14"]["cpu_s_per_v"] == pytest.approx(total / (3 * 0.08))


def test_rows_without_a_repeat_column_are_one_repeat():
    """Rows of earlier releases (no ``repeat``) read as repeat 0: no spread, the same medians."""
    cases = [{"epsilon": e} for e in (0.14, 0.05)]
    rows = [r for c, n in zip(cases, (31104, 204800)) for r in _level(c["epsilon"], n, 0, 2e-5 * n**1.2)]
    for r in rows:
        del r["repeat"]
    info = bb.summary(rows, cases)
    assert "exponent_spread" not in info
    assert info["exponents_all_warm"]["cpu_s"] == pytest.approx(1.2, abs=1e-9)
