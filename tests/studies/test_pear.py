"""The pear/prolate cases of the ``phase_diagram`` study (vesicle_opt.studies._pear): the shape measures
against closed forms, the seeded phase field's form against its sharp shape, and the summary's crossing
and eps -> 0 extrapolation on rows with a known answer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vesicle_opt.io.meridian import meridian_curves, phase_field_of
from vesicle_opt.mesh import discretize, refine
from vesicle_opt.studies import _pear as P


def _two_spheres(r1: float, r2: float, d: float, m: int = 20001):
    """The meridian (north pole to south pole) of two spheres of radii r1 (centre z = 0) and r2
    (centre z = -d) fused where they meet, the plane z = -a, and its neck radius."""
    a = (d * d + r1 * r1 - r2 * r2) / (2 * d)
    t1 = np.linspace(0.0, math.pi - math.acos(a / r1), m)  # polar angle on sphere 1 down to the plane
    t2 = np.linspace(math.acos((d - a) / r2), math.pi, m)  # on sphere 2 from the plane (angle from its top)
    r = np.concatenate([r1 * np.sin(t1), r2 * np.sin(t2)])
    z = np.concatenate([r1 * np.cos(t1), -d + r2 * np.cos(t2)])
    return r, z, math.sqrt(r1 * r1 - a * a), a


def _cap(R: float, h: float) -> tuple[float, float]:
    """Volume (over pi) and centroid height above the sphere's centre of a cap of height h."""
    return h * h * (3 * R - h) / 3, 3 * (2 * R - h) ** 2 / (4 * (3 * R - h))


def test_measure_of_two_fused_spheres_matches_closed_forms():
    r1, r2, d = 0.8, 0.5, 1.1
    r, z, rho, a = _two_spheres(r1, r2, d)
    neck, asym = P.measure(r, z)
    # the neck is the meridian's vertex on the plane of contact: exact up to the sampling (dtheta ~ 1.6e-4)
    assert neck == pytest.approx(rho, abs=1e-6)
    v1, c1 = _cap(r1, r1 + a)  # sphere 1 above z = -a; its centroid c1 above z = 0
    v2, c2 = _cap(r2, r2 + d - a)  # sphere 2 below z = -a; its centroid c2 below z = -d
    centroid = (v1 * c1 + v2 * (-d - c2)) / (v1 + v2)
    top, bottom = r1, -d - r2
    expected = (centroid - (top + bottom) / 2) / (top - bottom)
    # frusta on 2 x 20001 points: second order in the spacing, 1e-8 relative (measured ~1e-9)
    assert asym == pytest.approx(expected, abs=1e-7)
    # the box is centred on the volume centroid (where the solve's pin holds the centre of mass), the
    # walls at least WALL eps + MARGIN from both ends (frusta: the same 1e-7 as above)
    box, _, _ = P.box_of(r, z, 0.05)
    assert (box[1][0] + box[1][1]) / 2 == pytest.approx(centroid, abs=1e-7)
    assert min(box[1][1] - top, bottom - box[1][0]) >= P.WALL * 0.05 + P.MARGIN - 1e-12
    # the mirror image: the same neck, the opposite asymmetry; a sphere: no neck, no asymmetry
    assert P.measure(r[::-1], -z[::-1]) == pytest.approx((neck, -asym), abs=1e-12)
    t = np.linspace(0, math.pi, 4001)
    n_s, a_s = P.measure(np.sin(t), np.cos(t))
    assert math.isnan(n_s) and abs(a_s) < 1e-12


@pytest.fixture(scope="module")
def sharp_074():
    return P.sharp_branches([0.74], 24)  # ~3 s: seven SLSQP solves at 24 modes


def test_sharp_pear_is_asymmetric_with_a_neck_and_lies_below_the_symmetric_shape(sharp_074):
    pear, sym = sharp_074["pear"][0], sharp_074["prolate_c2.4"][0]
    assert pear.converged and sym.converged
    neck, asym = P.measure(*pear.meridian(4096))
    n_s, a_s = P.measure(*sym.meridian(4096))
    assert abs(asym) > 2 * P.ASYM_MIN and neck > 0.05  # measured -0.112, neck 0.12 R0 at 24 modes
    assert abs(a_s) < 1e-6  # odd modes zeroed between steps; SLSQP leaves them at ~1e-8 (asymmetry 3e-8, measured)
    # below the published crossing (0.746) the pear is the lower state (sharp N = 24 .. 96: 1.5e-3 .. 8e-3)
    assert pear.f < sym.f


