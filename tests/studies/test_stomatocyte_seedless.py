"""The seedless stomatocyte's pieces (``studies._stomatocyte``, ``studies._same_state``): the detour's box
(n_z even: a mesh mirrored about its mid-height), the field distance of two meridian states, and (slow)
the detour reaching a cup from the oblate without a stomatocyte seed."""

import math

import numpy as np
import pytest

from vesicle_opt.io.meridian import phase_field_of
from vesicle_opt.mesh import discretize
from vesicle_opt.mesh.band_start import axial_centre
from vesicle_opt.mesh.refine import curve_distance
from vesicle_opt.studies import _same_state as same
from vesicle_opt.studies import _stomatocyte as S
from vesicle_opt.studies._meridian import layout, scene


def _ellipse(a, b, z0=0.0, n=2048):
    t = np.linspace(-math.pi / 2, math.pi / 2, n)
    return a * np.cos(t), z0 + b * np.sin(t)


def _reflected_mesh_matches(disc, mid) -> bool:
    """The triangles (as sets of vertex coordinates) reflected about z = mid are the mesh's own."""
    p = disc.mesh.p.T
    q = np.column_stack([p[:, 0], 2 * mid - p[:, 1]])

    def tris(x):
        x = np.round(x, 9)
        return {frozenset(map(tuple, x[t])) for t in disc.mesh.t.T}
    return tris(p) == tris(q)


def _odd(lay: dict) -> dict:
    """The layout with one coarse cell fewer along z (half a cell off each end: the same mid-height):
    n_z odd where ``layout``'s is even (what ``layout`` made before it rounded n_z up)."""
    h0 = lay["h"] * 2 ** lay["mesh"]["levels"]
    (z_lo, z_hi), n = lay["box"][1], [lay["n"][0], lay["n"][1] - 1]
    return {**lay, "box": [list(lay["box"][0]), [z_lo + h0 / 2, z_hi - h0 / 2]], "n": n, "mesh": {**lay["mesh"], "n": n}}


def test_layout_makes_the_band_mesh_mirrored_about_mid_height():
    """An up-down symmetric interface (an ellipse centred at z = 0): on ``layout``'s box (n_z even) the
    band mesh is mirrored triangle for triangle (an independent test: the reflected triangles); on the
    same box less one coarse row (n_z odd) it is not (the middle row's diagonals)."""
    eps = 0.1
    r, z = _ellipse(1.0, 0.62)
    for half in np.arange(0.6, 1.2, 0.05):  # box heights whose n_z was odd before layout rounded it up
        lay = layout([(r, z), (np.zeros(2), np.array([-half, half]))], eps, 2.0, True)
        assert lay["n"][1] % 2 == 0 and lay["mesh"]["n"] == lay["n"]
    ev, odd = lay, _odd(lay)
    (lo, hi), (lo2, hi2) = odd["box"][1], ev["box"][1]
    assert (lo2 + hi2) / 2 == pytest.approx((lo + hi) / 2, abs=1e-12)  # round-off of a sum of box bounds
    for lay, mirrored in ((odd, False), (ev, True)):
        sc = scene(lay, eps, 0.62, "even-layout")
        disc = discretize(sc, interface=curve_distance(np.column_stack([r, z]), lay["h"]))
        assert _reflected_mesh_matches(disc, sum(lay["box"][1]) / 2) is mirrored


def test_tall_layout_holds_the_cup_about_the_oblates_centre():
    """The detour's box reaches ``TALL`` oblate radii (plus the walls' 12 eps) above and below z = 0,
    with n_z even."""
    r, z = _ellipse(1.24, 0.34)
    lay = S.tall_layout((r, z), 0.03, 4.0, True)
    lo, hi = lay["box"][1]
    assert lay["n"][1] % 2 == 0 and (lo + hi) / 2 == pytest.approx(0.0, abs=1e-12)  # round-off
    assert hi >= S.TALL * 1.24 + 12 * 0.03 and lo <= -(S.TALL * 1.24 + 12 * 0.03)


def _sphere_disc(radius, z0, box_z, eps, h):
    lay = layout([(np.array([0.0, 1.0]), np.array(box_z))], eps, eps / h, False)
    disc = discretize(scene(lay, eps, 1.0, "sphere"))
    r, z = _ellipse(radius, radius, z0, 1024)
    return disc, phase_field_of(r, z, disc.nodes, eps)


