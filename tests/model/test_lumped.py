"""The matrix-free model (model/lumped.py) against the other forms of E_h, A, B and derivatives:
the numpy functionals, the NLP's CasADi graph (values, AD gradients, AD Hessians), finite
differences; its guard; and the bulk model shared by the preconditioner and the flows."""

import casadi as ca
import numpy as np
import pytest

from vesicle_opt.errors import NotSupported
from vesicle_opt.mesh import fem
from vesicle_opt.mesh.spectral import fourier_grid
from vesicle_opt.model import functionals as F
from vesicle_opt.model.lumped import LumpedOperators, PhaseField, bulk_stiffness, bulk_symbol
from vesicle_opt.nk.precond import FourierPreconditioner, SparsePreconditioner
from vesicle_opt.nlp.exact import build_exact
from vesicle_opt import load_scene


# sparse lumped discretisations with nodal quadrature (the Fourier grids: test_spectral)
SCENES = {
    "fd": ("mesh.n=12",),
    "fem-lumped-periodic": ("mesh.n=12", "mesh.kind='fem-p1'"),
    "fem-lumped-natural": ("mesh.n=10", "mesh.kind='fem-p1'", "domain.boundary='natural'"),
}


def _nlp(name):
    sc = load_scene("ellipse-2d", ["model.epsilon=0.5", "model.c0=0.4", "model.rigidity=2.0", *SCENES[name]])
    return build_exact(sc, check=False)


def _field(disc, rng):
    x = disc.nodes
    return np.tanh(1.5 - np.hypot(x[:, 0] / 1.6, x[:, 1] / 1.2)) + 0.05 * rng.standard_normal(disc.n_nodes)


def _casadi(nlp):
    """phi -> (E_h, A, B, dE_h, dA, dB, H_E, H_B) from the NLP's own scaled f and g (AD)."""
    x = nlp.x
    rig = nlp.scene.model.rigidity
    E = nlp.f * nlp.f_scale / rig
    A = nlp.g[0] * nlp.g_scale[0] + nlp.alpha
    B = nlp.g[1] * nlp.g_scale[1] + nlp.beta
    HE, gE = ca.hessian(E, x)
    HB, gB = ca.hessian(B, x)
    fun = ca.Function("forms", [x], [E, A, B, gE, ca.gradient(A, x), gB, HE, HB])

    def forms(phi):
        out = [np.asarray(v.full()) for v in fun(phi)]
        return [float(v.item()) for v in out[:3]] + [v.ravel() for v in out[3:6]] + out[6:]
    return forms


@pytest.mark.parametrize("name", SCENES)
def test_values_and_gradients_equal_numpy_and_casadi(name, rng):
    nlp = _nlp(name)
    disc, sc = nlp.disc, nlp.scene
    eps, C = sc.model.epsilon, sc.model.C
    pf = PhaseField(LumpedOperators(disc), eps, C)
    phi = _field(disc, rng)
    st = pf.state(phi)
    vals = F.evaluate(disc, phi, eps, C)
    E, A, B, gE, gA, gB, _, _ = _casadi(nlp)(phi)
    for ours, numpy_, cas in ((st.E, vals["E"], E), (st.A, vals["A"], A), (st.B, vals["B"], B)):
        # the same sums in three orders (B: -m.(phi lap) against phi.K phi): round-off only
        # (measured <= 6e-16; 1e-12 leaves room for other BLAS summation orders)
        assert abs(ours - numpy_) <= 1e-12 * abs(numpy_)
        assert abs(ours - cas) <= 1e-12 * abs(numpy_)
    for ours, numpy_, cas in zip(pf.gradients(st), F.gradients(disc, phi, eps, C), (gE, gA, gB)):
        scale = np.max(np.abs(numpy_))
        # round-off of sums of terms up to ~10x the result (measured <= 7e-16 relative to max)
        assert np.max(np.abs(ours - numpy_)) <= 1e-12 * scale
        assert np.max(np.abs(ours - cas)) <= 1e-12 * scale


