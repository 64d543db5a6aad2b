"""The sharp stomatocyte branch (``sharp.stomatocyte``): the cup start, Newton's KKT point against
SLSQP's, the fold's singular Jacobian, the crossing's oblate against ``sharp.axisymmetric`` (an
independent code), and the published fold and crossing (Seifert, Berndl & Lipowsky 1991)."""

import math

import numpy as np
import pytest

from vesicle_opt.sharp import axisymmetric as A
from vesicle_opt.sharp import spontaneous as S
from vesicle_opt.sharp import stomatocyte as T


def test_cup_start_closes_and_turns_one_pole_inwards():
    """The three arcs close exactly; their sine fit (24 modes) leaves r(pi) at the fit's error
    (measured 1.8e-4: psi has corners where the arcs meet, so the sines converge like 1/N^2), and the
    north pole lies inside, above the south pole: a cup."""
    a = T.cup_start(24)
    g = S.Geometry(24)
    f, v, close = (float(np.real(q)) for q in g.all(a, 0.0))
    assert abs(close) < 1e-3  # 5x the measured fit error
    assert 0.5 < v < 0.7 and f > 2  # a cup of reduced volume 0.62; not yet relaxed (f 2.26)
    r, z, _, _ = g.shape(a)
    assert z[0].real > z[g.m // 2].real  # the inner pole above the outer one
    with pytest.raises(ValueError):
        T.cup_start(8, r_in=0.9, rho=0.5)  # arcs that cannot close


def test_newton_reaches_slsqp_point():
    """Newton on the KKT system from SLSQP's stomatocyte (16 modes, v = 0.62) stays on it (f to
    SLSQP's tolerance: both find the same stationary point) and it is asymmetric. (The oblate's
    agreement with sharp.axisymmetric, an independent code, is checked at the crossing, slow test.)"""
    sol = S.solve(0.62, 0.0, T.cup_start(16), 16)
    assert sol.converged
    p = T.newton(sol.a, 0.62, 0.0, 16)
    assert p.residual < T.TOL and p.f == pytest.approx(sol.f, abs=1e-9)  # SLSQP's KKT tolerance 1e-6, squared in f
    assert p.asymmetry > 0.5  # a cup, not an oblate (measured 2.4)
    # Newton's quadratic convergence: one more step from the converged point changes nothing
    q = T.newton(p.a, 0.62, 0.0, 16, lam0=p.lam)
    assert np.abs(q.a - p.a).max() < 1e-10  # the residual 1e-10 over the Hessian's least eigenvalue


def test_fold_of_a_parabola_in_the_multiplier():
    """A branch v = v* - a (l - l*)^2, f = f* + int l dv (df = l dv along a branch) through five
    points: ``studies._stomatocyte.fold_of`` gives v* exactly (a parabola) and f* up to the cubic
    term of f(l), (2a/3) dl^3 / ... (measured 3e-4 of dl^3 here)."""
    from vesicle_opt.studies._stomatocyte import fold_of
    vs, fs, a = 0.66, 1.96, 3.0
    for dl in (0.1, 0.05):
        lam = 0.5 + dl * np.arange(-2, 3) + 0.3 * dl
        x = lam - 0.5
        v = vs - a * x**2
        f = fs - 2 * a * (x**3 / 3 + 0.5 * x**2 / 2)
        fv, ff = fold_of(v, f, lam)
        assert fv == pytest.approx(vs, abs=1e-13)
        assert abs(ff - fs) < 2 * a * dl**3  # the cubic term over the three points


@pytest.mark.slow  # 40 s at load 2 (150 s at load 9): the continuation through the fold and the crossing's secant at 24 modes
def test_fold_and_crossing_against_the_published_values():
    """24 modes: fold (0.66038, 1.96331), crossing (0.59026, 1.98116); Seifert, Berndl & Lipowsky
    read (0.66, 1.96) and (0.59, 1.96-2.0) (+-0.005 in v, +-0.01 in f)."""
    ref = T.reference(0.0, 24, ds=0.05)
    (vf, ff), (vx, fx) = ref["fold"], ref["crossing"]
    assert vf == pytest.approx(0.66, abs=0.005) and ff == pytest.approx(1.96, abs=0.01)
    assert vx == pytest.approx(0.59, abs=0.005) and 1.96 - 0.01 < fx < 2.0 + 0.01
    # the fold is v's maximum along the branch, f's there the upper side's and lower side's meeting
    assert vf >= max(v for v, _ in ref["lower"] + ref["upper"]) - 1e-12
    # at the crossing the oblate from sharp.axisymmetric (independent code) has the same f
    o = A.solve(vx, "oblate", 12, second_order=False)
    assert o.reduced_energy == pytest.approx(fx, abs=1e-6)  # 24 modes' error at this v (N=24 vs 12: ~1e-7)
    assert math.isfinite(ref["up_walk"][0][2])


@pytest.mark.slow  # 64 s at load 2 (700 s at load 10): the oblate scan, the branch point's secant, the switched branch to its fold
def test_switching_at_the_oblate_branch_point_reaches_the_stomatocyte():
    """No seed: the oblate's least odd eigenvalue changes sign near v = 0.51 (the literature's
    branch point); stepping off along its eigenvector and continuing up in v reaches the fold of
    the branch that the cup start reaches (the same (v, f) to the continuation's accuracy)."""
    from vesicle_opt.sharp import stomatocyte_switch as W
    out = W.stomatocyte_by_switching((0.6, 0.55, 0.5), 0.0, 24)
    v_bp, f_bp = out["branch_point"]
    assert v_bp == pytest.approx(0.51, abs=0.005)  # measured 0.51044 (f 2.19287)
    assert out["scan"][0][1] > 0 > out["scan"][-1][1]
    # the fold of reference(0.0, 24) from the cup start: (0.6603760379079, 1.9633077520607); the same
    # branch and discretisation: measured 6e-14 apart, here allowed the fold secant's tolerance on t_v
    assert out["fold"][0] == pytest.approx(0.6603760379079, abs=1e-9)
    assert out["fold"][1] == pytest.approx(1.9633077520607, abs=1e-9)
