"""E_h (6), A (7), B (8): derivatives, the two backends, and the sharp-interface relations."""

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import quad

from vesicle_opt.mesh import fd
from vesicle_opt.mesh import fem
from vesicle_opt.model import functionals as F
from vesicle_opt.nlp import build_nlp
from vesicle_opt.scene.shape_spec import Shape
from vesicle_opt.scene.shapes import phase_field
from vesicle_opt import load_scene


BOX = ((-2.0, 2.0), (-2.0, 2.0))
DISCS = {
    "fd": lambda: fd.grid(BOX, (12, 12)),
    "fem-lumped-nodal": lambda: fem.p1(BOX, (12, 12), periodic=True),
    "fem-consistent-nodal": lambda: fem.p1(BOX, (12, 12), periodic=True, mass="consistent"),
    "fem-lumped-gauss": lambda: fem.p1(BOX, (12, 12), periodic=True, quadrature="gauss"),
    "fem-consistent-gauss-natural": lambda: fem.p1(BOX, (10, 10), periodic=False, mass="consistent",
                                                   quadrature="gauss"),
    "fem-3d-natural": lambda: fem.p1(((-1.0, 1.0),) * 3, (4, 4, 4), periodic=False),
}


@pytest.mark.parametrize("name", DISCS)
def test_gradients_match_finite_differences(name, rng):
    disc = DISCS[name]()
    phi = np.tanh(rng.standard_normal(disc.n_nodes))
    v = rng.standard_normal(disc.n_nodes)
    eps, C = 0.3, 0.7
    grads = F.gradients(disc, phi, eps, C)
    for key, g in zip("EAB", grads):
        f = lambda t: F.evaluate(disc, phi + t * v, eps, C)[key]
        t = 1e-5
        fd_dir = (f(t) - f(-t)) / (2 * t)
        # central differences: O(t^2) truncation ~1e-10 relative plus round-off |f| eps_mach / t ~1e-11
        assert fd_dir == pytest.approx(g @ v, rel=1e-6, abs=1e-9), key


def test_pointwise_nonlinearities_and_their_derivatives(rng):
    """W, W', W'' and g, g', g'' (the one definition every form uses) by central differences."""
    x = rng.uniform(-1.5, 1.5, 50)
    eps, C, t = 0.3, 0.7, 1e-5
    pairs = [(F.double_well, F.double_well_derivative),
             (F.double_well_derivative, F.double_well_second_derivative),
             (lambda p: F.reaction(p, eps, C), lambda p: F.reaction_derivative(p, eps, C)),
             (lambda p: F.reaction_derivative(p, eps, C), lambda p: F.reaction_second_derivative(p, eps, C))]
    for f, df in pairs:
        fd = (f(x + t) - f(x - t)) / (2 * t)
        # cubics: truncation t^2 |f'''| / 6 ~ 1e-9, round-off |f| 1e-16 / t ~ 1e-10 (measured 9e-11)
        assert np.max(np.abs(fd - df(x))) <= 1e-7 * max(np.max(np.abs(df(x))), 1.0)
    assert np.array_equal(F.curvature_residual(x, 0 * x, eps, C), F.reaction(x, eps, C))
    # W of (8) written out: one rounding apart at most
    assert np.allclose(F.double_well(x), (x * x - 1) ** 2 / 4, rtol=1e-15, atol=0)


def _casadi_forms(disc, eps, C):
    """E_h, A, B with CasadiOps and their AD gradients; consistent mass via the dense -M^{-1} K."""
    ops = F.CasadiOps(disc)
    x = ca.MX.sym("x", disc.n_nodes)
    if disc.consistent:
        L = -np.linalg.solve(disc.M.toarray(), disc.K.toarray())
        lap = ca.mtimes(ca.DM(L), x)
    else:
        lap = ca.mtimes(ca.DM(disc.laplacian.tocsc()), x)
    outs = [F.energy(ops, x, lap, eps, C), F.volume_functional(ops, x), F.area_functional(ops, x, eps)]
    fun = ca.Function("forms", [x], outs + [ca.gradient(o, x) for o in outs])
    return lambda phi: [np.asarray(v.full()).ravel() for v in fun(phi)]


