"""Second-order check: the ellipse minimiser is a minimum, the symmetric circle start a saddle."""

import numpy as np
import pytest

from vesicle_opt.verify import second_order as SO
import vesicle_opt as S
from vesicle_opt.nlp import build_nlp
from vesicle_opt import load_scene



@pytest.mark.parametrize("overrides", [("mesh.n=64",), ("mesh.n=32", "mesh.kind='fem-p1'", "mesh.mass='consistent'")],
                         ids=["fd", "fem-consistent"])
def test_minimiser_is_a_minimum(overrides):
    nlp = build_nlp(load_scene("ellipse-2d", [*overrides, "solver.second_order=false"]))
    res = S.solve(nlp)
    so = SO.check(nlp, res)
    # error bounds (residual on T, M^{-1} norm, mu_ref units) measured <= 4e-10: resolved
    assert so.verdict == "minimum" and so.residual < 1e-8
    assert so.relative_min_eigenvalue > 0 and so.excluded == "translations"  # both meshes periodic


def test_symmetric_start_lands_on_a_saddle_and_is_reported():
    """A circular start keeps the full symmetry: a KKT point with twice the minimum energy."""
    sc = load_scene("ellipse-2d", ["mesh.n=64", "initial.shape='circle'", "initial.radius=1.5"])
    res = S.solve(sc)
    assert res.converged and res.extra["second_order"] == "saddle"
    assert res.extra["second_order_min_eigenvalue"] < -0.1  # measured -3.2 mu_ref: far from round-off
    assert res.extra["second_order_excluded"] == "translations"
    minimum = S.solve(load_scene("ellipse-2d", ["mesh.n=64"]))
    assert minimum.extra["second_order"] == "minimum" and res.energy > 2 * minimum.energy


@pytest.mark.parametrize("sets", [("mesh.n=16", "model.epsilon=0.5"),
                                  ("mesh.n=32", "mesh.kind='fem-p1'", "initial={shape='circle', radius=1.45}")],
                         ids=["fd-16", "p1-32-saddle"])
def test_eigenvalues_match_a_dense_reduced_hessian(sets):
    """Independent check on small meshes: a dense null-space basis of the constraint rows. The P1
    saddle's least eigenvalue (-9.85) lies below a degenerate pair (-8.75) that the first shift
    (-mu_ref/2) finds first: the check must lower its shift to report it."""
    nlp = build_nlp(load_scene("ellipse-2d", [*sets, "solver.second_order=false"]))
    res = S.solve(nlp)
    assert res.converged
    so = SO.check(nlp, res, n_eig=3)
    H = SO.hessian(nlp, res.x, res.lam_g).toarray()
    m = nlp.disc.weights
    assert H.shape[0] == m.size  # lumped: no w block
    J = SO.constraint_rows(nlp, res.x, SO.translation_modes(nlp.disc, res.phi), np.diag(m)).toarray()
    # orthonormal basis Z of the tangent space in the mass metric: Z = M^{-1/2} null(J M^{-1/2})
    Jt = J / np.sqrt(m)
    _, _, Vt = np.linalg.svd(Jt)
    Z = Vt[J.shape[0]:].T / np.sqrt(m)[:, None]
    mu = np.linalg.eigvalsh(Z.T @ H @ Z)[:3]
    # the same matrix, eigensolved two ways (ARPACK tol 1e-10 vs LAPACK): agreement to ~1e-10
    assert np.allclose(so.eigenvalues, mu / (so.min_eigenvalue / so.relative_min_eigenvalue), rtol=1e-8)


def test_a_saddle_verdict_is_confirmed_by_descent():
    """Non-square periodic box, symmetric start: flagged saddle; stepping along the negative
    mode and re-solving must reach a lower energy, and that point must check as a minimum."""
    sc = load_scene("ellipse-2d", ["mesh.n=[48, 36]", "domain.box=[[-4.0, 4.0], [-3.0, 3.0]]", "solver.second_order=false"])
    nlp = build_nlp(sc)
    res = S.solve(nlp)
    so = SO.check(nlp, res)
    assert res.converged and so.verdict == "saddle"
    mode = so.lowest_mode / np.abs(so.lowest_mode).max()
    pushed = S.solve(nlp, x0=res.phi + 0.2 * mode)
    assert pushed.converged and pushed.energy < res.energy
    assert SO.check(nlp, pushed).verdict == "minimum"


@pytest.mark.parametrize("overrides", [("mesh.n=32",), ("mesh.n=16", "mesh.kind='fem-p1'")], ids=["fd", "fem-lumped"])
def test_lanczos_start_is_not_in_the_volume_constraints_normal(overrides):
    """ARPACK's shift-invert start is OPinv(M v0), which lies in the constraints' tangent space: v0 must
    have a part there. With lumped mass M^-1 grad A = ones, so ones(n) (the former start) has none: its
    start was round-off, set by the BLAS kernel and thread count (ARPACK "starting vector is zero" under
    OMP_NUM_THREADS=1). The start's M-part off ones must be nearly all of it: a standard normal vector's
    along ones is ~ 1/sqrt(n) of it (n = 1024, 256 here: <= 0.1 with margin)."""
    nlp = build_nlp(load_scene("ellipse-2d", [*overrides, "solver.second_order=false"]))
    w = np.asarray(nlp.disc.weights, float)
    n = w.size
    normal = np.ones(n)  # M^-1 grad A for A = w . phi, M = diag(w)
    for v0, off in ((SO.start_vector(n), True), (np.ones(n), False)):
        along = (w * v0) @ normal / ((w * normal) @ normal)
        rest = v0 - along * normal
        share = np.sqrt((w * rest) @ rest / ((w * v0) @ v0))
        assert bool(share > 0.9) is off, share  # ones: exactly 0 (round-off 1e-16)
    assert np.array_equal(SO.start_vector(n), SO.start_vector(n))  # deterministic
