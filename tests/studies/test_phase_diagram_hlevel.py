"""The h -> 0 correction of the ``phase_diagram`` transitions (``studies._hlevel``): the arithmetic on
closed forms (fast), and one state's three levels end to end (slow)."""

import math

import numpy as np
import pytest

from vesicle_opt.studies import _hlevel as H
from vesicle_opt.studies import phase_diagram as P

LEVELS = (2.0, 4.0, 8.0)  # eps / h of the three levels


@pytest.mark.parametrize("p", [2.0, 1.7])
def test_share_recovers_limit_and_order(p):
    """y = y0 + C h^p at h = eps/2, eps/4, eps/8: the observed order and limit are exact (brentq's xtol
    on p, 2e-12, amplified by the Richardson factor), the share of eps/h = 4 is C (eps/4)^p; the p = 2
    limit is exact for p = 2 only."""
    eps, y0, c = 0.03, 1.82, -7.0
    h = [eps / k for k in LEVELS]
    s = H.share(h, [y0 + c * x**p for x in h])
    assert s["order"] == pytest.approx(p, abs=1e-8) and s["limit"] == pytest.approx(y0, abs=1e-12)
    assert s["share"] == pytest.approx(c * (eps / 4) ** p, abs=1e-12)
    assert (abs(s["limit_p2"] - y0) < 1e-13) == (p == 2.0) and s["order_used"] == s["order"]
    two = H.share(h[1:], [y0 + c * x**p for x in h[1:]])  # the coarsest level missing: p = 2 from the others
    assert math.isnan(two["order"]) and two["order_used"] == 2.0 and two["share"] == two["share_p2"] == s["share_p2"]


def _branches(eps, h):
    """Closed form: f_a = 1 + (0.7 - v) + 2 (0.7 - v)^2 + eps^2 - 3 h^2 and
    f_b = 1.05 + 0.5 (0.7 - v) + 2 (0.7 - v)^2 + 3 eps^2 + 4 h^2 cross where
    0.5 (0.7 - v) = 0.05 + 2 eps^2 + 7 h^2: at h = 0, v0 = 0.6 - 4 eps^2, f0 = f_a(v0); at h, v0 - 14 h^2."""
    fa = lambda v: 1 + (0.7 - v) + 2 * (0.7 - v) ** 2 + eps**2 - 3 * h**2  # noqa: E731
    fb = lambda v: 1.05 + 0.5 * (0.7 - v) + 2 * (0.7 - v) ** 2 + 3 * eps**2 + 4 * h**2  # noqa: E731
    v0 = 0.6 - 4 * eps**2
    return fa, fb, v0, 1 + (0.7 - v0) + 2 * (0.7 - v0) ** 2 + eps**2


def test_corrected_crossing_is_the_h0_crossing():
    """Splines through the eps/h = 4 points, each shifted by its share from three levels at the located
    crossing: the h = 0 crossing of the closed form (spline exact on quadratics, brentq xtol 1e-14);
    the uncorrected crossing is off by the shares' difference over the slopes' (-7 h^2 / 0.5)."""
    eps = 0.04
    vs = np.array([0.68, 0.66, 0.64, 0.62, 0.6, 0.58, 0.56])
    fa4, fb4, v0, f0 = _branches(eps, eps / 4)
    x4 = P.crossing(vs, fa4(vs), vs, fb4(vs))
    assert x4["reduced_volume"] == pytest.approx(v0 - 14 * (eps / 4) ** 2, abs=1e-12)
    h = [eps / k for k in LEVELS]
    sa = H.share(h, [_branches(eps, x)[0](x4["reduced_volume"]) for x in h])
    sb = H.share(h, [_branches(eps, x)[1](x4["reduced_volume"]) for x in h])
    x = H.corrected_crossing(vs, fa4(vs), vs, fb4(vs), sa["share"], sb["share"])
    assert x["reduced_volume"] == pytest.approx(v0, abs=1e-12) and x["reduced_energy"] == pytest.approx(f0, abs=1e-12)


