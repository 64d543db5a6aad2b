"""Solves on the meridian half-plane (``mesh.axisymmetric``): certified on both backends with the same
point and the same least eigenvalue (two independent second-order checks), the verdict's class, the
files (meridian curve, revolved surface), and the literature units pinned by the sphere; the sphere's
eps -> 0 limit and the agreement with a 3D grid are slow."""

import csv
import json
import math

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt import cli
from vesicle_opt.result import Status
from vesicle_opt.scene import schema
from vesicle_opt.verify.verdict import AXISYMMETRIC_CLASS

# the bundled prolate at eps = 0.1, h = eps, its walls 16 eps from the shape: nearer natural walls
# attract a vesicle (the tanh tails meet their mirror images, ~exp(-sqrt2 d / eps)), and the
# translation along the axis becomes a saddle direction of the discrete problem (measured -9.7e-4
# mu_ref at 10 eps, both checks)
COARSE = ["model.epsilon=0.1", "mesh.n=[24, 68]", "domain.box=[[0, 2.4], [-3.4, 3.4]]"]


def test_prolate_certified_on_both_backends_and_written(tmp_path):
    out = tmp_path / "out"
    sets = [a for s in COARSE for a in ("--set", s)]
    assert cli.main(["solve", "prolate-axisymmetric", *sets, "--out", str(out), "-q"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["converged"]
    assert s["second_order"] == "minimum" and s["second_order_excluded"] == AXISYMMETRIC_CLASS
    assert s["reduced_volume"] == pytest.approx(0.8, abs=1e-8)  # the 3D target, to tol
    assert s["area"] == pytest.approx(4 * math.pi, rel=1e-8)
    assert s["f"] == s["reduced_energy"] and s["c0_reduced"] == 0.0  # f = F / 8 pi kappa (geometry)
    with open(out / "meridian.csv") as fh:
        rows = list(csv.DictReader(fh))
    r = np.array([float(x["r"]) for x in rows])
    assert {x["curve"] for x in rows} == {"0"} and r[0] == 0.0 and r[-1] == 0.0  # one curve, pole to pole
    assert (out / "surface.ply").is_file() and s["surface_closed"]
    # the revolved zero level set against the phase-field values: O(eps^2) apart, the volume by
    # (pi^2/12) eps^2 int kappa dA (``io.surface``'s docstring); measured +1.2%, -3.6% at eps = 0.1
    assert abs(s["surface_area_rel_diff"]) < 0.02 and abs(s["surface_volume_rel_diff"]) < 0.05
    nk = vo.solve(vo.load_scene("prolate-axisymmetric", COARSE), backend="newton-krylov")
    assert nk.converged and nk.extra["second_order_excluded"] == AXISYMMETRIC_CLASS
    # the same discrete problem: energies to the solvers' tolerance (measured 1.3e-11 relative)
    assert nk.energy == pytest.approx(s["energy"], rel=1e-8)
    # assembled shift-invert Lanczos (IPOPT) against matrix-free LOBPCG (NK): measured 1.5e-7 apart
    assert nk.extra["second_order_min_eigenvalue"] == pytest.approx(s["second_order_min_eigenvalue"], rel=1e-4)


def _sphere(eps, n, c0, half=2.2):
    raw = {"domain": {"box": [[0.0, half], [-half, half]], "boundary": "natural"},
           "mesh": {"kind": "axisymmetric", "n": [n, 2 * n]}, "model": {"epsilon": eps, "c0": c0},
           "constraints": {"target": {"shape": "sphere", "radius": 1.0}},
           "initial": {"shape": "sphere", "radius": 1.0}, "solver": {"method": "exact", "second_order": False}}
    res = vo.solve(schema.from_dict(raw))
    assert res.converged, res.reason
    return res.extra["f"], res.extra["c0_reduced"]


@pytest.mark.filterwarnings("ignore:beta")  # the sphere is at the isoperimetric bound: warned, not refused
def test_sphere_pins_the_sign_of_c0():
    """f of the sphere at c0 = +0.25 (scene units, C0 = 2 c0, c0_reduced ~ 0.5) is (1 - c0_reduced/2)^2
    = 0.561, not (1 + c0_reduced/2)^2 = 1.56: C0 = +sqrt(2) C with phi = +1 inside (``geometry``).
    Richardson in h (h = eps/2, eps/4; the P1 error is O(h^2)) at eps = 0.1."""
    (f1, c1), (f2, c2) = _sphere(0.1, 44, 0.25), _sphere(0.1, 88, 0.25)
    f, c = (4 * f2 - f1) / 3, (4 * c2 - c1) / 3
    assert c == pytest.approx(0.5, rel=5e-3)  # 2 c0 R0 with R0 the phase-field sphere's (measured 0.5016)
    # measured 0.5617 against 0.5613 at eps = 0.1 (the eps -> 0 limit: test_sphere_limit below)
    assert f == pytest.approx((1 - c / 2) ** 2, abs=2e-3)


@pytest.mark.slow  # ~45 s: six sphere solves up to 33 k nodes
@pytest.mark.filterwarnings("ignore:beta")
def test_sphere_limit_in_eps():
    """The sphere's eps -> 0 limit E -> (2 sqrt2/3) 8 pi (1 - c0_reduced/2)^2, i.e. f -> (1 - c0/2)^2 in
    literature units, at c0 = 0.25 (c0_reduced ~ 0.5): f Richardson-extrapolated in h (h = eps/3,
    eps/6) at eps = 0.2, 0.2/sqrt2, 0.1 with walls 12 eps from the sphere; the gap to the limit fitted
    in eps. Measured gaps 1.74e-3, 8.3e-4, 4.0e-4 (and 2.0e-4, 1.0e-4 at 0.1/sqrt2, 0.05): order 2.05."""
    gaps, epss = [], []
    for eps in (0.2, 0.2 / math.sqrt(2), 0.1):
        half = 1 + 12 * eps
        n = round(3 * half / eps)
        (f1, c1), (f2, c2) = _sphere(eps, n, 0.25, half), _sphere(eps, 2 * n, 0.25, half)
        f, c = (4 * f2 - f1) / 3, (4 * c2 - c1) / 3
        gaps.append(f - (1 - c / 2) ** 2)
        epss.append(eps)
    order = np.polyfit(np.log(epss), np.log(np.abs(gaps)), 1)[0]
    assert 1.7 < order < 2.3, (order, gaps)  # O(eps^2), measured 2.07 on these three
    assert abs(gaps[-1]) < 1e-3, gaps  # measured 4.0e-4 at eps = 0.1


@pytest.mark.slow  # ~20 s: a 32 k-node mirror-grid solve and three meridian solves
@pytest.mark.filterwarnings("ignore:beta")
def test_vesicle_agrees_with_the_3d_mirror_grid():
    """The vesicle of v = 0.8, R0 = 1 at eps = 0.2 (round at this eps: the wide interface holds the
    excess area, and prolate and oblate starts reach the same state on both discretisations, measured)
    from a prolate start on the meridian (Newton-Krylov) against the 3D mirror
    grid (``mesh.cosine``, spectral: its 14^3-ish and 28^3-ish levels agree to 6e-4): the gap shrinks at
    order 2 in the meridian's h (measured 0.742, 0.179, 0.044 of E = 32.339). The two domains have the
    same |Omega| (the cylinder r <= 3.1, |z| <= 4 and the cube [-a, a]^2 x [-4, 4], 4 a^2 = pi 3.1^2):
    the bulk field sits at -1 + O(lambda_A eps^3), and that shift times |Omega| is part of the volume
    constraint, so at eps = 0.2 unequal domains give other vesicles (measured 5% apart in E). That
    state is the discrete problem's, not the vesicle of v = 0.8 (``verify.shape``: the bulk carries
    42 % of V, the phi = 0 surface is round only with it): with the shape check on, both
    discretisations refuse it as ``wrong_shape`` (the meridian's phi = 0 surface measured by
    ``verify.shape_meridian``: the same reduced volumes and volume gap as the grid's marching cubes),
    and both measure the same bulk share."""
    eps, R, Z = 0.2, 3.1, 4.0
    a = R * math.sqrt(math.pi) / 2

    def solve(box, mesh, center=None, backend=None, verdict="wrong_shape"):
        start = {"shape": "ellipsoid", "semi_axes": [0.75, 0.75, 1.5], **({"center": center} if center else {})}
        raw = {"domain": {"box": box, "boundary": "natural"}, "mesh": mesh, "model": {"epsilon": eps},
               "constraints": {"reduced_volume": 0.8, "area": 4 * math.pi}, "initial": start,
               "solver": {"method": "exact", "second_order": False}}
        res = vo.solve(schema.from_dict(raw), backend=backend)
        assert res.extra["shape"] == verdict, (res.extra["shape"], res.extra.get("shape_reason"))
        # wrong_shape: a KKT point refused by the shape check alone (not converged, the point kept)
        if verdict == "wrong_shape":
            assert res.outcome == Status.WRONG_SHAPE and not res.converged, res.reason
        else:
            assert res.converged, res.reason
        return res

    grid = solve([[0, a], [0, a], [0, Z]], {"kind": "spectral", "n": [28, 28, 41]}, center=[0.0, 0.0, 0.0])
    assert grid.extra["shape"] == "wrong_shape"  # measured: surface 0.999, 0.645 without the bulk's volume
    ref, shares = grid.energy, []
    gaps, hs, meridian = [], [], []
    # at n = 16 (h = eps, below the recommended eps / h = 2: the scene warns) the discrete state is
    # itself less round (its phi = 0 surface's reduced volume 0.966 < ROUND, E 2.3 % low): a warning
    for n, verdict in ((16, "bulk_offset"), (31, "wrong_shape"), (62, "wrong_shape")):
        res = solve([[0, R], [-Z, Z]], {"kind": "axisymmetric", "n": [n, round(2 * n * Z / R)]},
                    backend="newton-krylov", verdict=verdict)
        gaps.append(abs(res.energy - ref))
        shares.append(res.extra["bulk_volume_share"])
        hs.append(R / n)
        meridian.append(res)
    fine = meridian[-1].extra
    # the meridian's surface against the grid's marching cubes (measured 0.4248 / 0.4166, 0.99986 /
    # 0.99874, 0.6407 / 0.6445): 1 %, the grid's own O(h^2) (its bulk-free gaps reach 1.1e-2)
    for key in ("shape_volume_gap", "zero_level_reduced_volume", "zero_level_reduced_volume_without_bulk"):
        assert abs(fine[key] - grid.extra[key]) < 0.012, (key, fine[key], grid.extra[key])
    d = [abs(sh - grid.extra["bulk_volume_share"]) for sh in shares]  # the grid's 0.4225 of V
    assert d[2] < d[1] < d[0] and d[2] < 0.01, d  # converging in h (measured 1.1e-2, 5.0e-3, 1.3e-3)
    order = np.polyfit(np.log(hs), np.log(gaps), 1)[0]
    assert 1.7 < order < 2.4, (order, gaps)  # P1: order 2 (measured 2.05)
    assert gaps[-1] < 2e-3 * ref, gaps  # measured 1.4e-3 relative at h = eps / 4


def test_penalty_gap_is_order_one_over_M():
    """Theorem 3.2 through its penalty form (11) on the meridian: |E_M - E| ~ 1/M (the constraint
    residuals ~ lambda/M), warm-started from the exact point. Measured gaps 8.4e-2, 8.6e-3, 8.6e-4 at
    M = 1e3, 1e4, 1e5: slope -0.994."""
    exact = vo.solve(vo.load_scene("prolate-axisymmetric", COARSE + ["solver.second_order=false"]))
    Ms, gaps = [1e3, 1e4, 1e5], []
    for M in Ms:
        res = vo.solve(vo.load_scene("prolate-axisymmetric", COARSE + ["solver.method='penalty'", f"solver.M={M}"]),
                       x0=exact.phi)
        assert res.converged, res.reason
        gaps.append(abs(res.energy - exact.energy))
    slope = np.polyfit(np.log(Ms), np.log(gaps), 1)[0]
    assert -1.1 < slope < -0.9, (slope, gaps)  # O(1/M): measured -0.994
