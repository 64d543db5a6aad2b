"""verify.shape: the phi = 0 surface's volume and curvature against closed forms, the bulk-offset
identity (two independent routes to the volume the bulk carries), mirror grids and corners, and the
front door's verdicts."""

import dataclasses
import math

import numpy as np
import pytest

from vesicle_opt.mesh import cosine, fd, spectral
from vesicle_opt.model import functionals as F
from vesicle_opt.verify import shape, topology


def _field(disc, R, eps, center=None, delta=0.0):
    """The tanh sphere / circle of radius R; delta: the outer bulk pushed to -1 - delta (+1 kept)."""
    x = disc.nodes
    c = np.zeros(disc.dim) if center is None else np.asarray(center, float)
    L = np.array([b - a for a, b in disc.box])
    d = x - c
    if disc.kind != cosine.KIND:  # the periodic image nearest
        d = d - L * np.round(d / L)
    phi = np.tanh((R - np.linalg.norm(d, axis=1)) / (math.sqrt(2) * eps))
    return np.where(phi < 0, phi * (1 + delta), phi)  # -1 -> -1 - delta, the zero level kept


def _check(disc, phi, eps):
    ev = F.evaluate(disc, phi, eps, 0.0)
    return shape.measure(disc, phi, eps, ev["A"], ev["B"], topology.report(disc, phi).get("wraps"))


def test_sphere_total_curvature_and_volume_against_closed_forms():
    R, eps = 1.2, 0.2
    ns, vol_err, gaps = (32, 48, 64), [], []
    for n in ns:
        disc = spectral.grid([[-3.0, 3.0]] * 3, (n,) * 3)
        c = _check(disc, _field(disc, R, eps), eps)
        # int kappa dA = 8 pi R (Steiner: sum |e| theta_e): measured -2.7e-3 at 32^3, falling with h
        assert c.curvature_integral == pytest.approx(8 * math.pi * R, rel=3e-3)
        vol_err.append(abs(c.zero_volume / (4 / 3 * math.pi * R**3) - 1))
        gaps.append(c.volume_gap)
        assert shape.judge(c) == ("ok", None)
    # marching cubes' volume (linear interpolation of the tanh across a cell) converges at order 2
    order = -np.polyfit(np.log(ns), np.log(vol_err), 1)[0]
    assert 1.8 < order < 2.2
    # the corrected gap is that grid error plus O((eps/R)^4) ~ 8e-4: |gap| at 64^3 within the
    # volume's own grid error (3.7e-3) plus the O(eps^4) term; the uncorrected one is -11 %
    assert abs(gaps[-1]) < vol_err[-1] + (eps / R) ** 4
    assert c.zero_volume / c.phase_field_volume - 1 < -0.1


def test_circle_turning_number_and_area():
    R, eps = 1.5, 0.2
    disc = fd.grid([[-4.0, 4.0]] * 2, (128, 128))
    c = _check(disc, _field(disc, R, eps), eps)
    assert c.curvature_integral == 2 * math.pi  # int kappa ds of one closed curve: exact
    assert c.zero_volume == pytest.approx(math.pi * R**2, rel=1e-3)  # shoelace, O(h^2) at h = 1/16
    assert c.zero_area == pytest.approx(2 * math.pi * R, rel=1e-3)
    assert abs(c.volume_gap) < 2e-3  # (eps/R)^4 = 3e-4 and the contour's O(h^2)


def test_bulk_offset_measured_two_ways():
    """The outer bulk at -1 - delta: the corrected surface volume misses exactly the volume the
    offset takes up, delta |Omega_out| / 2 (the surface does not move: same V_0 and curvature)."""
    R, eps, delta = 1.2, 0.2, 0.03
    disc = spectral.grid([[-3.0, 3.0]] * 3, (48,) * 3)
    clean, bulk = (_check(disc, _field(disc, R, eps, delta=d), eps) for d in (0.0, delta))
    assert bulk.bulk_offset_out == pytest.approx(delta, rel=1e-3)  # min phi at the box corner: tanh tail 1e-9
    # the zero level is kept; marching cubes' interpolation weights move by <= delta / 2 of a cell
    assert bulk.zero_volume == pytest.approx(clean.zero_volume, rel=delta / 2)
    # route 1, the surface: the gap grows by the volume the bulk takes from A; route 2, min phi
    # alone: delta |Omega_out| / (2 V), which counts the tanh tail's nodes at -1 - delta too (they
    # carry int (1 + phi) ~ S sqrt2 eps ln 2 = 2 % of |Omega_out| less) and the V_0 shift above (1 %)
    assert bulk.volume_gap - clean.volume_gap == pytest.approx(bulk.bulk_volume_share, rel=0.04)
    # the surface is round (0.99+), and without the 43 % of V the bulk carries it would not be: the
    # cubic box's wrong shape; so is an eighth of it, which takes that much of a sphere's deficit
    for c in (bulk, _check(disc, _field(disc, R, eps, delta=delta / 5), eps)):
        verdict, line = shape.judge(c)
        assert c.zero_reduced_volume >= shape.ROUND > c.without_bulk
        assert verdict == "wrong_shape" and "mirror grid" in line and "round" in line
    assert shape.judge(clean) == ("ok", None)