def test_field_distance_of_nested_spheres_is_their_volume_ratio():
    """Spheres of radius R1 and R2 (tanh profiles): |phi_1 - phi_2| integrates to twice the shell's
    volume and 1 + phi_1 to twice the inner ball's, so the distance is (R2/R1)^3 - 1 up to O(eps^2/R^2)
    profile terms (fitted: order 2 in eps at eps/h = 2); the same sphere in another box, centred
    elsewhere by a shift that is no multiple of h (the meshes not nested, the centroids moved onto
    each other): O(h^2), far below."""
    want = (0.55 / 0.5) ** 3 - 1
    dev, same_state = [], []
    for eps in (0.04, 0.02):
        a = _sphere_disc(0.5, 0.0, [-0.8, 0.8], eps, eps / 2)
        b = _sphere_disc(0.55, 0.13, [-0.7, 0.97], eps, eps / 2)
        c = _sphere_disc(0.5, -0.2137, [-0.9337, 0.6863], eps, eps / 2)
        assert axial_centre(*b) == pytest.approx(0.13, abs=1e-5)  # a sphere's centroid: its centre (measured 2e-7)
        dev.append(same.field_distance(*a, *b) / want - 1)
        same_state.append(same.field_distance(*a, *c))
    order = math.log2(dev[0] / dev[1])
    assert order == pytest.approx(2.0, abs=0.2)  # the profile's eps^2 term (measured -0.0216, -0.0055)
    assert abs(dev[1]) < 0.01  # eps^2 / R^2 = 1.6e-3 times the measured factor 3.4
    assert max(same_state) < 0.01 * want  # the same state: two orders below another one


@pytest.mark.slow
def test_tall_box_oblate_cold_start_is_certified_with_even_coarse_rows():
    """The detour's first solve (the oblate at eps 0.03, v 0.62, c0 0, from its sharp shape) on the tall
    box: with n_z odd (19 coarse rows) the mesh is not mirrored and the axial pin holds a force, so
    the solve is refused (kkt_not_met, the pin's force what fails: ``pin_held``); with n_z even
    (``layout``'s) it is certified, the pin's multiplier at round-off (a symmetric state on a
    mirrored mesh is exactly stationary along the slide), and f is that of the same oblate on the
    box about the oblate alone to the difference of two meshes' P1 errors."""
    from vesicle_opt.sharp import axisymmetric as sharp_a
    from vesicle_opt.studies._meridian import seed, solve_quiet

    eps, v = 0.03, 0.62
    mer = sharp_a.solve(v, "oblate", S.OBLATE_MODES, second_order=False).meridian(2048)
    half = 0.6 * float(mer[0].max())
    even = layout([mer, (np.zeros(2), np.array([-half, half]))], eps, 4.0, True)
    odd = _odd(even)
    assert odd["n"][1] % 2 == 1  # 19 coarse rows (measured: the box before layout rounded n_z up)
    res = {}
    for key, lay in (("odd", odd), ("even", even), ("own", layout([mer], eps, 4.0))):
        sc = scene(lay, eps, v, f"tall-{key}")
        res[key] = solve_quiet(sc, seed(sc, *mer, eps, lay["h"]))
    assert res["odd"].outcome == "kkt_not_met" and res["odd"].extra["pin_held"]
    assert res["even"].converged and res["own"].converged
    assert abs(res["even"].extra["translation_multiplier"]) < 1e-9  # measured 4e-12 (IPOPT's tol 1e-6 scaled rows)
    assert res["even"].extra["second_order_min_eigenvalue"] > 0  # a minimum (measured +0.0112 mu_ref)
    # the walls 12 eps away in both (e^-12 tails), but two band meshes from other coarse grids: their P1 errors
    # differ (measured 3.4e-5 relative here, 1.7e-5 against the detour's taller box)
    assert res["even"].extra["f"] == pytest.approx(res["own"].extra["f"], rel=1e-4)


@pytest.mark.slow
def test_switched_branch_leaves_the_oblate_subcritically_as_an_asymmetric_saddle():
    """``_stomatocyte.switched`` at eps 0.03, v 0.62 with a short budget: the secant's branch point
    is where the oblate's least eigenvalue vanishes (the bracket's values 5e-4 and -2e-4 mu_ref,
    the located point's two orders below), at the c0 the branch package located on another mesh
    (-0.8327, ``oblate-axisymmetric``) to the secant's error; the branch followed from it goes up
    in c0 (subcritical: where the oblate is still a minimum), one meridian curve, up-down
    asymmetric (docs/guide/bifurcation.md, "A continuous switch": up to c0 -0.39 in ~220 points)."""
    from vesicle_opt.verify import updown

    out = S.switched(0.62, 0.03, budget_s=120.0)
    (_, ra), (_, rb) = out.oblate[-2:]
    bracket = min(abs(ra.extra["second_order_min_eigenvalue"]), abs(rb.extra["second_order_min_eigenvalue"]))
    assert abs(out.bp.extra["second_order_min_eigenvalue"]) < bracket / 20  # measured 2e-6 against 2.3e-4
    assert out.c_star == pytest.approx(-0.8327, abs=0.005)  # the bracket's curvature: measured -0.8338
    f = out.followed
    assert f.end is None and f.stopped.startswith("CPU budget")
    assert 2 * max(f.ps) > out.c_star + 0.05  # the branch rises 0.44 to its fold (c0 -0.390); 0.05 is ~20 points
    last = updown.describe(out.corrector.disc, f.points[-1].phi)
    assert last["form"] in ("cup", "oblate") and last["updown_asymmetry"] > 100 * updown.SYMMETRIC


