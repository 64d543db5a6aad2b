"""Deflation on the Newton-Krylov path (``branch.deflation`` on ``branch.krylov_bordered``'s
matrix-free bordered GMRES Newton): the closed-form two-root problem, a vesicle's second certified
KKT point on a 2D spectral grid, and ``--deflate`` refused where no deflated corrector exists."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from vesicle_opt.branch import branch
from vesicle_opt.branch import deflation
from vesicle_opt.branch import krylov_bordered as kb
from vesicle_opt.branch.symmetry import align
from vesicle_opt.errors import InputError
from vesicle_opt.scene.schema import from_dict

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_krylov_bordered import FoldModel  # noqa: E402
from test_run import raw_scene  # noqa: E402


def test_deflated_krylov_newton_finds_the_other_root():
    """grad E = (x^2 - p, y - 1) at p = 1 (``FoldModel``: the toy's fold, roots (+-1, 1)): from
    x = 0.5 the bordered GMRES Newton goes to the root (1, 1); deflated by it, the same iteration
    (the undeflated GMRES step rescaled, Sherman-Morrison) goes to (-1, 1), to the Newton tolerance.
    (From x = 1.5 the deflated step +1.25 is cut to ``STEP_CAP`` = 1, a cap for phi in [-1, 1], and
    the iteration cycles 1.5 <-> 2.5: the cap is the vesicle's, the start here one it does not bind.)"""
    model, w = FoldModel(), np.ones(2)
    u0 = np.array([0.5, 1.0])
    plain = kb.newton(model, u0, (), 1.0, np.zeros(2), 1.0, 0.0, w, 1e-13)
    assert plain.converged and np.allclose(plain.phi, [1.0, 1.0], atol=1e-12)  # |r| <= 1e-13: x to 1e-13 / 2
    known = [plain.phi]
    hook = lambda phi, d: deflation.factor(phi, d, known, w)  # noqa: E731
    other = kb.newton(model, u0, (), 1.0, np.zeros(2), 1.0, 0.0, w, 1e-13, max_newton=60, deflation=hook)
    assert other.converged and abs(other.p - 1.0) == 0.0  # p held (t_p = 1, the hyperplane row)
    assert np.allclose(other.phi, [-1.0, 1.0], atol=1e-12)  # the second root, to Newton's tolerance
    # the same root from the dense deflated Newton (an independent linear solve: LU)
    u, ok, _ = deflation.newton(lambda u: model.at(u, (), 1.0).r, lambda u: np.diag([2 * u[0], 1.0]), u0, known, w)
    assert ok and np.abs(u - other.phi).max() <= 1e-12


def test_deflate_is_refused_before_any_work_where_there_is_no_deflated_corrector(tmp_path):
    """IPOPT with consistent mass (FEM) has no bordered fixed-p Newton: --deflate there is bad input,
    not a silent "none found" (nothing written)."""
    raw = raw_scene()
    raw["mesh"] = {"kind": "fem-p1", "n": 8, "mass": "consistent"}
    sc = from_dict(raw, "fem")
    with pytest.raises(InputError, match="--deflate"):
        branch(sc, "reduced_volume", to=0.9, step=-0.05, deflate=1, backend="ipopt", out=tmp_path / "o")
    assert not (tmp_path / "o").exists()


def test_nk_deflation_finds_a_second_certified_point_on_a_spectral_grid(tmp_path):
    """The circle start on the 48^2 spectral grid (Newton-Krylov) converges to the symmetric saddle;
    deflated by it, the bordered GMRES Newton from the scene's start field comes within ``NEAR_ROOT`` of
    another KKT point at nu = 0.95 (whatever the BLAS kernel: ``.ci/run``), which the fixed-p solve finishes, certified by the fixed-p Newton-Krylov solve with the one certificate: a minimum up
    to the rotation's flat mode (the elastica, as IPOPT's FD deflation finds; measured reduced
    energy 1.8648 against the saddle's 1.9582), far from the saddle and its images."""
    raw = raw_scene(n=48, eps=0.4, second_order=True, initial={"shape": "circle", "radius": 1.27})
    raw["mesh"]["kind"] = "spectral"
    sc = from_dict(raw, "circle-spectral")
    b = branch(sc, "reduced_volume", to=0.925, step=-0.025, deflate=1, backend="newton-krylov", max_points=2,
               out=tmp_path / "d")
    root, other = b.points(0)[0], b.points(1)[0]
    assert root["second_order"] == "saddle" and b.parents == {0: None, 1: None}
    assert other["corrector"] == "deflation" and other["converged"] and other["target"] == 0.95
    assert other["second_order"] in ("minimum", "marginal")  # index 0 (the rotation flat: marginal)
    assert other["topology"] == root["topology"] == "disk-like"
    # certified (converged: the one certificate); the fixed-p solve that finishes the deflated Newton's
    # best iterate (``deflation.NEAR_ROOT``) stops at its own test: measured 2.2e-8 at tol 1e-8
    assert other["kkt_residual"] <= 1e-7
    assert root["energy"] - other["energy"] > 1e-2 * root["energy"]  # another point: 4.8 % lower, not round-off
    assert all(r["converged"] for r in b.points(1))
    # distinct from the saddle and each of its grid images (translations, the square's group) by far
    # more than the radius within which a root counts as known (deflation.SAME |phi|_w)
    phi0, phi1 = b.field(root["point"])["phi"], b.field(other["point"])["phi"]
    w = np.full(phi0.size, (8.0 / 48) ** 2)
    near = align(phi0, phi1, (48, 48), [[-4.0, 4.0], [-4.0, 4.0]])
    dist = math.sqrt(float(w @ (near - phi1) ** 2)) / math.sqrt(float(w @ phi1**2))
    assert dist > 10 * deflation.SAME  # measured 0.13 (SAME = 1e-3)
