"""``model.band_coarse``: the interface band's coarse space on mirror grids, against independent products."""

import numpy as np
import pytest

from vesicle_opt.mesh.cosine import CosineGrid
from vesicle_opt.model import band_coarse as bc


def _b(t):
    """The quadratic B-spline, closed form."""
    t = np.abs(t)
    return np.where(t < 0.5, 0.75 - t**2, np.where(t < 1.5, 0.5 * (1.5 - t) ** 2, 0.0))


def test_quadratic_bsplines_are_a_partition_of_unity_even_about_the_mirror_plane():
    H, count = 0.5, 9
    x = np.linspace(0.0, 3.0, 301)
    cols, vals = bc.bspline_1d(x, 0.0, H, count)
    assert np.allclose(vals.sum(axis=1), 1.0, atol=1e-14)  # sum_J B(t - J) = 1, J = -1 read as its image 1
    dense = np.zeros((x.size, count))
    np.add.at(dense, (np.repeat(np.arange(x.size), 3), cols.ravel()), vals.ravel())
    t = x / H
    for J in range(count):  # column J is B(t - J) + B(t + J) (its mirror image; J = 0 is its own)
        ref = _b(t - J) + (_b(t + J) if J else 0.0)
        assert np.allclose(dense[:, J], ref, atol=1e-14), J


def _prolate_field(grid, eps):
    x, y, z = grid.nodes().T
    d = 1.0 - np.sqrt((x / 1.3) ** 2 + (y / 0.7) ** 2 + (z / 0.7) ** 2)
    return np.tanh(d / (np.sqrt(2) * eps))


def test_the_probed_galerkin_matrix_is_z_t_p_gn_z_where_one_colour_holds_one_column(monkeypatch):
    """With STRIDE past the lattice's extent every colour is one column and its cell the whole box, so
    the probing is exact: Hc equals Z^T P_GN Z from the matrix-free product (``gauss_newton``: three
    Laplacians applied to each column, no probing, no sparse algebra), to round-off."""
    eps = 0.3
    grid = CosineGrid(((0.0, 2.4), (0.0, 1.5), (0.0, 1.5)), (16, 10, 10))
    phi = _prolate_field(grid, eps)
    g_prime = -(3 * phi**2 - 1) / eps
    monkeypatch.setattr(bc, "STRIDE", 64)
    coarse = bc.BandCoarse(grid, grid.cell, eps, phi, g_prime, cE=1.3, cB=0.7).build()
    Z = coarse.Z.toarray()
    assert 20 <= Z.shape[1] < 200  # a band's worth of columns
    Hc = coarse._galerkin().toarray()
    ref = Z.T @ np.stack([coarse.gauss_newton(Z[:, j]) for j in range(Z.shape[1])], axis=1)
    ref = 0.5 * (ref + ref.T)
    # the two paths sum the same terms in other orders: round-off of |Hc| (measured 3e-15)
    assert np.max(np.abs(Hc - ref)) <= 1e-12 * np.max(np.abs(ref))
    assert np.linalg.eigvalsh(ref).min() > 0  # P_GN is positive definite, and Z has full rank


def test_the_hessians_galerkin_matrix_is_z_t_h_z_where_one_colour_holds_one_column(monkeypatch):
    """With ``hessian`` (the diagonals of ``PhaseField.hessian_parts``) and exact probing (STRIDE past
    the lattice), Hc is Z^T H Z for the model's own matrix-free Hessian product (``hvp_operator``: the
    fused grid product, no probing, no sparse algebra) at c0 != 0 and a negative cB, which it keeps
    (P_GN floors it at 0); and it is not P_GN's matrix."""
    from vesicle_opt.mesh import cosine
    from vesicle_opt.model.lumped import LumpedOperators, PhaseField
    eps, cE, cB = 0.3, 1.3, -2.5
    disc = cosine.grid(((0.0, 2.4), (0.0, 1.5), (0.0, 1.5)), (16, 10, 10))
    grid = disc.fourier
    pf = PhaseField(LumpedOperators(disc), eps, 0.7)
    st = pf.state(_prolate_field(grid, eps))
    parts = pf.hessian_parts(st)
    monkeypatch.setattr(bc, "STRIDE", 64)
    coarse = bc.BandCoarse(grid, grid.cell, eps, st.phi, st.s, cE, cB, hessian=parts).build()
    assert coarse.cB == cB
    Z = coarse.Z.toarray()
    hvp = pf.hvp_operator(st, parts, cE, cB)
    ref = Z.T @ np.stack([hvp(Z[:, j]) for j in range(Z.shape[1])], axis=1)
    assert np.max(np.abs(ref - ref.T)) <= 1e-12 * np.max(np.abs(ref))  # H is symmetric: round-off (measured 2e-16)
    ref = 0.5 * (ref + ref.T)
    Hc = coarse._galerkin().toarray()
    # the two paths sum the same terms in other orders: round-off of |Hc| (measured 2e-15)
    assert np.max(np.abs(Hc - ref)) <= 1e-12 * np.max(np.abs(ref))
    gn = bc.BandCoarse(grid, grid.cell, eps, st.phi, st.s, cE, cB)._galerkin().toarray()
    assert np.max(np.abs(gn - ref)) > 1e-2 * np.max(np.abs(ref))  # another matrix: the test can tell them apart
    r = np.random.default_rng(4).standard_normal(grid.size)
    u = coarse.factor.solve(coarse.restrict(r))
    # an LU solve of Hc: round-off times cond(Hc) (measured 6e-14)
    assert np.linalg.norm(ref @ u - coarse.restrict(r)) <= 1e-9 * np.linalg.norm(coarse.restrict(r))


