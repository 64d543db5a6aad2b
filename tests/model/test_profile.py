"""``model.profile``: the tanh profile's coordinate and the secant predictor in it (closed forms)."""

import numpy as np

from vesicle_opt.model import profile


def test_the_coordinate_and_the_field_are_inverse_and_c1():
    phi = np.linspace(-1.05, 1.05, 2101)  # the band and the bulk past +-1 (a bulk offset)
    assert np.allclose(profile.field(profile.coordinate(phi)), phi, rtol=0, atol=1e-12)  # round-off of atanh/tanh near C
    assert np.all(np.diff(profile.coordinate(phi)) > 0)  # monotone
    h, c = 1e-9, profile.C
    left = (profile.coordinate(c) - profile.coordinate(c - h)) / h
    right = (profile.coordinate(c + h) - profile.coordinate(c)) / h
    # C^1 at the band's edge: both one-sided slopes are atanh'(C) = 1 / (1 - C^2) = 500.25, to the
    # quotients' truncation h atanh''(C) / 2 = 1.3e-4 (2.5e-7 relative) and round-off eps_mach T / h ~ 1e-6
    assert abs(left / right - 1) < 1e-5 and abs(right * (1 - c * c) - 1) < 1e-5


def test_the_secant_moves_a_tanh_interface_without_blurring_it():
    """Two tanh profiles a shift delta apart: the secant extrapolated by k is the profile shifted by
    k delta more, exactly in the band's core; the linear secant of phi is not (its error is
    (delta / width)^2); in the bulk (both beyond OUTER) it is the linear secant."""
    x = np.linspace(-1.0, 1.0, 801)
    w = np.sqrt(2) * 0.05
    delta, k = 0.02, 0.8
    phi_a, phi_b = np.tanh((x - 0.1) / w), np.tanh((x - 0.1 - delta) / w)
    want = np.tanh((x - 0.1 - (1 + k) * delta) / w)
    got = profile.interface_secant(phi_a, phi_b, k)
    band = np.maximum.reduce([np.abs(phi_a), np.abs(phi_b), np.abs(want)]) < profile.C  # all in the band
    assert np.max(np.abs(got - want)[band]) < 1e-12  # the same point of the coordinate: round-off
    linear = phi_b + k * (phi_b - phi_a)
    assert np.max(np.abs(linear - want)) > 1e-2  # measured 0.043: the blend errs by ~ (delta / w)^2 (0.04 here)


def test_a_bulk_node_drifting_across_the_band_edge_jumps():
    """Why the corrector compares this start with the linear prediction (module docstring): the FD
    ellipse at eps 0.4, a bulk node at -1.0023, then -0.9975, is extrapolated by k = 1.13 to -0.76."""
    got = profile.interface_secant(np.array([-1.0022598]), np.array([-0.9974993]), 1.1267)[0]
    assert -0.8 < got < -0.7, got
