"""The phi = 0 surface of revolution on meridian meshes (``verify.shape_meridian``) against closed forms:
a sphere's tanh profile (volume gap 0 to O(h^2): the O(eps^4) term of a sphere vanishes), spheroids'
volume 4/3 pi a^2 c, area and total curvature, a torus (2 pi^2 R r^2, 4 pi^2 R r, 4 pi^2 R), a
spherical shell (the cavity counts negative), the 3D grids' Steiner sum on the revolved triangulation,
and the verdicts through ``verify.shape``."""

import math

import numpy as np
import pytest

from vesicle_opt.io import meridian
from vesicle_opt.mesh import axisymmetric
from vesicle_opt.verify import shape, shape_meridian

LEVELS = (20, 40, 80)  # cells along r of the box [0, 3] x [-3, 3]: h = 0.15, 0.075, 0.0375


def _disc(n):
    return axisymmetric.p1([[0.0, 3.0], [-3.0, 3.0]], [n, 2 * n])


def _tanh(d, eps):
    return np.tanh(d / (math.sqrt(2) * eps))


def _order(hs, errs):
    return np.polyfit(np.log(hs), np.log(np.abs(errs)), 1)[0]


def _spheroid(a, c):
    """(volume, area, int (kappa_1 + kappa_2) dA) of the spheroid of semi-axes a (equator), c (axis):
    int kappa_2 dA = 2 pi int n_r ds = 4 pi c, int kappa_1 dA = 2 pi int r dpsi (checked by quadrature)."""
    if c > a:
        k = math.sqrt(c * c - a * a)
        e = k / c
        S = 2 * math.pi * a * a * (1 + c / (a * e) * math.asin(e))
        M = 4 * math.pi * c + 2 * math.pi * a * a * math.log((c + k) / (c - k)) / k
    else:
        k = math.sqrt(a * a - c * c)
        e = k / a
        S = 2 * math.pi * a * a + math.pi * c * c / e * math.log((1 + e) / (1 - e))
        M = 4 * math.pi * c + 4 * math.pi * a * a * math.atan(k / c) / k
    return 4 / 3 * math.pi * a * a * c, S, M


def test_sphere_tanh_profile_gap_vanishes_at_order_two():
    """For phi = tanh((R - rho) / (sqrt2 eps)), V - V_0 = 2 pi int (R + s)^2 H(s) ds with H odd about
    the interface: only the s term is left, (pi^2 / 12) eps^2 8 pi R, exactly (no O(eps^4) term; the
    box and the axis cut the tails at exp(-sqrt2 2 / eps)). So the gap is the mesh's alone: the zero
    level's O(h^2) and the lumped quadrature of A. Measured gap -9.4e-3, -2.3e-3, -6.1e-4."""
    eps, R = 0.2, 1.0
    hs, gaps, errs = [], [], []
    for n in LEVELS:
        disc = _disc(n)
        r, z = disc.nodes.T
        phi = _tanh(R - np.hypot(r, z), eps)
        A = float(disc.weights @ phi)
        check = shape.measure(disc, phi, eps, A, 1.0)
        hs.append(disc.h)
        gaps.append(check.volume_gap)
        errs.append([check.zero_volume - 4 / 3 * math.pi, check.zero_area - 4 * math.pi,
                     check.curvature_integral - 8 * math.pi])
        assert shape.judge(check) == ("ok", None)
    assert 1.8 < _order(hs, gaps) < 2.2, gaps  # O(h^2): measured 2.0
    assert abs(gaps[-1]) < 1e-3, gaps  # measured 6.1e-4 at h = eps / 5
    # V_0, S_0, int kappa: errors 1.5e-3, 2.3e-3, 1.6e-3 at the finest; fitted orders 1.99, 1.86, 1.68
    # (the curvature's turning angles are pre-asymptotic: 1.54 then 1.83 per halving, towards 2)
    for k, low in enumerate((1.8, 1.7, 1.5)):
        assert low < _order(hs, [e[k] for e in errs]) < 2.3, errs