def _rows(epsilons=(0.05, 0.04, 0.03)):
    """Study rows of the closed form: eps/h = 4 near walks and, per eps, h-level rows of both branches
    at the uncorrected crossing (as the stage-two cases solve them)."""
    rows = []
    vs = (0.68, 0.66, 0.64, 0.62, 0.6, 0.58, 0.56)
    for eps in epsilons:
        fa4, fb4, _, _ = _branches(eps, eps / 4)
        for b, f in (("prolate", fa4), ("oblate", fb4)):
            rows += [{"branch": b, "shape": b, "epsilon": eps, "target_v": v, "reduced_volume": v, "f": f(v),
                      "sharp_f": math.nan, "converged": "True", "kind": "point", "part": "near"} for v in vs]
        vx = P.crossing(vs, [fa4(v) for v in vs], vs, [fb4(v) for v in vs])["reduced_volume"]
        for k in LEVELS:
            fa, fb, _, _ = _branches(eps, eps / k)
            rows += [{"branch": b, "shape": b, "epsilon": eps, "target_v": vx, "reduced_volume": vx, "f": f(vx),
                      "lambda": 0.0, "converged": "True", "kind": "h_level", "transition": "crossing", "point": "",
                      "eps_over_h": k} for b, f in (("prolate", fa), ("oblate", fb))]
    return rows


def test_summary_corrects_each_eps_and_extrapolates():
    """The summary's new keys on the closed form's rows: per eps the h = 0 crossing (v0 = 0.6 - 4 eps^2),
    observed order 2 and the shares -3 h^2 / 4 h^2 of eps/h = 4; eps -> 0 (p = 2, exact in eps^2): 0.6;
    the uncorrected keys unchanged by the h-level rows (the crossing at eps/h = 4)."""
    s = P.summarise(_rows())
    for e, x in s["crossings_h_corrected"].items():
        eps = float(e)
        _, _, v0, f0 = _branches(eps, 0.0)
        assert x["v"] == pytest.approx(v0, abs=1e-12) and x["f"] == pytest.approx(f0, abs=1e-12)  # brentq xtol
        assert s["crossings"][e]["v"] == pytest.approx(v0 - 14 * (eps / 4) ** 2, abs=1e-12)
        lv = s["h_levels"][e]
        assert lv["prolate"]["order"] == pytest.approx(2.0, abs=1e-8)  # brentq on p
        assert lv["prolate"]["mesh_share"] == pytest.approx(-3 * (eps / 4) ** 2, abs=1e-12)
        assert lv["oblate"]["mesh_share_p2"] == pytest.approx(4 * (eps / 4) ** 2, abs=1e-12)
        assert abs(lv["oblate"]["same_state"]) < 1e-12  # the spline is exact on the quadratic: round-off
    ext = s["extrapolated_h_corrected"]
    assert ext["reduced_volume_p2"] == pytest.approx(0.6, abs=1e-9)  # round-off / (1 - r^2)
    assert ext["reduced_volume_richardson"] == pytest.approx(0.6, abs=1e-8)  # free order: exact in eps^2
    assert ext["order_reduced_volume"] == pytest.approx(2.0, abs=1e-4)
    assert s["extrapolated_h_corrected_p2"]["reduced_volume_p2"] == pytest.approx(0.6, abs=1e-9)