@pytest.mark.parametrize("name", SCENES)
def test_hvp_equals_casadi_hessian(name, rng):
    """The one hand-written Hessian product against CasADi's AD Hessian of the NLP's graph."""
    nlp = _nlp(name)
    disc, sc = nlp.disc, nlp.scene
    pf = PhaseField(LumpedOperators(disc), sc.model.epsilon, sc.model.C)
    phi = _field(disc, rng)
    st = pf.state(phi)
    parts = pf.hessian_parts(st)
    *_, HE, HB = _casadi(nlp)(phi)
    for _ in range(3):
        v = rng.standard_normal(disc.n_nodes)
        for cE, cB in ((1.0, 0.0), (0.0, 1.0), (2.0, -0.7)):
            ref = cE * (HE @ v) + cB * (HB @ v)
            # products of two sparse stencils in another order: round-off (measured <= 5e-16)
            assert np.max(np.abs(pf.hvp(st, parts, v, cE, cB) - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_gradients_and_hvp_vs_finite_differences_on_an_unstructured_lumped_mesh(rng):
    """P1 lumped with natural boundary: m varies and Delta_h is not symmetric (Delta_h^T != Delta_h)."""
    disc = fem.p1(((-2.0, 2.0), (-2.0, 2.0)), (10, 10), periodic=False)
    eps, C = 0.5, 0.4
    pf = PhaseField(LumpedOperators(disc), eps, C)
    phi = _field(disc, rng)
    v = rng.standard_normal(disc.n_nodes)
    st = pf.state(phi)
    t = 1e-4
    plus, minus = pf.state(phi + t * v), pf.state(phi - t * v)
    for name, g in zip("EAB", pf.gradients(st)):
        fd = (getattr(plus, name) - getattr(minus, name)) / (2 * t)
        # central differences: t^2 |third derivative| ~ 1e-8 relative, round-off |E| 1e-16/t ~ 1e-12
        assert abs(fd - g @ v) <= 1e-6 * max(abs(fd), 1.0), name
    parts = pf.hessian_parts(st)
    gp, gm = pf.gradients(plus), pf.gradients(minus)
    for cE, cB in ((1.0, 0.0), (0.0, 1.0), (2.0, -0.7)):
        fd = (cE * (gp[0] - gm[0]) + cB * (gp[2] - gm[2])) / (2 * t)
        assert np.max(np.abs(pf.hvp(st, parts, v, cE, cB) - fd)) <= 1e-6 * np.max(np.abs(fd))  # as above


@pytest.mark.parametrize("kwargs, key", [({"mass": "consistent"}, "mesh.mass"),
                                         ({"quadrature": "gauss"}, "mesh.quadrature")])
def test_guard_names_the_key_and_what_is_supported(kwargs, key):
    disc = fem.p1(((-1.0, 1.0), (-1.0, 1.0)), (6, 6), periodic=True, **kwargs)
    supported = {"mesh.mass": "'lumped'", "mesh.quadrature": "'nodal'"}[key]
    with pytest.raises(NotSupported, match=key) as info:
        LumpedOperators(disc)
    assert info.value.key == key and supported in str(info.value)


# --- the bulk model: exact at phi = +-1, c0 = 0 ---------------------------------------------------

def test_bulk_symbol_is_minus_the_jacobian_of_f_c_in_the_bulk(rng):
    disc = fourier_grid(((-2.0, 2.0), (-1.5, 1.5)), (16, 12), "spectral")
    eps = 0.3
    fg = disc.fourier
    v = rng.standard_normal(disc.n_nodes)
    one = np.ones(disc.n_nodes)
    J_v = eps * fg.laplacian(v) + F.reaction_derivative(one, eps, 0.0) * v  # J = eps Delta_h + g'
    # one FFT pair each way: round-off relative to |q| |v| ~ 1e2
    assert np.max(np.abs(fg.apply_symbol(v, bulk_symbol(fg, eps)) + J_v)) <= 1e-12 * np.max(np.abs(J_v))


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_fourier_preconditioner_is_the_hessian_in_the_bulk(sign, rng):
    """P(cE, cB) = cE H_E + cB H_B exactly at phi = +-1, c0 = 0 (cB > 0: the floor is inactive)."""
    disc = fourier_grid(((-2.0, 2.0), (-1.5, 1.5), (-1.0, 1.0)), (8, 6, 6), "spectral")
    eps = 0.4
    pf = PhaseField(LumpedOperators(disc), eps, 0.0)
    st = pf.state(sign * np.ones(disc.n_nodes))
    parts = pf.hessian_parts(st)
    P = FourierPreconditioner(disc.fourier, disc.weights[0], eps)
    v = rng.standard_normal(disc.n_nodes)
    for cE, cB in ((1.0, 0.0), (2.0, 0.5)):
        ref = pf.hvp(st, parts, v, cE, cB)
        model = disc.fourier.apply_symbol(v, P.symbol(cE, cB))
        assert np.max(np.abs(model - ref)) <= 1e-12 * np.max(np.abs(ref))  # two FFT pairs: round-off


def test_bulk_stiffness_is_the_sparse_bulk_model(rng):
    """S = eps K + (2/eps) M_L = -M_L J at phi = 1, c0 = 0, and the sparse preconditioner's S."""
    disc = fem.p1(((-2.0, 2.0), (-2.0, 2.0)), (8, 8), periodic=False)
    eps = 0.5
    S = bulk_stiffness(disc.K, disc.weights, eps)
    v = rng.standard_normal(disc.n_nodes)
    J_v = eps * (disc.laplacian @ v) + F.reaction_derivative(np.ones(disc.n_nodes), eps, 0.0) * v
    assert np.max(np.abs(S @ v + disc.weights * J_v)) <= 1e-12 * np.max(np.abs(S @ v))  # round-off
    assert abs(SparsePreconditioner(disc.K, disc.weights, eps).S - S).max() == 0.0  # the same matrix
