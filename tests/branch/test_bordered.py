"""The bordered (Keller) corrector with p free on a vesicle (``branch.bordered``): from a secant
prediction it lands on the arclength hyperplane at a p of its own, and that point is a KKT point
of the fixed-p problem: the hand-derived KKT residual (``verify.kkt``, no CasADi) is at round-off,
and IPOPT at that p, started there, stops at once with the common certificate. In the reduced
volume (alpha moves) and in c0 (C moves: the explicit p column of the Jacobian)."""

import numpy as np
import pytest

from vesicle_opt.branch import branch
from vesicle_opt.branch.bordered import Affine, BorderedCorrector
from vesicle_opt.branch.corrector import IpoptCorrector
from vesicle_opt.branch.params import parameter
from vesicle_opt.io.files import load_npz
from vesicle_opt.scene.schema import from_dict
from vesicle_opt.verify.kkt import kkt_residual


# shape_check off: this toy (eps = 0.5, perimeter 8: eps/R0 = 0.4) is a circle whose bulk carries
# 27-38 % of the volume at every nu (verify.shape: wrong_shape); the tests here check the branch's
# machinery on its KKT points; tests/branch/test_run.py::test_a_wrong_shape_stops_the_branch the check
_RAW = {"domain": {"box": [[-4.0, 4.0], [-4.0, 4.0]], "boundary": "periodic"},
        "mesh": {"kind": "fd", "n": 32}, "model": {"epsilon": 0.5},
        "constraints": {"reduced_volume": 0.95, "area": 8.0},
        "initial": {"shape": "ellipse", "semi_axes": [1.45, 1.1]},
        "solver": {"method": "exact", "tol": 1e-8, "second_order": False, "max_iter": 60, "shape_check": False}}


def scene():
    return from_dict(_RAW, "small-2d")



@pytest.mark.parametrize("name, p1", [("reduced_volume", 0.925), ("c0", 0.2)])
def test_the_bordered_point_is_a_fixed_p_kkt_point(name, p1):
    sc = scene()
    par = parameter(sc, name)
    corr = IpoptCorrector(sc)
    a = corr.solve(sc, corr.nlp.x0)
    b = corr.solve(par.scene_at(sc, p1), a.phi, (a.lambda_volume, a.lambda_area))
    assert a.converged and b.converged
    w = corr.disc.weights
    # the secant tangent in the arclength metric theta^2 <.,.>_w + dp^2 (theta as branch.arclength)
    dphi, dp = b.phi - a.phi, p1 - par.start
    theta = abs(dp) / np.sqrt(w @ dphi**2)
    length = np.hypot(theta * np.sqrt(w @ dphi**2), dp)
    t_phi, t_p = dphi / length, dp / length
    ds = length
    phi_pred, p_pred = b.phi + ds * t_phi, p1 + ds * t_p
    bordered = BorderedCorrector(corr.scene, corr.disc, Affine(*par.affine(sc)))
    nw = bordered.solve(phi_pred, p_pred, (b.lambda_volume, b.lambda_area), t_phi, t_p, theta)
    assert nw.converged and nw.iterations <= 20, nw  # Newton and chord steps from the secant (measured 5 in nu, 11 in c0)
    N = theta**2 * w @ ((nw.phi - phi_pred) * t_phi) + (nw.p - p_pred) * t_p
    assert abs(N) < 1e-12 * ds  # on the hyperplane to round-off (a linear row of the system)
    assert abs(nw.p - p_pred) > 1e-6 * ds  # p moved off the prediction: it is an unknown
    at = par.scene_at(sc, nw.p)
    kkt = kkt_residual(corr.disc, nw.phi, at.model.epsilon, at.model.C, at.model.rigidity, *nw.lam)
    assert kkt < 1e-10, kkt  # stationarity at round-off (relative L2; measured 1.8e-12, 1.2e-13), far below tol 1e-8
    res = corr.solve(at, nw.phi, nw.lam)
    assert res.converged and res.iterations <= 1, (res.iterations, res.reason)  # already a KKT point (measured 0)
    assert np.sqrt(w @ (res.phi - nw.phi) ** 2) < 1e-6 * np.sqrt(w @ nw.phi**2)  # IPOPT did not move it