def test_tanh_seed_keeps_the_sharp_form_on_the_band_mesh(sharp_074):
    """The seed of a phase-field case (tanh profile of the sharp meridian on the band mesh about it):
    its phi = 0 curve is a pear whose neck and asymmetry are the sharp pear's to the P1 interpolant's
    accuracy, and the symmetric shape's is up-down symmetric on the mirrored mesh."""
    eps = 0.035  # the 24-mode pear's neck 0.1215 R0 is 3.5 eps: clear of NECK_EPS = 3
    for which, want in (("pear", "pear"), ("prolate_c2.4", "prolate")):
        s = sharp_074[which][0]
        r, z = s.meridian(2048)
        box, n, levels = P.box_of(r, z, eps)
        assert n[1] % 2 == 0 and math.isclose((box[1][1] - box[1][0]) / n[1], box[0][1] / n[0])  # square, even n_z
        sc = P._scene(box, n, levels, eps, 0.74, "seed")
        disc = discretize(sc, interface=refine.curve_distance(np.column_stack([r, z]), eps / P.EPS_OVER_H))
        phi = phase_field_of(r, z, disc.nodes, eps)
        shape, neck_eps, asym = P.form(meridian_curves(disc, phi), eps)
        sharp_neck, sharp_asym = P.measure(r, z)
        assert shape == want, (which, shape, neck_eps, asym)
        h = eps / P.EPS_OVER_H
        if want == "pear":
            # the zero line of the P1 interpolant: measured 4e-4 from the sharp neck at eps = 0.04 (h = 0.01)
            assert neck_eps * eps == pytest.approx(sharp_neck, abs=h)
            assert asym == pytest.approx(sharp_asym, abs=1e-4)  # measured 3e-6 at eps = 0.04
        else:
            assert abs(asym) < 1e-6  # a mirrored mesh and a mirrored field (measured 8e-11 at eps = 0.04)
    assert P.form([np.array([[0.0, 1.0], [0.5, 0.0]]), np.array([[0.0, -0.5], [0.2, -0.7], [0.0, -0.9]])],
                  eps)[0] == "pinched"  # two bodies


def _rows(eps: float, v_x: float, f_x: float, neck=lambda v: 4.0) -> list[dict]:
    out = []
    for v in (0.72, 0.74, 0.76, 0.78):
        for b, slope in (("pear", 1.6), ("prolate_c2.4", 0.5)):
            n = neck(v)
            out.append({"branch": b, "epsilon": eps, "kind": "point", "converged": "True", "reduced_volume": v,
                        "f": f_x + slope * (v - v_x), "neck_over_eps": n if b == "pear" else math.nan,
                        "shape": ("pear" if n >= P.NECK_EPS else "pinched") if b == "pear" else "prolate"})
    out.append({**out[0], "shape": "pinched", "f": 0.0, "neck_over_eps": math.nan})  # two bodies: never used
    return out


def test_summary_extrapolates_a_known_crossing_with_its_order():
    rows = [{"branch": "pear", "epsilon": 0.0, "kind": "crossing", "reduced_volume": 0.7476, "f": 0.1076,
             "n": "96", "converged": "True"}]
    for eps in (0.03, 0.02, 0.015):
        rows += _rows(eps, 0.746 + 4 * eps**2, 0.107 - 3 * eps**2)
    pinched = _rows(0.04, 0.76, 0.11, neck=lambda v: 1.5)  # at eps = 0.04 every pear's neck is under NECK_EPS eps
    # at eps = 0.05 the neck grows with v through NECK_EPS: pinched below v = 0.745, a pear at the crossing
    grows = _rows(0.05, 0.77, 0.12, neck=lambda v: 2.0 + 25 * (v - 0.705))
    out = P.summary(rows + pinched + grows)["pear_prolate_crossing"]
    assert "0.04" not in out["per_eps"] and out["narrow_neck"]["per_eps"]["0.04"]["v"] == pytest.approx(0.76, abs=1e-12)
    # the neck at the crossing, linear in v between the pear points: 2 + 25 (0.77 - 0.705) = 3.625
    assert out["per_eps"]["0.05"]["neck_over_eps"] == pytest.approx(3.625, abs=1e-12)
    assert out["per_eps"]["0.02"]["v"] == pytest.approx(0.746 + 4 * 0.02**2, abs=1e-12)  # lines: spline-exact
    assert out["extrapolated"]["epsilons"] == [0.05, 0.03, 0.02, 0.015]
    ext = out["extrapolated"]
    # crossings exactly v* + c eps^2 (the eps = 0.05 level off that line is not among the three finest):
    # Richardson recovers v*, f* and the order 2 to round-off
    assert ext["reduced_volume_richardson"] == pytest.approx(0.746, abs=1e-9)
    assert ext["reduced_energy_richardson"] == pytest.approx(0.107, abs=1e-9)
    assert ext["order_reduced_volume"] == pytest.approx(2.0, abs=1e-6)
    # the neck radius at the crossing, 4 eps here, extrapolates linearly to 0: order 1
    assert ext["neck_radius_richardson"] == pytest.approx(0.0, abs=1e-12)
    assert ext["order_neck_radius"] == pytest.approx(1.0, abs=1e-9)
    assert set(out["narrow_neck"]["per_eps"]) == {"0.05", "0.04", "0.03", "0.02", "0.015"}
    assert out["sharp"]["v"] == 0.7476 and out["published"] == {"v": 0.746, "f": 0.107}