def test_an_exactly_singular_hessian_galerkin_matrix_is_factored_with_p_gns_bulk_share(monkeypatch):
    """Z^T H Z may be singular (H is indefinite); where the LU finds it exactly singular the factor is
    that of Z^T (H + GN_DELTA (cE/eps) m (eps Delta_h - 2/eps)^2) Z, which is regular."""
    eps = 0.3
    grid = CosineGrid(((0.0, 2.4), (0.0, 1.5), (0.0, 1.5)), (16, 10, 10))
    phi = _prolate_field(grid, eps)
    zero = np.zeros(grid.size)
    # cE = 1 with a zero g' and diagonals, cB = 0: Hc = (1/eps) m D^T D; made singular below by the LU stub
    coarse = bc.BandCoarse(grid, grid.cell, eps, phi, zero, 1.0, 0.0, hessian=(zero, zero))
    real, calls = bc.spla.splu, []

    def splu(A):
        calls.append(A)
        if len(calls) == 1:
            raise RuntimeError("Factor is exactly singular")
        return real(A)
    monkeypatch.setattr(bc.spla, "splu", splu)
    coarse.build()
    assert len(calls) == 2
    share = coarse._bulk_share(coarse._laplacians().tocsr() - (2.0 / eps) * coarse.Z)
    expected = (coarse._galerkin() + 0.5 * (share + share.T)).toarray()
    assert np.array_equal(calls[1].toarray(), expected)


def test_the_correction_inverts_the_galerkin_matrix_on_the_coarse_space():
    eps = 0.3
    grid = CosineGrid(((0.0, 2.4), (0.0, 1.5), (0.0, 1.5)), (16, 10, 10))
    phi = _prolate_field(grid, eps)
    coarse = bc.BandCoarse(grid, grid.cell, eps, phi, -(3 * phi**2 - 1) / eps, cE=1.0, cB=0.0).build()
    y = np.random.default_rng(1).standard_normal(coarse.Z.shape[1])
    Hc = coarse._galerkin()
    # Hc (Hc^-1 Z^T r) = Z^T r: an LU solve, round-off times cond(Hc)
    r = coarse.Z @ y
    u = coarse.factor.solve(coarse.Z.T @ r)
    assert np.linalg.norm(Hc @ u - coarse.Z.T @ r) <= 1e-9 * np.linalg.norm(coarse.Z.T @ r)
    # the tensor-form restrict sums Z^T r in another order than the sparse product (measured 1e-15 of it),
    # which the solve amplifies by cond(Hc) (measured 5e3): 4e-15 of the correction measured
    assert np.linalg.norm(coarse.correction(r) - coarse.Z @ u) <= 1e-12 * np.linalg.norm(coarse.Z @ u)


@pytest.fixture(scope="module")
def octant_prolate():
    """The bench's octant prolate at eps 0.14 (54 x 24 x 24 = 31 k nodes), solved cold (~3 s)."""
    import vesicle_opt as vo
    from vesicle_opt.studies import bench_branch_3d as bb
    sc = bb.scene(0.14)
    res = vo.solve(sc)
    assert res.converged
    return sc, res


