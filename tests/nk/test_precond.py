"""S^{-1} inside the sparse (P1 lumped) preconditioner (issue 6): the Chebyshev polynomial and the
pyamg-CG solve against the exact LU, as operators (symmetry, spectrum, mesh symmetries) and through
whole Newton-Krylov solves."""

import numpy as np
import pytest
import scipy.linalg as sl
import scipy.sparse as sp

from vesicle_opt.nk import solve as nk
from vesicle_opt.nk import precond
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.model.functionals import evaluate
from vesicle_opt.mesh import discretize
from vesicle_opt import load_scene
from vesicle_opt.model import metric



def _mesh(n, *sets):
    sc = load_scene("ellipse-2d", ["mesh.kind='fem-p1'", f"mesh.n={n}", "mesh.mass='lumped'", *sets])
    return sc, discretize(sc)


def _inverse(disc, eps, kind):
    return precond.SparsePreconditioner(disc.K, disc.weights, eps, disc.dim, kind=kind)._S_inv


@pytest.mark.parametrize("tol", [precond.CHEB_TOL, 1e-8])
def test_chebyshev_inverse_is_symmetric_and_within_its_bound(monkeypatch, tol):
    monkeypatch.setattr(metric, "CHEB_TOL", tol)  # S^-1 is built in model.metric (nk.precond reuses it)
    sc, d = _mesh(16)
    eps = sc.model.epsilon
    S = (eps * d.K + sp.diags(2 / eps * d.weights)).toarray()
    apply = _inverse(d, eps, "chebyshev")
    B = np.column_stack([apply(e) for e in np.eye(d.n_nodes)])
    assert np.max(np.abs(B - B.T)) <= 1e-15 * np.max(np.abs(B))  # round-off (measured <= 1e-17)
    ev = sl.eigvals(B @ S).real
    # |1 - lambda p(lambda)| <= tol is rigorous (measured 5.6e-5 at 1e-3); 1e-12 allows round-off
    assert np.max(np.abs(1 - ev)) <= tol + 1e-12


@pytest.mark.parametrize("kind, level", [
    ("chebyshev", 1e-14),  # a polynomial in M^{-1} S: round-off (measured 1.2e-16)
    ("lu", 1e-14),  # exact: round-off (measured 4e-16)
    ("pyamg", 10 * precond.AMG_TOL),  # CG to AMG_TOL (measured 7e-11; 3 plain V-cycles: 3e-5 at 64^2)
])
def test_sparse_inverses_commute_with_mesh_symmetries(kind, level):
    """A shift and the transposition of the periodic 32^2 grid map the mesh's S to itself, so they
    commute with S^{-1}; an approximation that breaks this seeds symmetry breaking in the iterates."""
    n = 32
    sc, d = _mesh(n)
    apply = _inverse(d, sc.model.epsilon, kind)
    rng = np.random.default_rng(2)
    shift = lambda u: np.roll(u.reshape(n, n), (1, 3), axis=(0, 1)).ravel()  # noqa: E731
    flip = lambda u: u.reshape(n, n).T.ravel()  # noqa: E731
    for _ in range(3):
        v = rng.standard_normal(d.n_nodes)
        a = apply(v)
        for g in (shift, flip):
            assert np.linalg.norm(apply(g(v)) - g(a)) <= level * np.linalg.norm(a)


def test_pyamg_inverse_is_symmetric():
    """CG on the outer level relies on v^T B w = w^T B v; pyamg-CG to AMG_TOL keeps it to that level."""
    sc, d = _mesh(32)
    apply = _inverse(d, sc.model.epsilon, "pyamg")
    rng = np.random.default_rng(1)
    for _ in range(5):
        v, w = rng.standard_normal(d.n_nodes), rng.standard_normal(d.n_nodes)
        Bw = apply(w)
        # relative to |v| |B w|: AMG_TOL bounds it (measured 2.7e-12)
        assert abs(v @ Bw - w @ apply(v)) <= precond.AMG_TOL * np.linalg.norm(v) * np.linalg.norm(Bw)


def test_forced_pyamg_path_matches_lu(monkeypatch):
    """The 41^2 P1 ellipse (natural boundaries, h ~ eps), whose LU solution is a strict local
    minimum (reduced-Hessian eigenvalues >= 0.17; at 40^2 it is a saddle, -2.3, where 1e-10
    differences decide the end point): pyamg-CG S^{-1} against the LU (measured: the same energy
    to 1e-12, 24 Newton steps each, ~9 s)."""
    sc, _ = _mesh(41, "domain.boundary='natural'")
    lu = nk.solve(sc)
    monkeypatch.setattr(precond, "LU_MAX_NODES", {2: 0, 3: 0})
    monkeypatch.setattr(precond, "CHEB_MAX_STEPS", -1)
    amg = nk.solve(sc)
    assert lu.converged and amg.converged
    assert abs(amg.energy / lu.energy - 1) <= 1e-8  # both solved to tol 1e-8 (issue 6's agreement)
    assert amg.iterations <= 2 * lu.iterations  # same path up to the 1e-10 S^{-1}: no extra steps