def test_corner_and_mirror_grid_give_the_same_measures():
    R, eps = 1.0, 0.2
    centred = spectral.grid([[-2.4, 2.4]] * 3, (40,) * 3)
    corner = spectral.grid([[0.0, 4.8]] * 3, (40,) * 3)  # the vesicle split over the 8 corners
    octant = cosine.grid([[0.0, 2.4]] * 3, (20,) * 3)  # one octant, nodes at cell centres
    a = _check(centred, _field(centred, R, eps), eps)
    b = _check(corner, _field(corner, R, eps), eps)
    c = _check(octant, _field(octant, R, eps), eps)
    assert b.volume_gap == pytest.approx(a.volume_gap, abs=1e-12)  # the same nodes, rolled
    # the octant's doubled box has its nodes shifted by h/2 from the periodic box's: the marching
    # cubes' O(h^2) volume error (3.7e-3 of V at h = 0.094 above, so ~6e-3 at h = 0.12) differs
    assert c.zero_volume == pytest.approx(a.zero_volume, rel=6e-3)
    assert c.volume_gap == pytest.approx(a.volume_gap, abs=6e-3)
    assert c.curvature_integral == pytest.approx(a.curvature_integral, rel=3e-3)  # as the sphere test


def test_wrapped_slab_is_a_wrong_shape():
    disc = fd.grid([[-2.0, 2.0]] * 2, (32, 32))
    phi = np.tanh((0.8 - np.abs(disc.nodes[:, 1])) / (math.sqrt(2) * 0.2))  # a band across x
    c = _check(disc, phi, 0.2)
    assert c.wraps == (0,) and c.volume_gap is None  # open contours: no enclosed volume
    verdict, line = shape.judge(c)
    assert verdict == "wrong_shape" and "periodic image" in line


def _prolate(box, n, boundary="periodic"):
    from vesicle_opt.scene.schema import from_dict
    raw = {"domain": {"box": box, "boundary": boundary}, "mesh": {"kind": "spectral", "n": n},
           "model": {"epsilon": 0.2}, "constraints": {"reduced_volume": 0.75, "area": 4 * math.pi},
           "initial": {"shape": "ellipsoid", "semi_axes": [1.6, 0.7, 0.7], "center": [0, 0, 0]},
           "solver": {"method": "exact", "tol": 1e-8, "backend": "newton-krylov"}}
    return from_dict(raw, "prolate")


def test_fitted_prolate_on_the_mirror_grid_is_certified_with_its_bulk_reported():
    """The issue's prolate (v = 0.75, eps = 0.2, area 4 pi) in its fitted box, one octant: a
    converged minimum whose surface is the asked shape (0.744), its bulk carrying 25 % of V."""
    from vesicle_opt import solve
    r = solve(_prolate([[0.0, 3.6], [0.0, 1.44], [0.0, 1.44]], [45, 18, 18], "natural"))
    assert r.converged and r.outcome == "converged" and r.extra["second_order"] == "minimum"
    assert r.extra["shape"] == "bulk_offset" and "25%" in r.extra["shape_reason"]
    # the two routes agree (0.245 both, measured), the surface's reduced volume is the asked one
    # within the grid's isoperimetric slack
    assert r.extra["shape_volume_gap"] == pytest.approx(r.extra["bulk_volume_share"], abs=0.01)
    assert abs(r.extra["zero_level_reduced_volume"] - 0.75) < 0.01  # measured 0.744
    assert r.extra["zero_level_reduced_volume_without_bulk"] < r.extra["zero_level_reduced_volume"] < shape.ROUND


@pytest.mark.slow
def test_cubic_box_prolate_is_not_a_converged_minimum():
    """The issue's case: [-3, 3]^3, spectral 48^3: a KKT point (before: "converged, minimum") whose
    phi = 0 surface is a sphere (0.998) with half of V in the bulk: outcome wrong_shape."""
    from vesicle_opt import solve
    r = solve(_prolate([[-3.0, 3.0]] * 3, 48))
    assert not r.converged and r.outcome == "wrong_shape"
    assert r.extra["zero_level_reduced_volume"] > shape.ROUND > r.extra["zero_level_reduced_volume_without_bulk"]
    assert r.extra["shape_volume_gap"] > 0.4
    assert "mirror grid" in r.reason and "fitted" in r.reason


def test_annulus_curvature_cancels_and_its_area_is_the_ring():
    """2D: a ring (one outer curve, one hole): int kappa ds = 2 pi - 2 pi = 0, area pi (R^2 - r^2)."""
    eps, R, r = 0.15, 2.0, 1.0
    disc = fd.grid([[-4.0, 4.0]] * 2, (128, 128))
    rho = np.linalg.norm(disc.nodes, axis=1)
    phi = np.tanh(np.minimum(R - rho, rho - r) / (math.sqrt(2) * eps))
    c = _check(disc, phi, eps)
    assert c.curvature_integral == 0.0
    assert c.zero_volume == pytest.approx(math.pi * (R**2 - r**2), rel=2e-3)  # the contours' O(h^2), h = 1/16