def test_corrected_fold_removes_the_shares():
    """A fold walk at eps/h = 4: lambda_h = lambda0 + 0.3 h^2, f_h = F(lambda0) + 5 h^2 at the same v
    (v = 0.66 - 3 (lambda0 - 0.5)^2, F = 1.96 + (lambda0 - 0.5)^2); the three fold points' shares from
    their levels give the h = 0 fold (0.66, 1.96) to polyfit's round-off; uncorrected f is 5 h^2 high."""
    eps = 0.03
    lam0 = np.array([0.2, 0.3, 0.4, 0.45])
    v = 0.66 - 3 * (lam0 - 0.5) ** 2
    level = lambda h: ([1.96 + (x - 0.5) ** 2 + 5 * h**2 for x in lam0], lam0 + 0.3 * h**2)  # noqa: E731
    f4, l4 = level(eps / 4)
    up = [{"reduced_volume": a, "f": b, "lambda": c} for a, b, c in zip(v, f4, l4)]
    assert H.fold_points(v) == [1, 2, 3]
    sh = {}
    for i, k in enumerate(H.fold_points(v)):
        fs, ls = zip(*[(level(eps / q)[0][k], level(eps / q)[1][k]) for q in LEVELS])
        h = [eps / q for q in LEVELS]
        sh[("fold", f"stomatocyte{i}", eps)] = {"v": v[k], "eps_over_h": list(LEVELS), "f": list(fs), "lambda": list(ls),
                                                "f_share": H.share(h, fs), "lambda_share": H.share(h, ls)}
    raw = P.stoma.fold_of(v, f4, l4)
    assert raw[1] == pytest.approx(1.96 + 5 * (eps / 4) ** 2, abs=1e-12)
    fold, fold_p2, levels = H.fold(up, sh, eps)
    for x in (fold, fold_p2):
        assert x["reduced_volume"] == pytest.approx(0.66, abs=1e-12)  # polyfit round-off
        assert x["reduced_energy"] == pytest.approx(1.96, abs=1e-12)
    assert levels["0"]["order"] == pytest.approx(2.0, abs=1e-8) and levels["1"]["same_state"] == 0.0  # the same numbers


def test_fold_points_are_fold_of_selection():
    """The indices ``fold_points`` gives are those ``fold_of`` fits: about an interior maximum, the last
    three at a maximum at the end, none with a maximum first or fewer than three points."""
    assert H.fold_points([0.60, 0.63, 0.64, 0.62]) == [1, 2, 3]
    assert H.fold_points([0.60, 0.63, 0.65, 0.64, 0.62]) == [1, 2, 3]
    assert H.fold_points([0.65, 0.63, 0.6]) == [] and H.fold_points([0.6, 0.61]) == []


def test_level_layout_keeps_box_and_coarse_cells():
    """eps/h = 2, 4, 8 on one box: the band's spacing halves per level, the coarse cell side
    h 2^levels (and so the box and its cells) is the same."""
    from vesicle_opt.studies import _meridian as M
    t = np.linspace(0, np.pi, 401)
    lay = M.layout([(0.8 * np.sin(t), 1.3 * np.cos(t))], 0.05, 4.0)
    for j in (-1, 1):
        q = H.level_layout(lay, j)
        assert q["box"] == lay["box"] and q["mesh"]["n"] == lay["mesh"]["n"]
        assert q["h"] * 2 ** q["mesh"]["levels"] == pytest.approx(lay["h"] * 2 ** lay["mesh"]["levels"], rel=1e-15)
        assert q["h"] == pytest.approx(lay["h"] / 2**j, rel=1e-15)


