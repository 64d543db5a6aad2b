"""The walk's interface secant (``nlp.predict.interface_secant``): for a tanh front moving at constant
speed it is exact inside the interface (the secant in artanh(phi) of a translation), where the
secant in phi itself misses by the profile's curvature; the multipliers are extrapolated linearly."""

from types import SimpleNamespace

import numpy as np

from vesicle_opt.nlp.predict import interface_secant

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