def test_newton_at_fixed_p_finds_the_ipopt_point():
    """The fallback of the IPOPT corrector (``BorderedCorrector.fixed``): Newton at fixed nu from the
    previous point lands on the point IPOPT finds there (two solvers, one KKT point)."""
    sc = scene()
    par = parameter(sc, "reduced_volume")
    corr = IpoptCorrector(sc)
    a = corr.solve(sc, corr.nlp.x0)
    at = par.scene_at(sc, 0.925)
    b = corr.solve(at, a.phi, (a.lambda_volume, a.lambda_area))
    nw = BorderedCorrector(corr.scene, corr.disc, Affine(*par.affine(sc))).fixed(a.phi, 0.925,
                                                                                   (a.lambda_volume, a.lambda_area))
    assert nw.converged and nw.p == 0.925
    w = corr.disc.weights
    gap = np.sqrt(w @ (nw.phi - b.phi) ** 2) / np.sqrt(w @ b.phi**2)
    assert gap < 1e-8, gap  # IPOPT stops at tol 1e-8 on the scaled gradient (measured gap 1e-12: its last step is Newton too)
    assert nw.lam == pytest.approx((b.lambda_volume, b.lambda_area), rel=1e-8)  # measured 1e-11


def test_a_branch_walked_by_arclength_with_p_free_meets_the_natural_one():
    """``turn`` above 1 makes every step after the first a pseudo-arclength step with p free
    (``branch.run``: bordered Newton, then IPOPT at its p): the points are certified, lie on their
    hyperplanes, and the end point (a natural step onto nu = 0.85) is the natural walk's."""
    sc = scene()
    free = branch(sc, "reduced_volume", to=0.85, step=-0.025, turn=1.01)
    natural = branch(sc, "reduced_volume", to=0.85, step=-0.025)
    pts = free.points()
    assert free.stopped == {0: "reached"} and all(r["converged"] for r in pts)
    arcs = [r for r in pts if r["corrector"] == "arclength"]
    assert len(arcs) >= 2 and all(abs(r["arc_condition"]) < 1e-10 for r in arcs)  # measured <= 1e-15
    assert pts[-1]["target"] == natural.points()[-1]["target"] == 0.85
    # two certified KKT points at tol 1e-8 (measured 1e-10 relative)
    assert pts[-1]["energy"] == pytest.approx(natural.points()[-1]["energy"], rel=1e-8)


@pytest.mark.slow
def test_a_vesicle_branch_is_followed_through_its_turning_point_in_c0(tmp_path):
    """The 48^2 (eps = 0.4) branch in c0 from the nu = 0.95 ellipse turns back at c0 ~ 0.687: the
    walk, pseudo-arclength with p free there, goes through it; p rises then falls, every point
    certified at its own c0 (measured: the top at point 119, c0 = 0.68740, least eigenvalue
    1.7e-5 mu_ref there, positive on both sheets). The returning sheet is the forward one reflected
    in the diagonal (the shape turns from the x axis towards the diagonal, a lattice-orientation
    family of this coarse grid, eps / h = 2.4): at equal c0 the fields are transposes."""
    b = branch(from_dict({**_RAW, "mesh": {"kind": "fd", "n": 48}, "model": {"epsilon": 0.4},
                          "solver": {**_RAW["solver"], "second_order": True}}, "c0-48"),
               "c0", to=1.5, step=0.02, max_points=135, out=tmp_path / "b", snapshots=False)
    pts = b.points()
    assert all(r["converged"] for r in pts)
    p = np.array([r["target"] for r in pts])
    top = int(np.argmax(p))
    assert 0 < top < len(p) - 5 and 0.6 < p[top] < 0.8, (top, p[top])  # a turning point inside the walk
    assert np.all(np.diff(p[top:]) < 0) and p[-1] < p[top] - 1e-3  # then p falls
    assert any(r["corrector"] == "arclength" for r in pts[top - 3: top + 3])  # passed with p free
    shape = (48, 48)
    k = top - 10
    j = min(range(top, len(pts)), key=lambda i: abs(p[i] - p[k]))
    fwd, back = (load_npz(tmp_path / "b" / "points" / f"point-{int(pts[i]['point']):04d}.npz")["phi"].reshape(shape)
                 for i in (k, j))
    # the sheets: mirror images (measured |back - fwd^T| 8e-4 at |dc0| 3e-5, |back - fwd| 0.16)
    assert np.abs(back - fwd.T).max() < 0.1 * np.abs(back - fwd).max()