def test_stage_two_cases_from_located_transitions(tmp_path):
    """The h-level cases of the located transitions: a crossing's states from each branch's point
    nearest it (a saved field where there is one), walked to from its sharp shape otherwise; the fold
    one case an eps with its three points and the up grid's walk to the highest."""
    from vesicle_opt.studies._meridian import state_path
    rows = [r for r in _rows((0.05,)) if r["kind"] == "point"]
    for r in rows:
        r["case"] = f"{r['branch']}-eps0.05"
    up = [0.62, 0.64, 0.65, 0.655, 0.66]
    rows += [{"branch": "stomatocyte", "epsilon": 0.05, "target_v": v, "reduced_volume": v, "f": 1.9, "lambda": i,
              "converged": "True", "kind": "point", "walk": "up", "shape": "cup", "case": "stomatocyte-up-eps0.05"}
             for i, v in enumerate(up)]
    state_path(tmp_path, "oblate-eps0.05", 0.6).touch()
    summary = {"crossings": {"0.05": {"v": 0.603, "f": 1.2}}, "stomatocyte_fold": {"per_eps": {"0.05": {}}}}
    cs = {c["case"]: c for c in H.cases(rows, summary, tmp_path, {"up": up + [0.665], "down": [0.62, 0.6], "low": [], "near": [0.6]})}
    assert set(cs) == {"h-crossing-prolate-eps0.05", "h-crossing-oblate-eps0.05", "h-fold-stomatocyte-eps0.05"}
    ob, pro, fold = cs["h-crossing-oblate-eps0.05"], cs["h-crossing-prolate-eps0.05"], cs["h-fold-stomatocyte-eps0.05"]
    assert ob["v"] == pro["v"] == 0.603 and ob["source"] == "oblate-eps0.05 v 0.6" and pro["walk_vs"] == [0.603]
    assert ob["state"] == str(state_path(tmp_path, "oblate-eps0.05", 0.6)) and ob["layout_vs"] == [0.6]
    assert [q["v"] for q in fold["points"]] == [0.65, 0.655, 0.66] and fold["walk_vs"] == up


@pytest.mark.parametrize("p", [2.0, 1.7])
def test_share_at_order_is_exact_with_the_true_order(p):
    """y = y0 + C h^p at eps/h = 2 and 4 only, with the order p known (observed at another eps): the
    limit and the share C (eps/4)^p of eps/h = 4 exactly (round-off of the Richardson factor); with
    no order observed (nan), the p = 2 limit and ``order_used`` 2."""
    eps, y0, c = 0.025, 1.82, -7.0
    h = [eps / 2, eps / 4]
    y = [y0 + c * x**p for x in h]
    s = H.share_at_order(h, y, p)
    assert s["limit"] == pytest.approx(y0, abs=1e-13) and s["share"] == pytest.approx(c * (eps / 4) ** p, abs=1e-13)
    assert s["order_used"] == p and (abs(s["limit_p2"] - y0) < 1e-13) == (p == 2.0)
    none = H.share_at_order(h, y, math.nan)
    assert none["order_used"] == 2.0 and none["share"] == none["share_p2"] == s["share_p2"]


def test_summary_with_the_order_from_the_coarsest_eps():
    """Stage two as the study runs it (``ORDER_FROM``): eps/h = 8 at the coarsest eps alone, eps/h = 2
    and 4 at the finer ones. The closed form's shares are exact in h^2, so every eps's corrected
    crossing is the h = 0 one (brentq xtol), the finer eps carry the order observed at 0.05."""
    rows = [r for r in _rows() if not (r["kind"] == "h_level" and r["eps_over_h"] == 8.0 and r["epsilon"] != 0.05)]
    s = P.summarise(rows)
    assert set(s["crossings_h_corrected"]) == {"0.05", "0.04", "0.03"}
    for e, x in s["crossings_h_corrected"].items():
        _, _, v0, f0 = _branches(float(e), 0.0)
        assert x["v"] == pytest.approx(v0, abs=1e-12) and x["f"] == pytest.approx(f0, abs=1e-12)  # brentq xtol
        lv = s["h_levels"][e]["prolate"]
        assert lv["order"] == pytest.approx(2.0, abs=1e-8)  # brentq on p at eps 0.05, carried
        assert lv["order_from_eps"] == (None if e == "0.05" else 0.05)
    assert s["extrapolated_h_corrected"]["reduced_volume_p2"] == pytest.approx(0.6, abs=1e-9)  # round-off / (1 - r^2)


