"""The assembled Hessian of the Lagrangian (``nlp.lumped_hessian``) against CasADi's own (automatic
differentiation of the NLP's graph: no shared code but the pointwise functions' definitions), and the
same IPOPT solve with either."""

import math

import numpy as np
import pytest
import scipy.sparse as sp

import vesicle_opt as vo
from vesicle_opt.nlp import IpoptOptions, lumped_hessian, reuse
from vesicle_opt.model import functionals as F
from vesicle_opt.nlp.exact import build_exact, parameter_values

REFINED = {"model.epsilon": 0.1, "domain.box": [[0.0, 2.4], [-3.4, 3.4]], "mesh.n": [12, 34],
           "mesh.refine": "interface", "mesh.levels": 1, "solver.second_order": False}


def _reference(disc, phi, epsilon: float, rigidity: float, f_scale: float, beta: float, C: float,
                       sigma: float, lam_area: float) -> sp.csc_matrix:
    """sigma rigidity / f_scale d2E_h + lam_area / beta d2B at phi (``nlp.lumped_hessian``, written again by sparse products): the full symmetric
    matrix (scipy CSC) of IPOPT's scaled NLP, ``lam_area`` its multiplier of the area row."""
    phi = np.asarray(phi, float)
    m, L, K = disc.weights, disc.laplacian, disc.K
    fc = F.curvature_residual(phi, L @ phi, epsilon, C)
    J = (epsilon * L + sp.diags(F.reaction_derivative(phi, epsilon, C))).tocsr()
    d2E = (J.T @ sp.diags(m) @ J + sp.diags(m * fc * F.reaction_second_derivative(phi, epsilon, C))) / epsilon
    Ks = (K + K.T) / 2  # CasADi's Hessian of phi^T K phi / 2, whatever K's round-off asymmetry
    d2B = epsilon * Ks + sp.diags(m * F.double_well_second_derivative(phi) / epsilon)
    return (sigma * rigidity / f_scale * d2E + lam_area / beta * d2B).tocsc()


def _upper(fun, *args):
    out = fun(*args)
    return sp.csc_matrix(out.sparse())


@pytest.mark.parametrize("c0", [0.0, 0.6])
def test_the_same_matrix_as_casadis(c0):
    """At a perturbed tanh field, random multipliers and objective factor: the upper triangles agree to
    round-off (1e-12 of the matrix's largest entry: sums of ~20 products of O(1/eps^3) terms in double)."""
    scene = vo.load_scene("prolate-axisymmetric", {**REFINED, "model.c0": c0})
    disc = vo.solve(scene).disc
    nlp = reuse._pinned(build_exact(scene, disc, check=False, parametric=True))
    assert lumped_hessian.applies(nlp)
    import casadi as ca
    lam = ca.MX.sym("lam", nlp.g.shape[0])
    sigma = ca.MX.sym("sigma")
    H_ad, _ = ca.hessian(sigma * nlp.f + ca.dot(lam, nlp.g), nlp.x)
    ad = ca.Function("ad", [nlp.x, nlp.p, sigma, lam], [ca.triu(H_ad)])
    rng = np.random.default_rng(1)
    r = np.hypot(disc.nodes[:, 0] / 0.8, disc.nodes[:, 1] / 1.2)
    phi = np.tanh((1 - r) / (math.sqrt(2) * 0.1)) + 0.05 * rng.standard_normal(disc.n_nodes)
    alpha, beta = 0.3 * disc.volume, 4 * math.pi * 1.1
    p = np.concatenate([parameter_values(scene, disc, alpha, beta), reuse.pin_row(disc)])
    lam_g = rng.standard_normal(nlp.g.shape[0])
    mine = lumped_hessian.hess_lag(nlp)
    a, b = _upper(ad, phi, p, 0.7, lam_g), _upper(mine, phi, p, 0.7, lam_g)
    scale = abs(a).max()
    assert abs(a - b).max() <= 1e-12 * scale, abs(a - b).max() / scale
    # the scipy products' matrix (the formula written once more, by sparse algebra), full and symmetric
    ref = _reference(disc, phi, 0.1, scene.model.rigidity, p[3], p[1], p[2], 0.7, lam_g[1])
    assert abs(ref - ref.T).max() <= 1e-12 * scale and abs(sp.triu(ref) - b).max() <= 1e-12 * scale  # round-off


def test_the_same_solve_with_either_hessian(monkeypatch):
    """A refined meridian solve with the assembled Hessian and with CasADi's: the same point (energy to
    IPOPT's tolerance, 1e-8 relative stationarity) and the same iterations (the same Newton steps up to
    round-off)."""
    scene = vo.load_scene("prolate-axisymmetric", REFINED)
    fast = vo.solve(scene)
    reuse._CACHE.clear()
    monkeypatch.setattr(lumped_hessian, "applies", lambda nlp: False)
    slow = vo.solve(scene)
    assert fast.converged and slow.converged
    assert fast.energy == pytest.approx(slow.energy, rel=1e-9)  # IPOPT tol 1e-8 on the same iterates
    assert abs(fast.iterations - slow.iterations) <= 1  # round-off may move the last test by one step
