"""The branch's IPOPT corrector built once (``branch.corrector``): a point of the parametric NLP is
the front door's point; its second-order check (matrix-free, the rotation kept as on every grid)
against the assembled shift-invert check; the rotation-modulo verdict (a study's option)."""

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt.branch.corrector import IpoptCorrector, rotation_modulo
from vesicle_opt.branch.params import parameter
from vesicle_opt.nlp import build_nlp
from vesicle_opt.verify import second_order
from vesicle_opt.verify import verdict as V
from vesicle_opt.verify.verdict import SecondOrder

from vesicle_opt.scene.schema import from_dict


def scene(n=48, eps=0.4, second_order=True):
    """A vesicle of perimeter 8 in a periodic 8 x 8 box, nu = 0.95, an ellipse start (as test_run)."""
    return from_dict({"domain": {"box": [[-4.0, 4.0], [-4.0, 4.0]], "boundary": "periodic"},
                      "mesh": {"kind": "fd", "n": n}, "model": {"epsilon": eps},
                      "constraints": {"reduced_volume": 0.95, "area": 8.0},
                      "initial": {"shape": "ellipse", "semi_axes": [1.45, 1.1]},
                      "solver": {"method": "exact", "tol": 1e-8, "second_order": second_order, "max_iter": 60}},
                     "small-2d")


@pytest.fixture(scope="module")
def point():
    """The 48^2 elastica scene (eps = 0.4) at nu = 0.9: the corrector's point (from the start's
    field, warm multipliers from the start) and the front door's (cold)."""
    sc = scene(n=48, eps=0.4, second_order=True)
    par = parameter(sc, "reduced_volume")
    corr = IpoptCorrector(sc)
    start = corr.solve(sc, corr.nlp.x0)
    at = par.scene_at(sc, 0.9)
    res = corr.solve(at, start.phi, (start.lambda_volume, start.lambda_area))
    return sc, at, corr, start, res, vo.solve(at, x0=start.phi)


def test_the_parametric_point_is_the_front_doors(point):
    sc, at, corr, start, res, ref = point
    assert start.converged and res.converged and ref.converged
    assert res.iterations <= 6  # warm, the rotation held: measured 5 (the front door from the same field, cold: 4)
    # two certified KKT points of the same NLP at tol 1e-8: energies and multipliers agree to the
    # solver tolerance (measured 9e-10 and 1e-8 relative: different iterates within tol)
    assert res.energy == pytest.approx(ref.energy, rel=1e-7)
    assert res.lambda_volume == pytest.approx(ref.lambda_volume, rel=1e-5)
    assert res.lambda_area == pytest.approx(ref.lambda_area, rel=1e-5)
    assert abs(res.extra["reduced_volume"] - 0.9) < 1e-6  # A = alpha to tol relative to |Omega|
    # the warm solve held the orientation (corrector.pinned): the row's multiplier vanishes at this
    # symmetric shape (measured 1.9e-11 against lam_g ~ 700: round-off), so the point is unpinned KKT
    assert abs(res.extra["rotation_multiplier"]) < 1e-9 * np.max(np.abs(res.lam_g))


def test_the_branch_check_against_the_assembled_one(point):
    """The assembled check (shift-invert Lanczos) and the branch's matrix-free LOBPCG both exclude the
    translations only and keep the rotation (``verify.verdict``: no grid in a periodic box has it as a
    symmetry): both find the soft rotation mode as the least eigenvalue, at the same number, and
    report the rotation generator's Rayleigh quotient beside it. Two eigensolvers sharing no code
    (sparse LU + ARPACK vs FFT + LOBPCG)."""
    sc, at, corr, start, res, ref = point
    assembled = second_order.check(build_nlp(at), res)
    ev = np.array(assembled.eigenvalues)
    assert res.extra["second_order_excluded"] == assembled.excluded == V.TRANSLATIONS
    assert res.extra["second_order"] == assembled.verdict
    rot = res.extra["rotation_rayleigh"]
    # the generator's quotient lies at or above the least eigenvalue (Courant-Fischer) and is the
    # assembled check's own (the same direction, the same Hessian; measured agreement ~1e-9)
    assert ev[0] <= rot + 1e-9 and rot == pytest.approx(assembled.rotation_rayleigh[0], rel=1e-6), (ev, rot)
    # LOBPCG's least = the assembled least (error bounds ~1e-4, Kato-Temple: eigenvalue error ~1e-8)
    assert res.extra["second_order_min_eigenvalue"] == pytest.approx(ev[0], abs=1e-6), ev


def _so(mu, rayleigh, excluded=V.TRANSLATIONS_ROTATIONS):
    return SecondOrder("saddle", mu, mu, (mu,), tuple(rayleigh), 1e-9, excluded=excluded, errors=(1e-9,))


def test_the_verdict_is_modulo_the_rotation_only():
    assert rotation_modulo(_so(1.8, (1e-11, 2e-11, -3e-4)), 2).verdict == "minimum"  # the grid's rotation
    assert rotation_modulo(_so(1.8, (-1e-3, 2e-11, -3e-4)), 2).verdict == "saddle"  # a translation: not removed
    assert rotation_modulo(_so(-0.5, (1e-11, 2e-11, 3e-4)), 2).verdict == "saddle"  # a shape mode below zero
    kept = _so(1.8, (-1e-3, -1e-3), excluded=V.TRANSLATIONS)  # rotations not excluded: unchanged
    assert rotation_modulo(kept, 2) is kept