@pytest.mark.parametrize("name", DISCS)
def test_numpy_values_and_hand_gradients_equal_casadi_ad(name, rng):
    disc = DISCS[name]()
    phi = np.tanh(rng.standard_normal(disc.n_nodes))
    eps, C = 0.3, 0.7
    E, A, B, gE, gA, gB = _casadi_forms(disc, eps, C)(phi)
    vals = F.evaluate(disc, phi, eps, C)
    for key, cas in zip("EAB", (E, A, B)):
        # the same lines by numpy and CasADi (consistent: LU vs dense solve): round-off (measured 2e-15)
        assert vals[key] == pytest.approx(cas.item(), rel=1e-11), key
    for key, ours, cas in zip("EAB", F.gradients(disc, phi, eps, C), (gE, gA, gB)):
        # hand adjoint against reverse-mode AD: round-off relative to the largest entry (measured 8e-16)
        assert np.max(np.abs(ours - cas)) <= 1e-11 * np.max(np.abs(cas)), key


@pytest.mark.parametrize("overrides", [(), ("mesh.kind='fem-p1'", "mesh.mass='consistent'"),
                                       ("mesh.kind='fem-p1'", "mesh.quadrature='gauss'")],
                         ids=["fd", "fem-consistent", "fem-gauss"])
def test_casadi_graph_equals_numpy(overrides):
    """The NLP's f, g and grad f (CasADi) against the numpy definitions and hand gradients."""
    sc = load_scene("ellipse-2d", ["mesh.n=16", "model.c0=0.4", *overrides])
    nlp = build_nlp(sc)
    disc, x0 = nlp.disc, nlp.x0
    phi, _ = nlp.split(x0)
    funcs = ca.Function("fg", [nlp.x], [nlp.f, nlp.g, ca.gradient(nlp.f, nlp.x)])
    f, g, gf = (np.asarray(v).ravel() for v in funcs(x0))
    eps, C = sc.model.epsilon, sc.model.C
    vals = F.evaluate(disc, phi, eps, C)
    dE, _, _ = F.gradients(disc, phi, eps, C)
    assert f[0] * nlp.f_scale == pytest.approx(vals["E"], rel=1e-12)  # same sums, round-off only
    assert g[0] * nlp.g_scale[0] + nlp.alpha == pytest.approx(vals["A"], rel=1e-12)
    assert g[1] * nlp.g_scale[1] + nlp.beta == pytest.approx(vals["B"], rel=1e-12)
    if not disc.consistent:
        assert np.allclose(gf * nlp.f_scale, dE, rtol=1e-10, atol=1e-12 * np.abs(dE).max())
    else:  # x = (phi, w): E depends on w directly; (M w + K phi) rows vanish at x0 by construction
        assert np.abs(g[2:]).max() < 1e-9  # x0's w solves M w = -K phi to LU round-off


# --- the tanh circle against the sharp interface (Section 3.1) ------------------------------------

def _radial(R, eps):
    """A+|Omega| (= 2 x volume), B and E of the tanh circle by 1D quadrature (no mesh)."""
    phi = lambda r: np.tanh((R - r) / (np.sqrt(2) * eps))
    top = R + 40 * eps
    kw = dict(points=[R], limit=400, epsabs=0, epsrel=1e-13)
    mass = quad(lambda r: (phi(r) + 1) * 2 * np.pi * r, 0, top, **kw)[0]
    B = quad(lambda r: (1 - phi(r) ** 2) ** 2 / (2 * eps) * 2 * np.pi * r, 0, top, **kw)[0]
    # f_c = -(1 - phi^2)/(sqrt(2) r) for the tanh profile in 2D (the 1D part cancels exactly)
    # below R/4 the integrand is < exp(-2.1 R/eps) relative (<1e-9 here): cut it, avoiding r = 0
    E = quad(lambda r: (1 - phi(r) ** 2) ** 2 / (2 * r**2) / (2 * eps) * 2 * np.pi * r, R / 4, top, **kw)[0]
    return mass, B, E