def test_extrapolate_modes_recovers_an_algebraic_limit_and_bounds_its_error():
    ns = (24, 32, 48, 64, 96)
    exact = {n: {"v": 0.7483 - 2.0 * n**-2.5, "f": 0.1079 - 1.0 * n**-2.6, "neck_radius": 0.04 + 2 * n**-1.0}
             for n in ns}
    ext = P.extrapolate_modes({str(n): x for n, x in exact.items()})
    # y_inf + C N^-p exactly: the three-point fit is exact (brentq's root to ~1e-12 in p, measured)
    assert ext["v"] == pytest.approx(0.7483, abs=1e-10) and ext["order_v"] == pytest.approx(2.5, abs=1e-6)
    assert ext["f"] == pytest.approx(0.1079, abs=1e-10) and ext["neck_radius"] == pytest.approx(0.04, abs=1e-9)
    assert ext["error_v"] < 1e-9 and ext["n_modes"] == list(ns)  # dropping N = 96 refits the same law
    assert ext["correction_v"] == pytest.approx(2.0 * 96**-2.5, rel=1e-6)
    # a second term (N^-3.5, a tenth of the first at N = 24 .. a fortieth at 96): the estimate is off
    # (3.4e-7, measured) and the stated error (the shift when the largest N is dropped: 9.4e-7) exceeds it
    two = {n: {"v": 0.7483 - 2.0 * n**-2.5 + 5.0 * n**-3.5, "f": math.nan} for n in ns}
    e2 = P.extrapolate_modes(two)
    off = abs(e2["v"] - 0.7483)
    assert 0 < off < e2["error_v"], (off, e2["error_v"])
    assert math.isnan(e2["f"]) and math.isnan(P.extrapolate_modes({24: {"v": 1.0}, 32: {"v": 0.9}, 48: {"v": 0.8}})["error_v"])


def test_seed_from_carries_a_solutions_curve_to_a_finer_eps():
    """The eps-continuation's transfer on a sphere's tanh field: the new curve is the old phi = 0 line
    (the unit half circle to the P1 interpolant's accuracy), densified below the new spacing."""
    t = np.linspace(0.0, math.pi, 2049)
    r, z = np.sin(t), np.cos(t)
    eps = 0.06
    box, n, levels = P.box_of(r, z, eps)
    sc = P._scene(box, n, levels, eps, 1.0, "sphere")
    disc = discretize(sc, interface=refine.curve_distance(np.column_stack([r, z]), eps / P.EPS_OVER_H))
    phi = phase_field_of(r, z, disc.nodes, eps)
    import types
    rr, zz = P.seed_from(types.SimpleNamespace(disc=disc, phi=phi), 0.04)
    h = eps / P.EPS_OVER_H
    # the zero line of a P1 interpolant of tanh(d / sqrt2 eps): O(h^2) off the circle (measured 0.030 h on
    # these 17 k nodes); a tenth of a cell flags a curve taken off the wrong line or unscaled
    assert np.max(np.abs(np.hypot(rr, zz) - 1.0)) < 0.1 * h
    assert rr[0] <= 0 and rr[-1] <= 0 and abs(abs(zz[0] - zz[-1]) - 2.0) < 0.1 * h  # axis to axis (same bound)
    assert np.max(np.hypot(np.diff(rr), np.diff(zz))) <= 0.04 / P.EPS_OVER_H / 8 + 1e-12
    two = types.SimpleNamespace(disc=disc, phi=np.where(np.abs(disc.nodes[:, 1]) < 0.1, -1.0, phi))  # cut in two
    assert P.seed_from(two, 0.04) is None


