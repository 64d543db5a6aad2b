"""The study ``phase_diagram`` (meridian half-plane, c0 = 0): its summary's crossing on rows of known
branches (fast), and the quick run end to end (slow: ~20 s)."""

import csv
import json
import math

import numpy as np
import pytest

from vesicle_opt.io.meridian import phase_field_of
from vesicle_opt.mesh import axisymmetric as ax
from vesicle_opt.studies import phase_diagram as P


def test_seed_is_the_tanh_profile_of_the_curve():
    """phase_field_of a half circle (the unit sphere's meridian, 2001 vertices) against the closed form
    tanh((1 - rho) / (sqrt2 eps)): the distance to the vertices errs by <= half their spacing (8e-4),
    times the profile's slope 1/(sqrt2 eps) = 7.1: measured 3.7e-3."""
    d = ax.p1(((0.0, 2.0), (-2.0, 2.0)), (40, 80))
    t = np.linspace(0, np.pi, 2001)
    phi = phase_field_of(np.sin(t), np.cos(t), d.nodes, 0.1)
    exact = np.tanh((1 - np.hypot(*d.nodes.T)) / (math.sqrt(2) * 0.1))
    assert np.abs(phi - exact).max() < 6e-3


def test_summary_crossing_of_two_known_branches():
    """Straight branches f = 1 + (0.7 - v) and f = 1.05 + 0.5 (0.7 - v) + eps^2 cross at
    v = 0.6 - 2 eps^2, f = 1.1 + 2 eps^2: the summary finds each crossing (spline root, exact on lines)
    and extrapolates them to (0.6, 1.1) (p = 2 Richardson, exact on eps^2); the sharp crossing through
    the same points (eps-free lines) is (0.6, 1.1)."""
    rows = []
    for eps in (0.1, 0.07, 0.05):
        for v in (0.75, 0.7, 0.65, 0.6, 0.55):
            lines = (("prolate", 1 + (0.7 - v), 1 + (0.7 - v)),
                     ("oblate", 1.05 + 0.5 * (0.7 - v) + eps**2, 1.05 + 0.5 * (0.7 - v)))
            for b, f, f_sharp in lines:
                rows.append({"branch": b, "epsilon": eps, "target_v": v, "reduced_volume": v, "f": f,
                             "sharp_f": f_sharp, "converged": "True"})
    s = P.summarise(rows)
    for e, x in s["crossings"].items():
        eps = float(e)
        assert x["v"] == pytest.approx(0.6 - 2 * eps**2, abs=1e-12)  # round-off of brentq's xtol
        assert x["f"] == pytest.approx(1.1 + 2 * eps**2, abs=1e-12)
    assert s["extrapolated"]["reduced_volume_p2"] == pytest.approx(0.6, abs=1e-9)  # round-off amplified by 1/(1-r^2)
    assert s["extrapolated"]["reduced_energy_p2"] == pytest.approx(1.1, abs=1e-9)
    assert s["sharp_crossing_at_these_points"]["v"] == pytest.approx(0.6, abs=1e-12)


def test_shape_of_tells_prolate_oblate_and_cup():
    """The form of three fields: tanh ellipsoids (semi-axes 0.7, 0.7, 1.4 and 1.2, 1.2, 0.5) and the tanh
    profile of a cup (psi - s = 5 sin s ((1 - cos s)/2)^3 of ``sharp.spontaneous``'s parametrisation:
    one pole turned inwards to the other's side)."""
    from vesicle_opt.scene.shape_spec import Shape
    from vesicle_opt.scene.shapes import phase_field
    from vesicle_opt.sharp import spontaneous as S
    d = ax.p1(((0.0, 2.0), (-2.0, 2.0)), (80, 160))
    for semi, form in (((0.7, 0.7, 1.4), "prolate"), ((1.2, 1.2, 0.5), "oblate")):
        phi = phase_field(Shape("ellipsoid", semi_axes=semi), *d.scene_points(), 0.05)
        assert P.shape_of(d, phi) == form
    g = S.Geometry(24)
    y = 5.0 * np.sin(g.s) * ((1 - np.cos(g.s)) / 2) ** 3
    a = np.array([2 / g.m * np.sum(y * np.sin(j * g.s)) for j in range(1, 25)])
    r, z, _, _ = g.shape(a)
    half = g.m // 2 + 1
    r, z = np.maximum(r[:half].real, 0.0), z[:half].real
    assert P.shape_of(d, phase_field_of(r, z - (z.max() + z.min()) / 2, d.nodes, 0.03)) == "cup"