def test_stage_two_levels_eps_over_h_8_at_the_coarsest_eps_only(tmp_path, monkeypatch):
    """``cases`` gives each transition's coarsest eps the three levels and the finer eps two (eps/h = 4,
    2); ``ORDER_FROM = "all"`` gives every eps three (the former stage two)."""
    rows = [r for r in _rows((0.05, 0.04)) if r["kind"] == "point"]
    for r in rows:
        r["case"] = f"{r['branch']}-eps{r['epsilon']:g}"
    summary = {"crossings": {"0.05": {"v": 0.6, "f": 1.2}, "0.04": {"v": 0.6, "f": 1.2}}}
    grids = {"up": [], "down": [], "low": [], "near": [0.6]}
    cs = H.cases(rows, summary, tmp_path, grids)
    assert {(c["epsilon"], tuple(c["levels"])) for c in cs} == {(0.05, H.LEVELS), (0.04, H.CHEAP_LEVELS)}
    monkeypatch.setattr(H, "ORDER_FROM", "all")
    assert {tuple(c["levels"]) for c in H.cases(rows, summary, tmp_path, grids)} == {H.LEVELS}


def test_stage_three_observes_the_order_one_eps_down_where_the_coarsest_refused_eps_over_h_2(tmp_path):
    """``order_cases``: the coarsest eps (0.05) refused eps/h = 2, so stage two skipped eps/h = 8 there and
    no state has three levels: eps/h = 8 is asked at 0.04 (both states have eps/h = 2 and 4), the levels
    (1,) alone under new case names; with those rows the summary carries 0.04's order (exact on the closed
    form) to 0.03, and the corrected crossings are the h = 0 ones. Nothing is asked where the order was
    observed, nor at an eps whose eps/h = 2 is missing."""
    rows = [r for r in _rows() if not (r["kind"] == "h_level" and r["eps_over_h"] == 8.0)]
    for r in rows:
        if r["kind"] == "h_level" and r["epsilon"] == 0.05 and r["eps_over_h"] == 2.0:
            r["converged"] = "False"  # refused
    pts = [r for r in rows if r["kind"] == "point"]
    for r in pts:
        r["case"] = f"{r['branch']}-eps{r['epsilon']:g}"
    summary = {"crossings": {f"{e:g}": {"v": 0.6, "f": 1.2} for e in (0.05, 0.04, 0.03)}}
    staged = H.cases(pts, summary, tmp_path, {"up": [], "down": [], "low": [], "near": [0.6]})
    third = H.order_cases(rows, staged)
    assert sorted(c["case"] for c in third) == ["h-crossing-oblate-eps0.04-order", "h-crossing-prolate-eps0.04-order"]
    assert all(c["levels"] == [1] and c["epsilon"] == 0.04 for c in third)
    # the eps/h = 8 rows they give: the summary takes the order at 0.04 and carries it to 0.03
    done = rows + [r for r in _rows() if r["kind"] == "h_level" and r["eps_over_h"] == 8.0 and r["epsilon"] == 0.04]
    assert H.order_cases(done, staged) == []
    s = P.summarise(done)
    assert s["h_levels"]["0.03"]["prolate"]["order_from_eps"] == 0.04
    assert s["h_levels"]["0.03"]["prolate"]["order"] == pytest.approx(2.0, abs=1e-8)  # brentq on p at 0.04
    for e in ("0.04", "0.03"):
        _, _, v0, f0 = _branches(float(e), 0.0)
        x = s["crossings_h_corrected"][e]
        assert x["v"] == pytest.approx(v0, abs=1e-12) and x["f"] == pytest.approx(f0, abs=1e-12)  # brentq xtol
    # an eps whose eps/h = 2 is missing for a state is passed over: 0.04's prolate refused, so 0.03
    for r in rows:
        if r["kind"] == "h_level" and r["epsilon"] == 0.04 and r["eps_over_h"] == 2.0 and r["branch"] == "prolate":
            r["converged"] = "False"
    assert {c["epsilon"] for c in H.order_cases(rows, staged)} == {0.03}