def test_3d_fem_takes_chebyshev_and_matches_fd():
    """The lumped P1 tensor mesh has the FD 7-point operator, so the 16^3 torus on it, forced onto the
    sparse path of unstructured meshes (S^{-1} by the Chebyshev polynomial, the default in 3D), must
    end at the FD/FFT solution (measured 4e-12)."""
    sets = ("mesh.n=16", "mesh.mass='lumped'")
    fem = load_scene("torus-table1-3d", ["mesh.kind='fem-p1'", *sets])
    assert nk.prepare(fem, tensor_fft=False)[2].kind == "chebyshev"
    sparse = NewtonKrylovOptions.from_scene(fem, tensor_fft=False)
    r_fem, r_fd = nk.solve(fem, options=sparse), nk.solve(load_scene("torus-table1-3d", ["mesh.kind='fd'", *sets]))
    assert r_fem.extra["discretization_path"] == "sparse (chebyshev)"
    assert r_fem.converged and r_fd.converged
    assert abs(r_fem.energy / r_fd.energy - 1) <= 1e-8  # both solved to tol 1e-8 (issue 6's agreement)


def test_3d_fem_periodic_tensor_box_goes_to_fft():
    """Lumped P1 on a periodic tensor box is the FD stencil, so the backend runs it on the FFT path
    (nothing assembled) and says so; the sparse-path field's energy is the same on both operators."""
    sets = ("mesh.n=16", "mesh.mass='lumped'")
    fem = load_scene("torus-table1-3d", ["mesh.kind='fem-p1'", *sets])
    disc, _, prec, _ = nk.prepare(fem)
    assert getattr(disc, "fourier", None) is not None and isinstance(prec, precond.FourierPreconditioner)
    r_fft, r_fd = nk.solve(fem), nk.solve(load_scene("torus-table1-3d", ["mesh.kind='fd'", *sets]))
    assert r_fft.converged and r_fft.extra["discretization_path"].startswith("fft (lumped P1")
    assert r_fd.extra["discretization_path"] == "fft"
    # the same operator and the same start: the same iterates up to round-off (measured 0 to 1e-14)
    assert abs(r_fft.energy / r_fd.energy - 1) <= 1e-10
    # one field, two operators: E_h of the assembled lumped P1 and of the FFT grid agree to round-off
    # of sums of ~4e3 terms of size up to 1e2 (measured ~1e-15 relative)
    p1 = discretize(fem)
    eps, C = fem.model.epsilon, fem.model.C
    assert abs(evaluate(p1, r_fft.phi, eps, C)["E"] / evaluate(disc, r_fft.phi, eps, C)["E"] - 1) <= 1e-10


def test_gauss_newton_model_is_the_hessians_gauss_newton_part(monkeypatch):
    """P_GN of ``SparsePreconditioner.gauss_newton`` (GN_DELTA = 0) plus the Hessian's two remaining
    terms, cE diag(m r g''/eps) and cB (eps K + diag(m W''/eps)), is the matrix-free Hessian product
    (``PhaseField.hvp_operator``, a separate code path) on a field with an interface and c0 != 0, to
    round-off; its LU solve inverts it; and in the bulk (phi = -1, c0 = 0) it is the bulk model
    (cE/eps) S M_L^-1 S."""
    from vesicle_opt.model.lumped import LumpedOperators, PhaseField
    monkeypatch.setattr(precond, "GN_DELTA", 0.0)
    sc, d = _mesh(24)
    eps, cE, cB = sc.model.epsilon, 1.3, -0.4
    x, y = np.asarray(d.nodes, float).T
    phi = np.tanh((1.0 - np.hypot(x / 1.2, y / 0.8)) / (np.sqrt(2) * eps))
    pr = precond.SparsePreconditioner(d.K, d.weights, eps, d.dim, kind="lu")
    pf = PhaseField(LumpedOperators(d), eps, 0.7)
    st = pf.state(phi)
    dE_diag, dB_diag = pf.hessian_parts(st)
    H = pr.gauss_newton_matrix(st.s, cE) + sp.diags(cE * dE_diag) + cB * (eps * d.K + sp.diags(dB_diag))
    hvp = pf.hvp_operator(st, (dE_diag, dB_diag), cE, cB)
    rng = np.random.default_rng(0)
    for _ in range(3):
        v = rng.standard_normal(d.n_nodes)
        ref = hvp(v)
        assert np.linalg.norm(H @ v - ref) <= 1e-13 * np.linalg.norm(ref)  # round-off (measured 2.4e-16)
    P = pr.gauss_newton_matrix(st.s, cE, 0.5)
    r = rng.standard_normal(d.n_nodes)
    z = pr.gauss_newton(st.s, cE, 0.5)(r)
    assert np.linalg.norm(P @ z - r) <= 1e-10 * np.linalg.norm(r)  # LU: round-off times cond(P) (measured 1.3e-15)
    bulk = PhaseField(LumpedOperators(d), eps, 0.0)
    s_bulk = bulk.state(-np.ones(d.n_nodes)).s
    Mi = sp.diags(1 / np.asarray(d.weights, float))
    S = sp.csc_matrix(pr.S)
    diff = pr.gauss_newton_matrix(s_bulk, cE) - (cE / eps) * (S @ Mi @ S)
    assert abs(diff).max() <= 1e-13 * abs((cE / eps) * (S @ Mi @ S)).max()  # g'(-1) = -2/eps: the bulk model
