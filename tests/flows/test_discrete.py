"""flows/discrete.FlowModel against the model: its one-argument quantities are the model's
(functionals, penalised_energy), its two-argument difference quotients reduce to the model's
gradients and (differentiated) to the one matrix-free Hessian (model.lumped), and its Fourier
Jacobian model is exact in the bulk. (The exact discrete chain rules: tests/flows/test_schemes.py.)"""

import numpy as np
import pytest

from vesicle_opt import scene as S
from vesicle_opt.errors import NotSupported
from vesicle_opt.flows.discrete import FlowModel
from vesicle_opt.flows.api import build_model
from vesicle_opt.mesh import fem
from vesicle_opt.mesh.spectral import fourier_grid
from vesicle_opt.model import functionals as F
from vesicle_opt.model.lumped import LumpedOperators, PhaseField


def _scene(*sets, n=24):
    return S.load("ellipse-2d", [f"mesh.n={n}", "solver.M=100", *sets])


@pytest.fixture(params=["fd", "fem-lumped-natural", "fft-fd"])
def model(request):
    if request.param == "fem-lumped-natural":
        md = build_model(_scene('mesh.kind="fem-p1"', 'domain.boundary="natural"', n=12))
    else:
        md = build_model(_scene())
    disc = md.disc
    if request.param == "fft-fd":
        disc = fourier_grid(disc.box, disc.grid_shape, "fd")
    return FlowModel(disc, md.epsilon, 0.4, 2.0, md.alpha, md.beta, md.M, 1.0)  # C != 0, kappa != 1


def _field(md, rng):
    x = md.disc.nodes
    return np.tanh(-(np.hypot(x[:, 0] / 1.6, x[:, 1] / 1.25) - 1) / 0.3) + 0.05 * rng.standard_normal(x.shape[0])


def test_one_argument_quantities_are_the_models(model, rng):
    md, phi = model, _field(model, rng)
    disc, eps, C = md.disc, md.epsilon, md.C
    vals = F.evaluate(disc, phi, eps, C)
    # the same functions on the same Laplacian: identical to the last bit
    assert md.E(phi) == md.rigidity * vals["E"] and md.A(phi) == vals["A"] and md.B(phi) == vals["B"]
    assert np.array_equal(md.F(phi), F.curvature_residual(phi, disc.apply_laplacian(phi), eps, C))
    assert np.array_equal(md.dp(phi), -F.reaction_derivative(phi, eps, C))
    dE, dA, dB = F.gradients(disc, phi, eps, C)
    assert np.array_equal(md.g1(phi), md.rigidity * dE / md.m) and np.array_equal(md.f1(phi), -dB / md.m)
    # ... and the matrix-free model's (another summation order: round-off, measured <= 1e-16)
    st = PhaseField(LumpedOperators(disc), eps, C).state(phi)
    assert abs(md.E(phi) - md.rigidity * st.E) <= 1e-12 * md.E(phi)
    assert abs(md.B(phi) - st.B) <= 1e-12 * st.B


def test_difference_quotients_reduce_to_the_gradients(model, rng):
    """f(phi, phi) = -grad B, g(phi, phi) = kappa grad E_h (lumped L^2), Q(phi, phi) = p'(phi)."""
    md, phi = model, _field(model, rng)
    # the same polynomials in another order (and m L against -K): round-off (measured <= 5e-16)
    for two, one in ((md.f2(phi, phi), md.f1(phi)), (md.g2(phi, phi), md.g1(phi)), (md.Q(phi, phi), md.dp(phi))):
        assert np.max(np.abs(two - one)) <= 1e-12 * np.max(np.abs(one))


def test_jacobians_on_the_diagonal_are_half_the_matrix_free_hessian(model, rng):
    """d/dphi g(phi, phi) = 2 d_1 g (symmetry), so d_1 g(phi, phi) = kappa H_E / (2 m), d_1 f = -H_B / (2 m):
    the flows' second derivatives against the one hand-written Hessian product (model.lumped)."""
    md, phi = model, _field(model, rng)
    pf = PhaseField(LumpedOperators(md.disc), md.epsilon, md.C)
    st = pf.state(phi)
    parts = pf.hessian_parts(st)
    v = np.random.default_rng(7).standard_normal(phi.size)
    HE, HB = pf.hvp(st, parts, v, md.rigidity, 0.0), pf.hvp(st, parts, v, 0.0, 1.0)
    a, b = 0.3, -0.7
    ref = v + a * HE / (2 * md.m) - b * HB / (2 * md.m)
    # two stencil products summed in another order: round-off (measured <= 5e-16)
    assert np.max(np.abs(md.jacobian_apply(phi, phi, a, b)(v) - ref)) <= 1e-12 * np.max(np.abs(ref))
    if not md.matrix_free:
        # as above (measured <= 2e-16)
        assert np.max(np.abs(md.dg2(phi, phi) @ v - HE / (2 * md.m))) <= 1e-12 * np.max(np.abs(HE / md.m))
        assert np.max(np.abs(md.df2(phi, phi) @ v + HB / (2 * md.m))) <= 1e-12 * np.max(np.abs(HB / md.m))


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_jacobian_model_is_exact_in_the_bulk(sign, rng):
    """At phi = eta = +-1 with c0 = 0 the Fourier model (model.lumped.bulk_symbol) is the Jacobian."""
    disc = fourier_grid(((-2.0, 2.0), (-1.5, 1.5)), (16, 12), "spectral")
    md = FlowModel(disc, 0.3, 0.0, 2.0, 0.0, 1.0, 100.0, 1.0)
    one = sign * np.ones(disc.n_nodes)
    v = rng.standard_normal(disc.n_nodes)
    for a, b in ((1e-3, 0.0), (1e-2, -0.5), (1e-2, 1e-3)):  # b small: the floor stays inactive
        w = md.jacobian_model_inverse(a, b)(md.jacobian_apply(one, one, a, b)(v))
        assert np.max(np.abs(w - v)) <= 1e-12 * np.max(np.abs(v))  # FFT round-off (measured <= 2e-15)


@pytest.mark.parametrize("kwargs, key", [({"mass": "consistent"}, "mesh.mass"),
                                         ({"quadrature": "gauss"}, "mesh.quadrature")])
def test_flow_model_refuses_what_is_not_lumped(kwargs, key):
    disc = fem.p1(((-1.0, 1.0), (-1.0, 1.0)), (6, 6), periodic=True, **kwargs)
    with pytest.raises(NotSupported, match=key):
        FlowModel(disc, 0.3, 0.0, 1.0, 0.0, 1.0, 100.0, 1.0)