def _tangent_system(octant_prolate):
    """``nk_free.tangent``'s bordered system (fixed p, a unit step in p) at the converged octant prolate:
    (setup, VesicleKKT, lam, its Linearization, the border's cols / rows / corner, the right-hand side)."""
    from vesicle_opt.branch import nk_free as nf
    from vesicle_opt.branch.bordered import Affine
    from vesicle_opt.branch.krylov_bordered import border
    from vesicle_opt.branch.params import parameter
    from vesicle_opt.nk.setup import prepare
    sc, res = octant_prolate
    setup = prepare(sc)
    kkt = nf.VesicleKKT(setup, sc, Affine(*parameter(sc, "reduced_volume").affine(sc)))
    lam = np.array([res.lambda_volume, res.lambda_area])
    lin = kkt.at(res.phi, lam, 0.71)
    cols, rows, D = border(lin, kkt.phase(res.phi), np.zeros_like(res.phi), 1.0)
    g = np.zeros(len(rows))
    g[len(lin.G)] = 1.0
    return setup, kkt, lam, lin, (cols, rows, D), g


def test_the_coarse_space_cuts_the_bordered_gmres_count_to_the_same_solution(octant_prolate):
    """The tangent's bordered system (``nk_free.tangent``'s, fixed p) at the converged octant prolate,
    GMRES to 1e-8 with the bulk model and with the bulk model plus the band's coarse space: the same
    solution (GMRES solves the true system either way), in fewer iterations."""
    from vesicle_opt.branch.krylov_bordered import bordered_solve
    setup, kkt, lam, lin, (cols, rows, D), g = _tangent_system(octant_prolate)
    zero = np.zeros_like(octant_prolate[1].phi)
    assert isinstance(kkt._lag.held[2], bc.BandCoarse)  # the mirror grid's pinv is the two-level one
    bulk = kkt.prec.inverse(kkt.rig, -lam[1], 0.0)
    x_bulk, _, n_bulk, ok_bulk = bordered_solve(lin.hvp, bulk, cols, rows, D, zero, g, 1e-8, 2000)
    x_two, _, n_two, ok_two = bordered_solve(lin.hvp, lin.pinv, cols, rows, D, zero, g, 1e-8, 2000)
    assert ok_bulk and ok_two
    w = setup[0].weights
    # both to GMRES's 1e-8 in their own preconditioned norms: agree to ~1e-6 (measured 2e-8)
    assert np.sqrt(w @ (x_two - x_bulk) ** 2) <= 1e-6 * np.sqrt(w @ x_bulk**2)
    # measured 24 against 39 here; the gap widens with the grid (205 k nodes, eps 0.05: 32 against 133)
    assert n_two <= 0.8 * n_bulk, (n_two, n_bulk)


def test_the_hessians_galerkin_matrix_matches_the_hessian_on_the_space_and_cuts_gmres(octant_prolate):
    """``nk_free``'s coarse matrix (the Hessian's own, probed) against P_GN's on the same space at the
    converged octant prolate: the generalised eigenvalues of (Z^T H Z from k Hessian products, Hc) lie
    much closer to 1, and the tangent's bordered GMRES (five tolerances) takes fewer iterations."""
    import scipy.linalg as sl
    from vesicle_opt.branch.krylov_bordered import bordered_solve
    sc, res = octant_prolate
    setup, kkt, lam, lin, (cols, rows, D), g = _tangent_system(octant_prolate)
    hess = kkt._lag.held[2].build()
    grid, st = setup[1].ops.fourier, kkt.pf(kkt.targets(0.71)[2]).state(res.phi)
    gn = bc.BandCoarse(grid, grid.cell, sc.model.epsilon, res.phi, st.s, kkt.rig, -lam[1]).build()
    assert hess.hessian is not None and gn.Z.shape == hess.Z.shape
    Z = hess.Z.toarray()
    ZHZ = Z.T @ np.stack([lin.hvp(Z[:, j]) for j in range(Z.shape[1])], axis=1)
    ZHZ = 0.5 * (ZHZ + ZHZ.T)
    spread = {}
    for name, c in (("hessian", hess), ("gn", gn)):
        ev = sl.eigvals(ZHZ, c._galerkin().toarray()).real
        assert ev.min() > 0, name  # both positive definite on the space at this minimum (measured 0.39, 0.09)
        spread[name] = ev.max() / ev.min()
    # measured 3.6 (the probing error, 4 % of Hc) against 85 (P_GN leaves out the tension and r g'' terms)
    assert spread["hessian"] < 0.2 * spread["gn"], spread
    zero = np.zeros_like(res.phi)
    bulk = kkt.prec.inverse(kkt.rig, -lam[1], 0.0)
    counts = {name: sum(bordered_solve(lin.hvp, p, cols, rows, D, zero, g, rt, 2000)[2]
                        for rt in (1e-2, 1e-3, 1e-4, 1e-6, 1e-8))
              for name, p in (("hessian", lin.pinv), ("gn", gn.additive(bulk)))}
    # measured 62 against 72 here (5 / 8 at 1e-2); at 205 k nodes a Newton system's 1e-6 solve takes 18 against 27
    assert counts["hessian"] < counts["gn"], counts


