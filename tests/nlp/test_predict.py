"""The walk's interface secant (``nlp.predict.interface_secant``): for a tanh front moving at constant
speed it is exact inside the interface (the secant in artanh(phi) of a translation), where the
secant in phi itself misses by the profile's curvature; the multipliers are extrapolated linearly.
The parabola through three points (``interface_extrapolation``) is exact for a front moving with
constant acceleration, which the secant misses."""

from types import SimpleNamespace

import numpy as np
import pytest

from vesicle_opt.nlp.predict import interface_extrapolation, interface_secant

EPS = 0.02


def _front(x, at):
    return np.tanh((x - at) / (np.sqrt(2) * EPS))


def test_a_moving_front_is_extrapolated_exactly_inside_the_interface():
    x = np.linspace(-1, 1, 4001)
    a, b, c = (_point(x, s, lam) for s, lam in ((0.0, (1.0, 2.0)), (EPS / 4, (1.5, 2.5)), (EPS / 2, (2.0, 3.0))))
    out = interface_secant(a, b)
    inside = np.abs(c.phi) < 0.99
    # exact up to artanh/tanh round-off (~1e-13 at |phi| = 0.99: 1/(1 - phi^2) amplifies eps)
    assert np.abs(out.phi - c.phi)[inside].max() < 1e-12
    lin = 2 * b.phi - a.phi  # the secant in phi: off by (delta/eps)^2 phi''/... inside (measured 0.02)
    assert np.abs(lin - c.phi)[inside].max() > 1e-2
    assert np.abs(out.phi - c.phi).max() < 1e-3  # the bulk: the secant in phi of a nearly constant field
    assert (out.lambda_volume, out.lambda_area) == (2.0, 3.0)  # linear data: the secant is exact
    half = interface_secant(a, b, ratio=0.5)  # half a step: the front at 3 delta / 2
    assert np.abs(half.phi - _front(x, 3 * EPS / 8))[np.abs(half.phi) < 0.99].max() < 1e-12


def _point(x, at, lam):
    phi = _front(x, at)
    return SimpleNamespace(phi=phi, x=phi, disc=None, lambda_volume=lam[0], lambda_area=lam[1])


def test_an_accelerating_front_is_extrapolated_exactly_by_the_parabola():
    x = np.linspace(-1, 1, 4001)
    at = [EPS / 4 * t + EPS / 16 * t**2 for t in range(4)]  # the front's position, quadratic in the walk
    lam = [(1.0 + t * t, 2.0 - t) for t in range(4)]
    a, b, c, d = (_point(x, s, m) for s, m in zip(at, lam))
    out = interface_extrapolation((a, b, c))
    inside = np.abs(d.phi) < 0.99
    # exact up to artanh/tanh round-off, as the secant for a uniform motion (~1e-13 at |phi| = 0.99)
    assert np.abs(out.phi - d.phi)[inside].max() < 1e-12
    sec = interface_secant(b, c)  # the secant misses the acceleration: 2 EPS/16 off, ~0.09 in phi here
    assert np.abs(sec.phi - d.phi)[inside].max() > 1e-2
    assert (out.lambda_volume, out.lambda_area) == (10.0, -1.0)  # quadratic data: the parabola is exact
    two = interface_extrapolation((b, c))  # two points: the secant itself
    assert np.array_equal(two.phi, sec.phi) and two.lambda_volume == sec.lambda_volume


def test_extrapolation_refuses_other_meshes_and_counts():
    x = np.linspace(-1, 1, 101)
    a, b = _point(x, 0.0, (1, 1)), _point(x[:-1], 0.0, (1, 1))
    with pytest.raises(ValueError, match="one mesh"):
        interface_extrapolation((a, b))
    with pytest.raises(ValueError, match="two or three"):
        interface_extrapolation((a,))