@pytest.mark.slow
def test_switched_at_v066_reaches_the_seeded_cup():
    """The seedless route (docs/guide/bifurcation.md, "A continuous switch"): at v = V_SWITCH the branch
    out of the oblate's odd branch point passes c0 = 0; its landing, walked down in v at c0 = 0 by
    the minimiser (``down_in_v``), is at v 0.62 the seeded cup, or its mirror image about the box's
    mid-height (the switch's sign picks which pole invaginates; the mesh is mirror symmetric), at the
    axial position it slid to. The axial slide between the natural walls is near-null: IPOPT leaves a
    start where it is along it (seeds moved by 0.0075, 0.018, 0.036 stayed there to 1.5e-4), and f
    varies along it by up to 7.5e-8 relative (1.9459230654, ...32019, ...31264, ...31974 at those
    positions, measured), so the seeded cup is solved from the seed moved to the landing's position.
    Checked: a certified minimum, f and the least eigenvalue equal to the seeded cup's there, and the
    field distance three orders below the torus's (measured: the landing 0.0356 up the axis, same
    orientation; f 1.1e-9 apart; distance 4.6e-5 against 0.15 mirrored; 751 s at load 2)."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation

    from vesicle_opt.branch.params import parameter
    from vesicle_opt.sharp import stomatocyte as sharp_s
    from vesicle_opt.studies._meridian import centroid

    out = S.switched(S.V_SWITCH, 0.03, c0s=(0.0, -0.5, -1.0, -1.25, -1.5))
    assert out.followed.end is not None and out.followed.end.converged
    corr = out.corrector
    disc, sc = corr.disc, corr.scene
    walk = S.down_in_v(corr, sc, out.followed.end.phi, (0.65, 0.64, 0.63, 0.62))
    v, cup = walk[-1]
    assert v == 0.62 and cup.converged and cup.extra["second_order"] == "minimum"
    s62 = parameter(sc, "reduced_volume").scene_at(sc, 0.62)
    r, z = sharp_s.start_point(0.62, 0.0, 24).meridian(2048)
    mid = sum(out.lay["box"][1]) / 2
    tri = Triangulation(disc.mesh.p[0], disc.mesh.p[1], disc.mesh.t.T)
    flip = np.ma.filled(LinearTriInterpolator(tri, cup.phi)(disc.nodes[:, 0], 2 * mid - disc.nodes[:, 1]), -1.0)
    z0 = np.asarray(z) + (mid - centroid(r, z))  # the sharp cup's centroid at mid-height (as ``seed``)
    at_mid = phase_field_of(r, z0, disc.nodes, 0.03)
    # the landing's orientation (the seed's or mirrored), then its position along the axis
    target = min((cup.phi, flip), key=lambda f: same.field_distance(disc, at_mid, disc, f))
    shift = axial_centre(disc, target) - axial_centre(disc, at_mid)
    seeded = corr.solve(s62, phase_field_of(r, z0 + shift, disc.nodes, 0.03), None)
    assert seeded.converged and seeded.extra["second_order"] == "minimum"
    # both where they started on the slide, to a hundredth of a cell (measured 1.5e-4 = h / 100)
    assert abs(axial_centre(disc, seeded.phi) - axial_centre(disc, target)) < 0.02 * out.lay["h"]
    # f varies along the slide by 7.5e-8 relative over 0.036 (docstring); the two sit <= 3e-4 apart on it
    assert cup.extra["f"] == pytest.approx(seeded.extra["f"], rel=1e-8)
    mu = seeded.extra["second_order_min_eigenvalue"]
    assert cup.extra["second_order_min_eigenvalue"] == pytest.approx(mu, rel=1e-3)  # the check's own error
    d_same = same.field_distance(disc, seeded.phi, disc, target)
    assert d_same < 1e-3 * 0.0767  # three orders below the torus's distance from the cup (module docstring)
