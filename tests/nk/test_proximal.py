"""The proximal objective of the minimising movement (Proposition 4.1): value, gradient and
Hessian-vector product against finite differences, and c = 0 is the plain objective."""

from __future__ import annotations

import numpy as np
import pytest

from vesicle_opt import load_scene
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.nk.newton_cg import Counters, Objective
from vesicle_opt.nk.proximal import ProximalObjective
from vesicle_opt.nk.setup import prepare


@pytest.fixture(params=["spectral", "fd"])
def pieces(request, rng):
    sc = load_scene("ellipse-2d", [f"mesh.kind='{request.param}'", "mesh.n=24"])
    disc, pf, prec, translations = prepare(sc)
    alpha, beta = constraint_data(sc, disc)
    x, y = disc.nodes[:, 0], disc.nodes[:, 1]
    phi = np.tanh(-(np.hypot(x / 1.6, y / 1.2) - 1) / 0.3) + 0.05 * rng.standard_normal(disc.n_nodes)
    args = (pf, prec, translations, sc.model.rigidity, alpha, beta, np.array([0.3, -0.2]), np.array([50.0, 50.0]))
    return args, phi, phi + 0.1 * rng.standard_normal(phi.size), rng.standard_normal(phi.size)


def test_gradient_and_hessian_match_finite_differences(pieces):
    args, anchor, phi, v = pieces
    obj = ProximalObjective(*args, Counters(), anchor=anchor, c=37.0)
    pt = obj.point(phi)
    h = 1e-6
    fd_slope = (obj.value(phi + h * v)[0] - obj.value(phi - h * v)[0]) / (2 * h)
    # central differences: O(h^2) truncation plus f's round-off ~1e-16 |f| / h (f ~ 1e2): ~1e-8 relative
    assert abs(fd_slope - pt.g @ v) <= 1e-6 * abs(pt.g @ v)
    Hv = obj.hvp(pt)(v)
    fd_Hv = (obj.point(phi + h * v).g - obj.point(phi - h * v).g) / (2 * h)
    assert np.linalg.norm(fd_Hv - Hv) <= 1e-5 * np.linalg.norm(Hv)  # same truncation / round-off budget
    # the proximal part alone is exactly c m (phi - anchor) and c m v
    base = Objective(*args, Counters())
    bp = base.point(phi)
    m = args[0].m
    assert np.allclose(pt.g - bp.g, 37.0 * m * (phi - anchor), rtol=0, atol=1e-12 * np.max(np.abs(pt.g)))
    assert np.allclose(Hv - base.hvp(bp)(v), 37.0 * m * v, rtol=0, atol=1e-12 * np.max(np.abs(Hv)))


def test_zero_shift_is_the_plain_objective(pieces):
    args, anchor, phi, _ = pieces
    a, b = ProximalObjective(*args, Counters(), anchor=anchor, c=0.0).point(phi), Objective(*args, Counters()).point(phi)
    assert a.f == b.f and np.array_equal(a.g, b.g) and a.rel == b.rel