@pytest.mark.parametrize("a, c", [(0.8, 1.4), (1.2, 0.6)])  # prolate, oblate
def test_spheroid_volume_area_curvature(a, c):
    """The zero level of f = 1 - sqrt(r^2/a^2 + z^2/c^2) (the level set, not its profile, is measured:
    a tanh of f has the same, only its P1 interpolant is rougher where h > eps) is the spheroid: its
    volume of revolution, area and total curvature converge to the closed forms at order 2."""
    exact = np.array(_spheroid(a, c))
    hs, errs = [], []
    for n in LEVELS:
        disc = _disc(n)
        r, z = disc.nodes.T
        hs.append(disc.h)
        errs.append(np.array(shape_meridian.zero_level(disc, 1 - np.hypot(r / a, z / c))) - exact)
    for k in range(3):
        assert 1.8 < _order(hs, [e[k] for e in errs]) < 2.2, errs  # the P1 zero level: O(h^2), measured 1.98-2.01
    assert np.all(np.abs(errs[-1]) / exact < 1e-3), errs  # measured 7e-5 to 7e-4 relative at h = 0.053


def test_torus_and_shell():
    """A torus (tube radius r_t = 0.7 about the circle R_t = 1.37, centred off the mesh's nodes): one
    closed meridian curve off the axis; volume 2 pi^2 R r^2, area 4 pi^2 R r, total curvature 4 pi^2 R
    (the azimuthal part 2 pi int n_r ds is 0; the ring part 2 pi sum r_i theta_i is 2 pi x the polygon's
    Steiner point, the tube's centre). Its tanh profile's gap is 0 up to O(h^2) as the sphere's (the
    cos t of r = R + rho cos t integrates to 0) and the tails cut at rho = 0 (exp(-sqrt2 r_t / eps),
    ~5e-4 of V at eps = 0.2). A shell 0.5 < rho < 1: two curves from the axis to the axis, the inner
    one reversed: V = 4/3 pi (1 - 1/8), S = 4 pi (1 + 1/4), int kappa = 8 pi (1 - 1/2)."""
    eps, Rt, rt = 0.2, 1.37, 0.7
    exact = np.array([2 * math.pi**2 * Rt * rt**2, 4 * math.pi**2 * Rt * rt, 4 * math.pi**2 * Rt])
    shell = np.array([4 / 3 * math.pi * (1 - 0.125), 4 * math.pi * 1.25, 8 * math.pi * 0.5])
    hs, errs, gaps, shell_errs = [], [], [], []
    for n in LEVELS:
        disc = _disc(n)
        r, z = disc.nodes.T
        phi = _tanh(rt - np.hypot(r - Rt, z - 0.1), eps)
        check = shape.measure(disc, phi, eps, float(disc.weights @ phi), 1.0)
        assert len(meridian.meridian_curves(disc, phi)) == 1
        hs.append(disc.h)
        errs.append(np.array([check.zero_volume, check.zero_area, check.curvature_integral]) - exact)
        gaps.append(check.volume_gap)
        rho = np.hypot(r, z)
        shell_errs.append(np.array(shape_meridian.zero_level(disc, np.minimum(1 - rho, rho - 0.5))) - shell)
    for k in range(2):
        assert 1.8 < _order(hs, [e[k] for e in errs]) < 2.3, errs  # O(h^2): measured 2.06, 1.99
    assert abs(errs[-1][2]) < 1e-4 * exact[2], errs  # measured 7e-7 relative (order 4 here)
    for k in range(3):
        assert 1.8 < _order(hs, [e[k] for e in shell_errs]) < 2.2, shell_errs  # measured 2.05, 2.00, 2.03
    assert abs(gaps[0]) > abs(gaps[1]) > abs(gaps[2]) and abs(gaps[2]) < 1.5e-3, gaps  # -6.6e-3, -9.9e-4, 3.3e-4