@pytest.mark.slow  # 20-45 s: four meridian solves and the sharp branches
def test_quick_run(tmp_path):
    assert P.main(tmp_path, quick=True) == 0
    with open(tmp_path / "phase_diagram.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 and all(r["converged"] == "True" for r in rows)
    assert {r["seed"] for r in rows} == {"sharp shape", "previous point"}
    # at eps = 0.1 the oblate seeds' dimples meet: tori (measured; the full run finds oblates at eps = 0.05)
    assert [r["shape"] for r in rows] == ["prolate", "prolate", "torus", "torus"]
    assert all(abs(float(r["reduced_volume"]) - float(r["target_v"])) < 1e-7 for r in rows)  # exact constraints
    assert all(float(r["c0_reduced"]) == 0.0 for r in rows)
    # the gap to the sharp f at eps = 0.1, h = eps/2: measured +0.18, +0.24 (prolate), -0.03, +0.02 (torus/oblate)
    assert all(abs(float(r["f_minus_sharp"])) < 0.3 for r in rows)
    assert P.summarise(rows)["crossings"] == {}  # no oblate points: no crossing
    summary = json.loads((tmp_path / "phase_diagram_summary.json").read_text())
    assert summary["sharp_crossing_at_these_points"]["v"] == pytest.approx(0.651, abs=0.01)  # 2 points' spline
    assert (tmp_path / "phase_diagram.png").is_file()


def test_stomatocyte_summary_on_known_branches():
    """Synthetic rows per eps: an up walk with v = 0.66 + eps^2 - 3 x^2, f = 1.96 + eps^2 + x^2
    (x = lambda - 0.5: the fold at (0.66 + eps^2, 1.96 + eps^2), exact for the parabolas), a lower side
    f = 1.98 + 0.5 (0.59 - v) and an oblate f = 1.98 + eps^2 + 2 (0.59 - v) (crossing at
    v = 0.59 + eps^2 / 1.5); the summary finds each per eps and extrapolates both to eps = 0 exactly
    (p = 2 on data exact in eps^2); the sharp rows (eps = 0, kind fold / crossing) pass through."""
    rows = [{"branch": "stomatocyte", "epsilon": 0.0, "kind": k, "reduced_volume": v, "f": f, "converged": "True"}
            for k, v, f in (("fold", 0.6604, 1.9633), ("crossing", 0.5903, 1.9812))]
    for eps in (0.05, 0.04, 0.03):
        for lam in (0.3, 0.4, 0.5, 0.6, 0.7):
            x = lam - 0.5
            rows.append({"branch": "stomatocyte", "epsilon": eps, "kind": "point", "walk": "up", "side": "",
                         "reduced_volume": 0.66 + eps**2 - 3 * x**2, "f": 1.96 + eps**2 + x**2, "lambda": lam,
                         "converged": "True"})
        for v in (0.63, 0.61, 0.59, 0.57):
            rows.append({"branch": "stomatocyte", "epsilon": eps, "kind": "point", "walk": "down", "side": "lower",
                         "reduced_volume": v, "f": 1.98 + 0.5 * (0.59 - v), "converged": "True"})
            rows.append({"branch": "oblate", "epsilon": eps, "shape": "oblate", "reduced_volume": v,
                         "f": 1.98 + eps**2 + 2 * (0.59 - v), "converged": "True"})
    s = P.stomatocyte_summary(rows)
    fold, cross = s["stomatocyte_fold"], s["oblate_stomatocyte_crossing"]
    for e, x in fold["per_eps"].items():
        eps = float(e)
        assert x["v"] == pytest.approx(0.66 + eps**2, abs=1e-12) and x["f"] == pytest.approx(1.96 + eps**2, abs=1e-12)
    for e, x in cross["per_eps"].items():
        assert x["v"] == pytest.approx(0.59 + float(e) ** 2 / 1.5, abs=1e-12)  # brentq's xtol, spline exact on lines
    assert len(fold["per_eps"]) == 3 and len(cross["per_eps"]) == 3
    assert fold["extrapolated"]["reduced_volume_p2"] == pytest.approx(0.66, abs=1e-9)  # round-off / (1 - r^2)
    assert cross["extrapolated"]["reduced_volume_p2"] == pytest.approx(0.59, abs=1e-9)
    assert fold["sharp"] == {"v": 0.6604, "f": 1.9633} and cross["published"] == {"v": 0.59, "f": 1.98}


def test_fold_from_the_lower_side_is_the_vertex_ahead():
    """Points of v = 0.66 - 3 (lambda - 0.5)^2, f = 1.96 + (lambda - 0.5)^2 on one side of the fold only
    (lambda 0.2, 0.3, 0.4: the walk ends below it): the vertex of the parabola through the last three is
    the fold, exact on parabolas (round-off of polyfit); a vertex more than AHEAD lambda steps ahead is
    no fold (None), nor is a walk whose v still rises linearly (no vertex ahead)."""
    from vesicle_opt.studies import _stomatocyte as S
    lam = np.array([0.1, 0.2, 0.3, 0.4])
    v, f = 0.66 - 3 * (lam - 0.5) ** 2, 1.96 + (lam - 0.5) ** 2
    fv = S.fold_of(v, f, lam)
    assert fv[0] == pytest.approx(0.66, abs=1e-12) and fv[1] == pytest.approx(1.96, abs=1e-12)  # polyfit round-off
    far = np.array([0.34, 0.36, 0.38, 0.40])  # steps of 0.02 ending 0.1 (5 steps) before the vertex
    assert S.fold_of(0.66 - 3 * (far - 0.5) ** 2, far, far) is None
    assert S.fold_of(0.6 + 0.01 * lam, lam, lam) is None


def test_extrapolate_reports_order_and_error():
    """Crossings y = y0 + c eps^p at four eps: the free-order limit and order are exact (p = 1.7 here,
    not 2), the error estimate (three coarsest against three finest) is round-off; with an eps^3 term
    added the estimate equals the actual change of the limit between the two triples, and bounds the
    actual error of the finest triple within a factor of a few (the next term's size)."""
    eps = (0.05, 0.04, 0.03, 0.025)
    exact = {e: {"reduced_volume": 0.65 + 2.0 * e**1.7, "reduced_energy": 1.83 - 3 * e**1.7} for e in eps}
    x = P.extrapolate(exact)
    assert x["reduced_volume_richardson"] == pytest.approx(0.65, abs=1e-10)  # brentq on p: xtol 2e-12, amplified
    assert x["order_reduced_volume"] == pytest.approx(1.7, abs=1e-6)
    assert x["reduced_volume_error"] < 1e-9 and x["order_reduced_energy_coarse"] == pytest.approx(1.7, abs=1e-6)
    bent = {e: {"reduced_volume": 0.65 + 2.0 * e**2 + 40 * e**3, "reduced_energy": 1.83 + e**2} for e in eps}
    y = P.extrapolate(bent)
    assert 0 < abs(y["reduced_volume_richardson"] - 0.65) < 5 * y["reduced_volume_error"]
    three = P.extrapolate({e: bent[e] for e in eps[1:]})
    assert three["reduced_volume_error"] == pytest.approx(abs(three["reduced_volume_richardson"] - three["reduced_volume_p2"]))


def test_layout_is_square_cells_about_the_shapes():
    """The box of ``_meridian.layout``: whole coarse cells of side 2^levels h (square: refined meshes
    need right isosceles triangles), r from 0, and at least WALL eps of free space about the meridian."""
    from vesicle_opt.studies import _meridian as M
    t = np.linspace(0, np.pi, 401)
    r, z = 0.8 * np.sin(t), 1.3 * np.cos(t) + 0.1
    for eps in (0.05, 0.025):
        lay = M.layout([(r, z)], eps, 4.0)
        (r0, r1), (z0, z1) = lay["box"]
        side = lay["h"] * 2 ** lay["mesh"]["levels"]
        assert r0 == 0 and lay["h"] == eps / 4
        assert (r1 - r0) / lay["n"][0] == pytest.approx(side) and (z1 - z0) / lay["n"][1] == pytest.approx(side)
        assert r1 >= r.max() + M.WALL * eps and z0 <= z.min() - M.WALL * eps and z1 >= z.max() + M.WALL * eps


def test_layout_centres_the_box_where_the_pin_holds_the_shape():
    """The axial pin holds the centre of mass of the inside at the box's mid-height
    (``nlp.reuse.pin_row``): an up-down asymmetric meridian (an egg) gets a box centred on its volume
    centroid (a closed-form quadrature, not the frusta) with WALL eps from both ends there; up-down
    symmetric meridians the box of the extent's middle (the layout before the centroid: written out
    here), one coarse cell taller where its n_z was odd (the refined mesh mirrors only with n_z even:
    ``mesh.refine.mirrored_tensor``); the seed moves the meridian to the mid-height (its phase field's centre of mass there to
    O(eps^2): the tanh profile's offset)."""
    import math
    from scipy.integrate import quad
    from vesicle_opt.studies import _meridian as M

    def by_extent(meridians, eps, even=True):  # the box centred on the middle of the extent (the former layout)
        h, pad = eps / 4, M.WALL * eps
        r_hi = max(float(r.max()) for r, _ in meridians) + pad
        z_lo, z_hi = min(float(z.min()) for _, z in meridians) - pad, max(float(z.max()) for _, z in meridians) + pad
        h0 = h * 2 ** M.LEVELS
        n = [max(4, math.ceil(r_hi / h0)), max(4, math.ceil((z_hi - z_lo) / h0))]
        n[1] += n[1] % 2 if even else 0  # even: the mirror
        mid = (z_lo + z_hi) / 2
        return [[0.0, n[0] * h0], [mid - n[1] * h0 / 2, mid + n[1] * h0 / 2]], n

    t = np.linspace(0, np.pi, 4001)
    sym = [(0.8 * np.sin(t), 1.3 * np.cos(t)), (1.1 * np.sin(t), 0.6 * np.cos(t))]
    for eps in (0.05, 0.025):
        for ms in (sym, sym[1:]):
            box, n = by_extent(ms, eps)
            lay = M.layout(ms, eps, 4.0)
            assert lay["n"] == n and n[1] % 2 == 0
            assert np.allclose(lay["box"], box, rtol=0, atol=1e-13)  # round-off: the centroid is 0 to ~1e-17
    R, Z, dZ = (lambda t: 0.8 * np.sin(t) * (1 + 0.4 * np.cos(t))), (lambda t: 1.1 * np.cos(t)), (lambda t: -1.1 * np.sin(t))
    zc = quad(lambda t: Z(t) * R(t) ** 2 * dZ(t), 0, np.pi)[0] / quad(lambda t: R(t) ** 2 * dZ(t), 0, np.pi)[0]
    r, z = R(t), Z(t)
    assert M.centroid(r, z) == pytest.approx(zc, abs=1e-7)  # frusta on 4001 points: second order, 5.1e-8 measured
    assert abs(zc - (z.max() + z.min()) / 2) > 0.1  # the egg's centroid is well off its middle (0.17)
    offsets = []
    for eps in (0.05, 0.025):
        lay = M.layout([(r, z)], eps, 4.0)
        (lo, hi) = lay["box"][1]
        assert (lo + hi) / 2 == pytest.approx(zc, abs=1e-7)  # as the centroid above
        zs = z - zc + (lo + hi) / 2  # where the pin puts it
        assert zs.min() - lo >= M.WALL * eps - 1e-7 and hi - zs.max() >= M.WALL * eps - 1e-7
        assert by_extent([(r, z)], eps, even=False)[0][1][0] + M.WALL * eps > zs.min()  # the former box: too near
    for eps in (0.1, 0.05):  # the seed, given 0.3 off: its centre of mass at the mid-height
        lay = M.layout([(r, z)], eps, 2.0, refine=False)
        s = M.seed(M.scene(lay, eps, 0.9, "egg"), r, z + 0.3, eps, lay["h"])
        w = s.disc.weights * (1 + s.phi)
        offsets.append(float(w @ s.disc.nodes[:, 1] / w.sum()) - sum(lay["box"][1]) / 2)
    assert abs(offsets[0]) < 3e-3  # the tanh profile's centroid: 1.9e-3 off at eps 0.1 (measured), not 0.3
    assert math.log2(offsets[0] / offsets[1]) == pytest.approx(2.0, abs=0.2)  # O(eps^2): 1.93 measured


@pytest.mark.slow
def test_seedless_detour_finds_the_oblates_odd_instability_where_the_sharp_one_is():
    """The detour's way out (``_stomatocyte.seedless``, eps 0.03, v 0.62, no push): the meridian
    oblate's least eigenvalue changes sign between c0 = -0.5 and -1.0 (measured +0.0053, -0.0014
    mu_ref), the bracket of the sharp oblate's odd branch point (c0 = -0.985 at v = 0.62,
    ``sharp.stomatocyte_switch``: +0.088 at -0.75, -0.0055 at -1.0), and every point is an oblate.
    ~40 CPU-s."""
    from vesicle_opt.sharp import stomatocyte as st
    from vesicle_opt.sharp import stomatocyte_switch as sw
    from vesicle_opt.studies import _stomatocyte as S

    assert sw.odd_eigenvalue(st.KKTSystem(24, -0.5), st.oblate_point(0.62, -0.5, 24))[0] > 0  # the sharp bracket, at 24 modes
    assert sw.odd_eigenvalue(st.KKTSystem(24, -1.0), st.oblate_point(0.62, -1.0, 24))[0] < 0
    d, _ = S.seedless(0.62, 0.03, 4.0, True, c0s=(0.0, -0.5, -1.0), push_beyond=-9.0)
    mus = [s.eigenvalue for s in d.leg("out")]
    assert [s.converged for s in d.leg("out")] == [True] * 3
    assert mus[0] > 0 and mus[1] > 0 and mus[2] < 0
    assert not d.reached and d.stopped.startswith("no switch")


def test_seedless_case_records_the_detour_and_falls_back_to_the_seed(monkeypatch):
    """The plumbing of the case key ``seedless`` (``_stomatocyte.phase_case``), the solves replaced: a
    detour that was not reached gives rows of kind "detour" at their own c0 (the last saying why),
    then the walk starts from the seed and its first row says so; a reached one starts the walk from
    its end state, on its layout, and the first row says "no seed"."""
    from vesicle_opt.branch.detour import Detour, Step
    from vesicle_opt.studies import _stomatocyte as S

    seen = {}

    def fake_walk(lay, eps, vs, first, name, stop=None, start=None, states=None, case="", max_iter=None):
        seen["lay"], seen["start"], seen["max_iter"] = lay, start, max_iter
        yield vs[0], "res", "previous point" if start is not None else "sharp shape"

    def row(res, v, eps, lay, sharp_f, seed, side, walk):
        return {"c0": 0.0, "kind": "point", "seed": seed, "status": "converged", "walk": walk}

    case = {"epsilon": 0.03, "walk": "up", "vs": [0.62], "n_modes": 8, "eps_over_h": 4.0, "seedless": True}
    monkeypatch.setattr(S, "walk", fake_walk)
    monkeypatch.setattr(S, "layout", lambda *a: {"seeded": True})
    steps = (Step("out", 0.0, "a", True, 0.01, False), Step("out", -1.0, "b", True, -0.001, False))
    monkeypatch.setattr(S, "seedless", lambda *a, **k: (Detour(steps, False, None, "no switch"), {"detour": True}))
    rows = S.phase_case(case, row)
    assert [(r["kind"], r["c0"]) for r in rows] == [("detour", 0.0), ("detour", -1.0), ("point", 0.0)]
    assert rows[1]["status"] == "detour not reached: no switch"
    assert rows[2]["seed"].endswith("(a seed); the detour in c0 was not reached")
    assert seen == {"lay": {"seeded": True}, "start": None, "max_iter": S.UP_MAX_ITER}  # the up walk's cap

    back = steps + (Step("switch", -1.0, "c", True, 0.02, True, 1), Step("back", 0.0, "d", True, 0.02, True))
    monkeypatch.setattr(S, "seedless", lambda *a, **k: (Detour(back, True, -1.0, None), {"detour": True}))
    rows = S.phase_case(case, row)
    assert rows[-1]["seed"] == "no seed: detour in c0 from the oblate (switched at c0 = -1)"
    assert seen == {"lay": {"detour": True}, "start": "d", "max_iter": S.UP_MAX_ITER}


def test_both_walks_share_one_seed_and_the_up_walk_stops_short_of_its_fold(monkeypatch):
    """``walk`` "both" (``_stomatocyte.phase_case``), the solves replaced by a branch with a known fold
    v(lambda) = v* - (lambda - 1)^2 on its lower side: the seed is solved once (one walk from the
    sharp shape), the down walk starts from the up walk's first point; the up walk does not try a grid
    v more than PAST_FOLD past the fold its last three minima extrapolate to (``fold_of``: exact on
    this parabola), and does try one closer to it (where the solve fails: no minimiser)."""
    import types

    from vesicle_opt.studies import _stomatocyte as S

    calls = []

    def fake_walk(lay, eps, vs, first, name, stop=None, start=None, states=None, case="", max_iter=None):
        calls.append((name, list(vs), start))
        for v in vs:
            ok = v <= v_star
            lam = 1.0 - math.sqrt(max(v_star - v, 0.0))
            res = types.SimpleNamespace(v=v, converged=ok, lambda_volume=lam, extra={"reduced_volume": v, "f": 2 - v})
            yield v, res, "previous point" if start is not None or v != vs[0] else "sharp shape"
            if stop(res):
                return

    def row(res, v, eps, lay, sharp_f, seed, side, walk):
        return {"kind": "point", "seed": seed, "walk": walk, "v": v, "shape": "cup" if res.converged else None}

    monkeypatch.setattr(S, "walk", fake_walk)
    monkeypatch.setattr(S, "layout", lambda *a: {"lay": True})
    sharp = types.SimpleNamespace(a=None, f=1.9, meridian=lambda m: (np.zeros(2), np.zeros(2)))
    monkeypatch.setattr(S.sharp_s, "start_point", lambda v, c0, n: sharp)
    monkeypatch.setattr(S.sharp_s, "newton", lambda a, v, c0, n: sharp)
    up = [0.62, 0.63, 0.64, 0.65, 0.656, 0.66, 0.662, 0.664, 0.666]
    case = {"epsilon": 0.03, "walk": "both", "vs": up, "vs_down": [0.62, 0.61, 0.6], "n_modes": 8, "eps_over_h": 4.0}
    for v_star, last_up in ((0.6625, 0.662), (0.6638, 0.664)):  # 0.664 is 1.5e-3 / 2e-4 past the fold
        calls.clear()
        rows = S.phase_case(case, row)
        got = [(r["walk"], r["v"]) for r in rows]
        ups = [v for w, v in got if w == "up"]
        assert ups == up[:up.index(last_up) + 1] and [v for w, v in got if w == "down"] == [0.61, 0.6]
        (_, _, s_up), (_, vs_down, s_down) = calls
        assert s_up is None and vs_down == [0.61, 0.6] and s_down.v == 0.62  # the seed once; down from it
        assert rows[0]["seed"].endswith("(a seed)") and rows[len(ups)]["seed"] == "the up walk's first point (the same seed)"
