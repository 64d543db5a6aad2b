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


def test_a_step_along_the_profile_shifts_a_tanh_interface():
    """The Newton step of a shift delta, dphi = -delta phi' (the linearised shift): ``step`` gives the
    shifted profile exactly where T moves by less than the cap; phi + dphi errs by ~ (delta / w)^2."""
    x = np.linspace(-1.0, 1.0, 801)
    w = np.sqrt(2) * 0.05
    delta = 0.02  # 0.28 eps-widths w of shift: a = delta / w = 0.28 < STEP_CAP
    phi = np.tanh(x / w)
    dphi = -(delta / w) * (1 - phi**2)
    want = np.tanh((x - delta) / w)
    got = profile.step(phi, dphi)
    band = np.maximum(np.abs(phi), np.abs(want)) < profile.C
    assert np.max(np.abs(got - want)[band]) < 1e-12  # the same coordinate, advanced exactly: round-off
    assert np.max(np.abs(phi + dphi - want)) > 1e-2  # measured 0.031, ~ (delta / w)^2 / 2 = 0.04


def test_a_step_along_the_profile_is_newtons_to_first_order():
    """|step(phi, t d) - (phi + t d)| = O(t^2): Newton's local (quadratic) convergence is kept. Fitted
    on t = 1e-4 .. 1e-6 (below the cap: T' t |d| <= 500 x 4e-4) for a random d on a band, bulk and offset nodes; beyond the band the linear
    step exactly; no node moves more than the cap in T beyond the linear step."""
    rng = np.random.default_rng(3)
    phi = np.concatenate([np.tanh(rng.uniform(-4, 4, 200)), [-1.0023, 1.0, 0.9995, -0.9991]])
    d = rng.standard_normal(phi.size)
    ts = np.array([1e-4, 1e-5, 1e-6])
    defect = [np.max(np.abs(profile.step(phi, t * d) - (phi + t * d))) for t in ts]
    order = np.polyfit(np.log(ts), np.log(defect), 1)[0]
    assert 1.9 < order < 2.1, (order, defect)  # second order: the coordinate's curvature times t^2
    bulk = np.array([-1.05, 1.002, 1.3])  # all beyond C, and so after a small step
    db = np.array([0.01, -0.0005, 0.1])
    assert np.array_equal(profile.step(bulk, db), bulk + db)  # T linear there: the same floats
    big = profile.step(phi, 10 * d)  # T' d up to 500 x 10: clipped to the cap
    # in the band field(T + a) and phi both lie in [-1, 1] and |a / T'| <= cap (1 - phi^2) <= 0.5; beyond it 0
    assert np.all(np.isfinite(big)) and np.max(np.abs(big - (phi + 10 * d))) <= 2.5


def test_a_step_at_round_off_level_is_the_plain_step():
    """dphi ~ 1e-12 (the last Newton steps of a point certified at tol 1e-10): the step's increment is
    formed without a round trip through atanh, so the iterate is phi + dphi's own float. The round trip
    T^{-1}(T(phi) + a) left half an ulp (1.1e-16), and with it the spectral 128^2 branch's first point
    (tests/verify/test_kkt_dual.py) stalled at error 5.29e-12 against its stop 5e-12 under two BLAS threads."""
    rng = np.random.default_rng(3)
    phi = np.concatenate([np.tanh(rng.uniform(-4, 4, 2000)), [-1.0023, 1.0, 0.9995, -0.9991]])
    d = 1e-12 * rng.standard_normal(phi.size)
    assert np.max(np.abs(profile.step(phi, d) - (phi + d))) < np.spacing(1.0) / 2  # measured 0