def test_curvature_matches_the_grids_steiner_sum():
    """The frustum/ring sum equals ``verify.shape``'s Steiner sum sum_e |e| theta_e of the 3D grids on
    the revolved triangulation (``io.meridian.revolve``) in the limit of many angles: the revolved
    polygon's O(1/n_theta^2)."""
    disc = _disc(40)
    r, z = disc.nodes.T
    phi = 1 - np.hypot(r / 0.8, z / 1.4)
    curves = meridian.meridian_curves(disc, phi)
    _, _, M = shape_meridian.zero_level(disc, phi)
    diffs = []
    for n_theta in (32, 64, 128):
        surf = meridian.revolve(curves, n_theta)
        diffs.append(shape._total_curvature(surf.vertices, surf.faces) - M)
    assert 1.9 < _order([1 / 32, 1 / 64, 1 / 128], diffs) < 2.1, diffs  # O(1/n_theta^2): measured 2.00
    assert abs(diffs[-1]) < 1e-4 * M, diffs  # measured 4.5e-5 relative at 128 angles


def test_bulk_carried_sphere_is_wrong_shape_and_open_curves_are_not_measured():
    """A sphere profile whose outer bulk sits at -1 - delta (phi = (1 + delta) t where t < 0): the gap
    measured from the phi = 0 surface equals the bulk's share measured from the weights less the
    ramp of the offset through the outer tail, delta int_out (1 + t) / 2 / V (two routes); the
    surface is round only with that volume: ``wrong_shape`` as on the 3D grids. A slab |z| < 0.5
    reaches the wall r = R: no closed surface, no gap (the verdict falls back to the bulk share)."""
    eps, delta = 0.2, 0.012
    disc = _disc(60)
    r, z = disc.nodes.T
    w = disc.weights
    t = _tanh(1 - np.hypot(r, z), eps)
    assert np.any(t == 0)  # nodes on rho = 1 (h = 0.05): the curve passes through phi = 0 nodes
    phi = np.where(t < 0, (1 + delta) * t, t)
    check = shape.measure(disc, phi, eps, float(w @ phi), 1.0)
    ramp = delta * float(w[t < 0] @ (1 + t[t < 0])) / 2 / check.phase_field_volume
    assert check.bulk_volume_share > 0.2  # measured 0.245
    # the bulk-free sphere's own O(h^2) gap at this mesh (-1.1e-3) and the P1 crossings moved by
    # O(delta h): measured -1.7e-3
    assert abs(check.volume_gap - (check.bulk_volume_share - ramp)) < 3e-3, (check, ramp)
    verdict, line = shape.judge(check)
    assert verdict == "wrong_shape" and check.zero_reduced_volume > shape.ROUND, (check, line)  # 0.99986
    slab = _tanh(0.5 - np.abs(z), eps)
    assert shape_meridian.zero_level(disc, slab) is None
    assert shape.measure(disc, slab, eps, float(w @ slab), 1.0).volume_gap is None


def test_interface_refined_mesh():
    """``mesh.refine = "interface"`` (graded, mirrored diagonals): the sphere's gap is 0 to O(h_fine^2)
    as on the uniform mesh, the coarse cells away from the curve do not enter. Measured -1.2e-2,
    -3.1e-3, -8.1e-4 at h_fine = 0.15, 0.075, 0.0375 (1, 2, 3 halvings of 0.3 in a band of 5 eps)."""
    eps, hs, gaps = 0.2, [], []
    for levels in (1, 2, 3):
        disc = axisymmetric.band_p1([[0.0, 3.0], [-3.0, 3.0]], [10, 20],
                                    lambda P: np.abs(np.hypot(P[:, 0], P[:, 1]) - 1), 5.0, levels, eps)
        r, z = disc.nodes.T
        phi = _tanh(1 - np.hypot(r, z), eps)
        check = shape.measure(disc, phi, eps, float(disc.weights @ phi), 1.0)
        hs.append(disc.h_fine)
        gaps.append(check.volume_gap)
    assert 1.8 < _order(hs, gaps) < 2.2, gaps  # O(h_fine^2): measured 1.96
    assert abs(gaps[-1]) < 1e-3 and shape.judge(check)[0] == "ok", gaps
