"""The in-place forms of the matrix-free hot loops against the plain formulas they replace:
``lumped.pointwise`` against ``functionals``, the fused grid Hessian product against the general
form (``hvp_operator(fused=False)`` plus the rank-one term written out), the spectral constant of
``apply_symbol`` against adding it, and the scaled spectral derivatives."""

import importlib.util

import numpy as np
import pytest

from vesicle_opt.mesh import cosine
from vesicle_opt.mesh.spectral import fft_library, fourier_grid
from vesicle_opt.model import functionals as F
from vesicle_opt.model.lumped import LumpedOperators, PhaseField, pointwise

ROUNDOFF = 1e-13  # relative max-norm: a few ulps per pointwise op, FFT round-off ~ u log N (<= 1e-15)
LIBRARIES = ["scipy"] + (["pyfftw"] if importlib.util.find_spec("pyfftw") else [])


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("C", [0.0, 0.7])
def test_pointwise_equals_functionals(C, rng):
    phi = np.tanh(rng.standard_normal(500) * 3)
    lap = rng.standard_normal(500)
    eps = 0.3
    r, s, one_minus_sq = pointwise(phi, lap, eps, C)
    assert _rel(r, F.curvature_residual(phi, lap, eps, C)) < ROUNDOFF
    assert _rel(s, F.reaction_derivative(phi, eps, C)) < ROUNDOFF
    assert _rel(one_minus_sq ** 2 / 4, F.double_well(phi)) < ROUNDOFF


def _grids():
    return {"spectral-2d": fourier_grid(((-2.0, 2.0), (-1.5, 1.5)), (16, 12), "spectral"),
            "fd-2d": fourier_grid(((-2.0, 2.0), (-1.5, 1.5)), (16, 12), "fd"),
            "spectral-3d": fourier_grid(((-2.0, 2.0),) * 3, (10, 8, 12), "spectral"),
            "cosine-3d": cosine.grid(((0.0, 2.0),) * 3, (6, 8, 7))}


@pytest.mark.parametrize("name", ["spectral-2d", "fd-2d", "spectral-3d", "cosine-3d"])
@pytest.mark.parametrize("library", LIBRARIES)
def test_fused_grid_hvp_equals_the_general_form(name, library, rng):
    disc = _grids()[name]
    pf = PhaseField(LumpedOperators(disc), 0.4, 0.5)
    x = disc.nodes
    phi = np.tanh(1.2 - np.linalg.norm(x - x.mean(axis=0), axis=1)) + 0.05 * rng.standard_normal(disc.n_nodes)
    v = rng.standard_normal(disc.n_nodes)
    m = pf.m
    with fft_library(library):
        st = pf.state(phi)
        parts = pf.hessian_parts(st)
        for cE, cB, rho_A in [(1.0, 0.0, 0.0), (2.0, -0.7, 0.0), (1.5, 0.3, 40.0)]:
            fused = pf.hvp_operator(st, parts, cE, cB, rho_A)(v)
            general = pf.hvp_operator(st, parts, cE, cB, fused=False)(v) + rho_A * (m @ v) * m
            assert _rel(fused, general) < ROUNDOFF, (cE, cB, rho_A)


@pytest.mark.parametrize("library", LIBRARIES)
def test_apply_symbol_adds_its_constant_through_the_zero_mode(library, rng):
    for disc in _grids().values():
        f = disc.fourier
        v = rng.standard_normal(disc.n_nodes)
        with fft_library(library):
            plain = f.apply_symbol(v, f.symbol)
            shifted = f.apply_symbol(v, f.symbol, 0.37)
        assert _rel(shifted, plain + 0.37) < ROUNDOFF


def test_scaled_derivatives_are_the_scaled_derivatives(rng):
    f = _grids()["spectral-3d"].fourier
    v = rng.standard_normal(f.size)
    for a, b in zip(f.derivatives(v, 0.125), f.derivatives(v)):
        assert _rel(a, 0.125 * b) < ROUNDOFF


@pytest.mark.parametrize("name", ["spectral-2d", "fd-2d", "spectral-3d"])
@pytest.mark.parametrize("library", LIBRARIES)
def test_the_product_in_fourier_coordinates_is_the_nodal_one(name, library, rng):
    """``hvp_coordinates`` y -> T H T^{-1} y (four transforms) against the general nodal product
    conjugated by T (``mesh.coordinates``); y random in T's range, every term on (rho_A, cB)."""
    disc = _grids()[name]
    pf = PhaseField(LumpedOperators(disc), 0.4, 0.5)
    T = disc.fourier.coordinates
    x = disc.nodes
    phi = np.tanh(1.2 - np.linalg.norm(x - x.mean(axis=0), axis=1)) + 0.05 * rng.standard_normal(disc.n_nodes)
    v = rng.standard_normal(disc.n_nodes) + 0.3  # a mean: the rank-one volume term is not zero
    m = pf.m
    with fft_library(library):
        st = pf.state(phi)
        parts = pf.hessian_parts(st)
        y = T.forward(v)
        for cE, cB, rho_A in [(1.0, 0.0, 0.0), (2.0, -0.7, 0.0), (1.5, 0.3, 40.0)]:
            product = pf.hvp_coordinates(st, parts, cE, cB, rho_A)
            in_y = product(y)
            again = product(y)  # the work fields are reused: a second product is the same
            nodal = T.forward(pf.hvp_operator(st, parts, cE, cB, fused=False)(v) + rho_A * (m @ v) * m)
            assert _rel(in_y, nodal) < ROUNDOFF, (cE, cB, rho_A)
            assert np.array_equal(in_y, again)