def test_cases_put_the_sharp_case_and_the_longest_first():
    cs = P.cases()
    eps = sorted(P.FULL["epsilons"])
    assert cs[0]["epsilon"] == 0.0 and len({c["case"] for c in cs}) == len(cs)
    # the pear one case a v, each an eps-continuation through every coarser eps with a row at each step
    pears = [c for c in cs if c["branch"] == "pear" and c["epsilon"] > 0]
    assert cs[1:1 + len(pears)] == pears and [c["vs"] for c in pears] == [[v] for v in P.FULL["pear_vs"]]
    assert all(c["epsilon"] == eps[0] and c["chain"] == eps[:0:-1] and c["chain_rows"] for c in pears)
    assert [c["epsilon"] for c in cs[1 + len(pears):]] == eps  # the prolate's, finest first
    # without pear_per_v: one pear case an eps, its first point through every coarser eps (descending)
    cs = P.cases(cfg={**P.FULL, "pear_per_v": False})
    assert [c["epsilon"] for c in cs[1:3]] == [eps[0]] * 2 and {c["branch"] for c in cs} == set(P.BRANCHES)
    chains = {c["case"]: c.get("chain") for c in cs}
    assert chains["pear-eps0.015"] == [0.03, 0.02] and chains["pear-eps0.02"] == [0.03]
    assert chains["pear-eps0.01"] == [0.03, 0.02, 0.015, 0.0125]
    assert chains["pear-eps0.03"] is None and chains["prolate_c2.4-eps0.015"] is None
    assert all("chain" not in c for c in P.cases(cfg={**P.FULL, "pear_per_v": False, "chain": False}))


def test_phase_case_walks_from_its_first_point_and_records_the_chain(monkeypatch):
    """The walk's order and starts with the solves stubbed (each 'solution' records its v and its start):
    up from the lowest v, each warm from the last; a point that fails ends the walk; with
    ``chain_rows`` the continuation's steps come first as rows at their own eps."""
    import types

    calls = []

    def solve(sc, start):
        v = sc.v
        calls.append((v, getattr(start, "v", "seed")))
        ok = v not in fail
        return types.SimpleNamespace(v=v, converged=ok, extra={"f": v}, disc=types.SimpleNamespace(n_nodes=1),
                                     phi=None, kkt_residual=0.0, iterations=1, wall_time_s=0.0,
                                     outcome="converged" if ok else "failed")

    sharp = types.SimpleNamespace(converged=True, f=0.1, meridian=lambda m: (np.zeros(2), np.zeros(2)))
    monkeypatch.setattr(P, "sharp_branches", lambda vs, n, which: {which[0]: [sharp] * len(vs)})
    def first(case, which, v, r, z, keep=None):  # a chain step at eps 0.03 recorded where asked (chain_rows)
        if keep is not None:
            keep.append((0.03, solve(types.SimpleNamespace(v=v), "seed"), [2, 2], 1.0))
            calls.pop()
        return [[0, 1], [-1, 1]], [2, 2], 1, "seed", "s", ""

    monkeypatch.setattr(P, "_first", first)
    monkeypatch.setattr(P, "_solve_quiet", solve)
    monkeypatch.setattr(P, "_scene", lambda box, n, levels, eps, v, name: types.SimpleNamespace(v=v))
    monkeypatch.setattr(P, "meridian_curves", lambda disc, phi: [])
    monkeypatch.setattr(P, "form", lambda curves, eps: ("pear", 4.0, 0.1))
    case = {"case": "pear-eps0.02", "branch": "pear", "epsilon": 0.02, "vs": [0.74, 0.75, 0.76, 0.77],
            "n_modes": 24}
    fail = set()
    rows = P.phase_case(case)
    assert calls == [(0.74, "seed"), (0.75, 0.74), (0.76, 0.75), (0.77, 0.76)]
    assert [r["walk"] for r in rows] == ["up"] * 4
    calls.clear()
    fail = {0.76}
    assert len(P.phase_case(case)) == 3 and calls == [(0.74, "seed"), (0.75, 0.74), (0.76, 0.75)]
    calls.clear()
    fail = set()
    rows = P.phase_case({**case, "vs": [0.75], "chain_rows": True})  # a per-v case: the chain's step, then the point
    assert [(r["epsilon"], r["target_v"]) for r in rows] == [(0.03, 0.75), (0.02, 0.75)]
    assert rows[0]["seed"].startswith("eps-continuation step") and rows[0]["converged"]
