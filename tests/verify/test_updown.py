"""``verify.updown``: the up-down asymmetry of a meridian field and its poles. A symmetric field on
a mesh that is not mirrored (a band about an asymmetric curve) is symmetric to round-off and
interpolation (1e-7); an asymmetric field's value is its exact mirror image's
(the field's formula at the mirrored points, no interpolation) to that error; the poles of an
oblate spheroid field are its semi-axis apart, and a torus has none."""

import functools
import math

import numpy as np
import pytest

from vesicle_opt.mesh import axisymmetric as ax
from vesicle_opt.verify import updown

EPS = 0.1
BOX, N0 = ((0.0, 2.0), (-2.0, 2.0)), (10, 20)  # square cells of 0.2


def _egg(r, z, skew):
    """A tanh field about an egg: the sphere of radius 1 with its upper half stretched by 1 + skew."""
    return np.tanh((1 - np.hypot(r, z / np.where(z > 0, 1 + skew, 1.0))) / (math.sqrt(2) * EPS))


@functools.lru_cache(maxsize=None)
def _mesh(levels):  # a band about the egg of skew 0.3: not mirrored about any height
    return ax.band_p1(BOX, N0, lambda p: np.abs(np.hypot(p[:, 0], p[:, 1] / np.where(p[:, 1] > 0, 1.3, 1.0)) - 1),
                      8.0, levels, EPS)


def test_a_symmetric_field_on_a_mesh_that_is_not_mirrored_is_symmetric():
    for levels in (2, 3):
        d = _mesh(levels)
        # measured 5e-8, 1e-7: the centroid's quadrature (z_c ~ 1e-8 off 0) and the P1 interpolation
        # of a field that is +-1 beyond the band; far below the threshold
        assert updown.asymmetry(d, _egg(d.nodes[:, 0], d.nodes[:, 1], 0.0)) < updown.SYMMETRIC / 1000


def test_an_asymmetric_field_against_its_exact_mirror_image():
    d = _mesh(3)
    r, z = d.nodes[:, 0], d.nodes[:, 1]
    phi = _egg(r, z, 0.3)
    w = d.weights
    inside = w * (1 + phi) / 2
    zc = inside @ z / inside.sum()
    exact = w @ np.abs(phi - _egg(r, 2 * zc - z, 0.3)) / (w @ (1 + phi))  # the formula, not interpolated
    got = updown.asymmetry(d, phi)
    assert got > 10 * updown.SYMMETRIC
    assert got == pytest.approx(exact, rel=1e-2)  # the P1 interpolation error (~1e-3 relative measured)
    info = updown.describe(d, phi)
    assert info["symmetric"] is False and info["form"] == "prolate"
    # the threshold tells a pole moved by 0.005 (a quarter of eps = 0.02's interface; measured 1.6e-3)
    assert updown.asymmetry(d, _egg(r, z, 0.005)) > updown.SYMMETRIC


def test_poles_of_an_oblate_and_none_for_a_torus():
    d = _mesh(3)
    r, z = d.nodes[:, 0], d.nodes[:, 1]
    oblate = np.tanh((1 - np.hypot(r / 1.2, z / 0.4)) * 0.4 / (math.sqrt(2) * EPS))  # semi-axes 1.2, 0.4
    info = updown.describe(d, oblate)
    assert info["form"] == "oblate" and info["symmetric"]
    assert info["pole_gap"] == pytest.approx(0.8, abs=2 * d.h_fine)  # the zero crossing on the axis, to a cell
    torus = np.tanh((0.3 - np.hypot(r - 1.0, z)) / (math.sqrt(2) * EPS))
    info = updown.describe(d, torus)
    assert info["pole_gap"] is None and info["form"] is None
