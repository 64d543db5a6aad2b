"""The LDL^T of the shift-invert matrix with its analysis kept per pattern (``verify.ldl``): a reused
analysis gives the fresh factorisation's solves bitwise and SuperLU's to round-off; a stale factor
refuses to solve; an LDL^T that cannot pivot falls back to the LU; and the assembled check through
it (``verify.second_order``) reports the LU path's eigenvalues to round-off, a saddle still a saddle."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import vesicle_opt as S
from vesicle_opt import load_scene
from vesicle_opt.nlp import build_nlp
from vesicle_opt.verify import ldl
from vesicle_opt.verify import second_order as SO
from vesicle_opt.verify import shift_invert as SI

pytestmark = pytest.mark.skipif(not ldl.available(), reason="the optional extra 'ldl' (qdldl) is not installed")


def _problem(n=300, seed=0):
    rng = np.random.default_rng(seed)
    lap = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    H = (lap @ lap * n**2 + sp.diags(rng.random(n))).tocsc()  # a bi-Laplacian (both triangles stored)
    return H, 1 + rng.random(n)


def test_a_reused_analysis_gives_the_fresh_factors_bitwise():
    H, m = _problem()
    b = np.random.default_rng(1).standard_normal(H.shape[0])
    ldl.clear()
    fresh = ldl.factor(H, m, -5.0).solve(b)  # the analysis and the numeric factors, first time
    stale = ldl.factor(H, m, -7.0)
    assert len(ldl._CACHE) == 1  # one pattern: the second shift reused its analysis
    again = ldl.factor(H, m, -5.0)  # numeric only, on the kept ordering and elimination tree
    assert np.array_equal(again.solve(b), fresh)  # the same code on the same permuted values
    ref = spla.spsolve((H + 5.0 * sp.diags(m)).tocsc(), b)
    # two backward-stable solves of one SPD system (condition ~1e9 here): 1e-6 relative
    assert np.abs(fresh - ref).max() < 1e-6 * np.abs(ref).max()
    with pytest.raises(RuntimeError, match="stale"):
        stale.solve(b)  # its pattern holds the -5 factors now: refused, not answered for another matrix


def test_another_pattern_gets_its_own_analysis():
    H, m = _problem()
    H2 = (H + sp.csc_matrix(([1.0, 1.0], ([0, 299], [299, 0])), shape=H.shape)).tocsc()  # a periodic link
    b = np.ones(H.shape[0])
    ldl.clear()
    ldl.factor(H, m, -1.0)
    x = ldl.factor(H2, m, -1.0).solve(b)
    assert len(ldl._CACHE) == 2
    r = H2 @ x + m * x - b
    assert np.linalg.norm(r) < 1e-9 * np.linalg.norm(b)  # backward stable: condition x eps far below this


def test_an_ldl_that_cannot_pivot_falls_back_to_the_lu():
    n = 40  # H = blocks [[0, 1], [1, 0]] (eigenvalues +-1), zero diagonal: the first pivot of LDL^T is 0
    H = sp.kron(sp.eye(n // 2), sp.csr_matrix([[0.0, 1.0], [1.0, 0.0]])).tocsc()
    C = np.column_stack([np.ones(n), np.linspace(-1, 1, n)])
    ldl.clear()
    out = SI.factorise(H, sp.eye(n), 0.0, C)
    assert out is not None and type(out.lu).__name__ == "SuperLU"
    b = np.random.default_rng(2).standard_normal(n)
    K = sp.bmat([[H, sp.csr_matrix(C)], [sp.csr_matrix(C.T), None]], format="csc")
    ref = spla.spsolve(K, np.concatenate([b, np.zeros(2)]))[:n]
    assert np.abs(out.solve(b) - ref).max() < 1e-12 * np.abs(ref).max()  # condition ~10: round-off


@pytest.mark.parametrize("sets, verdict", [(("initial={shape='circle', radius=1.45}",), "saddle"),
                                           (("model.epsilon=0.5",), "minimum")],
                         ids=["p1-32-saddle", "p1-32-minimum"])
def test_the_check_through_the_ldl_reports_the_lu_eigenvalues(sets, verdict, monkeypatch):
    """Lumped P1 (the Schur path of ``shift_invert``): the saddle's least eigenvalue lies below the
    first shift, so the LDL^T is refactorised at a second shift on the same analysis."""
    nlp = build_nlp(load_scene("ellipse-2d", ["mesh.n=32", "mesh.kind='fem-p1'", *sets, "solver.second_order=false"]))
    res = S.solve(nlp)
    assert res.converged
    used = []
    real = SI._tested
    monkeypatch.setattr(SI, "_tested", lambda solver, *a: used.append(real(solver, *a)) or used[-1])
    new = SO.check(nlp, res)
    # every shift through the LDL^T (it passed its test), the saddle at two: -mu_ref/2, then below -9.85
    assert [type(b.lu).__name__ for b in used] == ["Factor"] * (2 if verdict == "saddle" else 1)
    real_si = SI.factorise
    monkeypatch.setattr(SI, "factorise", lambda *a, **k: real_si(*a, ldl_first=False))
    old = SO.check(nlp, res)
    assert new.verdict == old.verdict == verdict
    # one pencil's eigenvalues through two factorisations: apart by round-off, below the check's own
    # error bound (here its floor eps ||M^-1 H||, 1.3e-12 mu_ref at the saddle; measured 6e-14 apart)
    assert np.abs(np.subtract(new.eigenvalues, old.eigenvalues)).max() < new.residual


def test_a_large_factor_is_not_kept(monkeypatch):
    H, m = _problem()
    ldl.clear()
    monkeypatch.setattr(ldl, "KEEP_FILL", 10)  # every factor is "large" (this one has ~600 nonzeros)
    f = ldl.factor(H, m, -1.0)
    assert ldl._CACHE == []
    b = np.ones(H.shape[0])
    assert np.linalg.norm(H @ f.solve(b) + m * f.solve(b) - b) < 1e-9 * np.linalg.norm(b)  # still solves