def test_a_new_tension_refactors_the_same_space_to_the_galerkin_matrix_made_fresh():
    """Hc is affine in cB: ``with_tension`` shares the space and the products and re-factors, and its
    Hc equals a coarse space made from scratch at that cB (the same sums: round-off)."""
    eps = 0.3
    grid = CosineGrid(((0.0, 2.4), (0.0, 1.5), (0.0, 1.5)), (16, 10, 10))
    phi = _prolate_field(grid, eps)
    g_prime = -(3 * phi**2 - 1) / eps
    first = bc.BandCoarse(grid, grid.cell, eps, phi, g_prime, cE=1.3, cB=0.7).build()
    moved = first.with_tension(2.1)
    assert moved.Z is first.Z and moved.factor is None and first.cB == 0.7
    fresh = bc.BandCoarse(grid, grid.cell, eps, phi, g_prime, cE=1.3, cB=2.1)
    a, b = moved._galerkin().toarray(), fresh._galerkin().toarray()
    assert np.max(np.abs(a - b)) <= 1e-13 * np.max(np.abs(b))  # the same products and sums: round-off
    r = np.random.default_rng(2).standard_normal(grid.size)
    ref = fresh.correction(r)
    # two LU factorizations of equal matrices: round-off times cond(Hc)
    assert np.allclose(moved.correction(r), ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())
    assert bc.BandCoarse(grid, grid.cell, eps, phi, g_prime, 1.3, -4.0).with_tension(-1.0).cB == 0.0  # floored
    parts = (np.zeros(grid.size), np.ones(grid.size))
    assert bc.BandCoarse(grid, grid.cell, eps, phi, g_prime, 1.3, -4.0, parts).with_tension(-1.0).cB == -1.0  # H: kept


def test_the_lagged_factorization_is_kept_retensioned_or_made_by_the_rules():
    made, lag = [], bc.Lagged(eps=0.1, lag_g=0.3, lag_cb=0.1)
    g = np.linspace(-20.0, 10.0, 50)

    def make():
        made.append(object())
        return made[-1]

    first = lag.get(g, 1.0, make, lambda held, cB: (held, cB))
    assert first is made[0] and lag.made == 1
    assert lag.get(g + 2.9, 1.05, make, lambda held, cB: (held, cB)) is first  # eps |dg'| 0.29, cB 5 %
    moved = lag.get(g + 2.9, 1.2, make, lambda held, cB: (held, cB))  # cB 20 %: re-tensioned, not made
    assert moved == (first, 1.2) and lag.made == 1
    assert lag.get(g, 1.5, make) is made[1] and lag.made == 2  # no re-tensioning offered: made anew
    assert lag.get(g + 3.1, 1.5, make) is made[2]  # eps |dg'| 0.31 > 0.3


def test_the_tensor_form_applies_z_and_its_transpose_as_the_sparse_matrix():
    """``restrict`` / ``extend`` (d one-axis contractions) against the assembled sparse Z: the same
    sums in other orders, round-off of their size."""
    eps = 0.3
    grid = CosineGrid(((0.0, 2.4), (0.0, 1.5), (0.0, 1.5)), (16, 10, 10))
    coarse = bc.BandCoarse(grid, grid.cell, eps, _prolate_field(grid, eps), np.zeros(grid.size), 1.0, 0.0).build()
    rng = np.random.default_rng(3)
    r, y = rng.standard_normal(grid.size), rng.standard_normal(coarse.Z.shape[1])
    ref_t, ref = coarse.Z.T @ r, coarse.Z @ y
    assert np.max(np.abs(coarse.restrict(r) - ref_t)) <= 1e-13 * np.max(np.abs(ref_t))
    assert np.max(np.abs(coarse.extend(y) - ref)) <= 1e-13 * np.max(np.abs(ref))
    assert np.isclose(coarse.restrict(r) @ y, r @ coarse.extend(y), rtol=1e-12)  # adjoint pair