def test_tanh_circle_sharp_interface_relations():
    R = 1.0
    eps_list = [R / 10, R / 20, R / 40]
    err_vol, err_E = [], []
    for eps in eps_list:
        mass, B, E = _radial(R, eps)
        # (1 - phi^2)^2 is even about r = R: the area relation is exact up to exp(-2 sqrt2 R/eps)
        assert F.surface_area(B) == pytest.approx(2 * np.pi * R, rel=1e-10)
        err_vol.append(abs(mass / 2 - np.pi * R**2) / (np.pi * R**2))
        err_E.append(abs(E - F.sharp_energy_sphere(B, 2)) / E)
    for name, err in (("volume", err_vol), ("energy", err_E)):
        order = np.polyfit(np.log(eps_list), np.log(err), 1)[0]
        # odd moments vanish, so both relations carry O(eps^2 / R^2) curvature corrections
        assert 1.9 < order < 2.1, f"{name}: observed order {order:.3f} in eps, errors {err}"


def test_mesh_functionals_converge_to_radial_values_at_h2():
    R, eps = 1.5, 0.2
    box = ((-5.0, 5.0), (-5.0, 5.0))  # tanh tail at the box edge ~1e-9: below the O(h^2) errors
    mass, B, E = _radial(R, eps)
    ns = [32, 64, 128, 256]
    errs = {"A": [], "B": [], "E": []}
    for n in ns:
        d = fd.grid(box, (n, n))
        v = F.evaluate(d, phase_field(Shape("circle", radius=R), d.nodes, box, eps), eps, 0.0)
        errs["A"].append(abs(v["A"] + d.volume - mass) / mass)
        errs["B"].append(abs(v["B"] - B) / B)
        errs["E"].append(abs(v["E"] - E) / E)
    for k, e in errs.items():
        order = -np.polyfit(np.log(ns), np.log(e), 1)[0]
        assert order > 1.8, f"{k}: observed order {order:.3f} in h, errors {e}"  # theory 2 (smooth data)


def test_sphere_energy_is_scale_free():
    """3D: E -> 16 sqrt(2) pi / 3 for any radius (the Willmore energy of a sphere is 4 pi)."""
    R, eps = 1.0, 0.1
    phi = lambda r: np.tanh((R - r) / (np.sqrt(2) * eps))
    E = quad(lambda r: (1 - phi(r) ** 2) ** 2 * 4 / (2 * r**2) / (2 * eps) * 4 * np.pi * r**2,
             0, R + 40 * eps, points=[R], limit=400)[0]
    assert E == pytest.approx(F.sharp_energy_sphere(1.0, 3), rel=3 * eps**2)  # O(eps^2/R^2) correction


def test_sparse_dm_is_casadis_own_conversion():
    """``sparse_dm`` (built from the CSC arrays) against ``casadi.DM(csc)`` on a matrix with an explicit
    zero, and on one whose row indices are unsorted: the same pattern and values, exactly."""
    import casadi as ca
    import scipy.sparse as sp

    from vesicle_opt.model.functionals import sparse_dm

    A = sp.random(50, 40, density=0.1, format="csc", random_state=1)
    A.data[0] = 0.0  # an explicit zero kept in the pattern
    B = sp.csc_matrix((A.data[::-1].copy(), A.indices.copy(), A.indptr.copy()), shape=A.shape)
    B.indices = np.concatenate([B.indices[a:b][::-1] for a, b in zip(B.indptr[:-1], B.indptr[1:])])
    B.has_sorted_indices = False
    for M in (A, B):  # casadi's own conversion of the unsorted one: from its sorted copy
        mine, ref = sparse_dm(M), ca.DM(M.sorted_indices())
        assert mine.sparsity() == ref.sparsity() and float(ca.norm_inf(mine - ref)) == 0.0
    assert sparse_dm(A).nnz() == A.nnz  # the explicit zero kept
