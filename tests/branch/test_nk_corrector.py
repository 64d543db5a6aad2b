"""``branch.nk_corrector``: a Newton-Krylov branch warm from point to point gives the points and the
verdicts of cold runs: every point certified, each warm second-order check agreeing with a cold
check of the same point on the verdict and on mu_min within the two reported error bounds, and a
warm solve landing on the front door's (cold) point."""

import dataclasses

import numpy as np
import pytest

from vesicle_opt import solve
from vesicle_opt.branch import branch
from vesicle_opt.branch import nk_corrector as nc
from vesicle_opt.branch.params import parameter
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.scene.schema import from_dict
from vesicle_opt.studies import energy_diagram as ed
from vesicle_opt.verify import lobpcg
from vesicle_opt.verify.verdict import TOL_REL


def scene_2d(n=64):
    raw = {"domain": {"box": [[-4.0, 4.0], [-4.0, 4.0]], "boundary": "periodic"},
           "mesh": {"kind": "spectral", "n": n}, "model": {"epsilon": 0.3},
           "constraints": {"reduced_volume": 0.9, "area": 8.0},
           "initial": {"shape": "ellipse", "semi_axes": [1.45, 1.1]},
           "solver": {"method": "exact", "tol": 1e-8, "second_order": True, "max_iter": 200,
                      "backend": "newton-krylov"}}
    return from_dict(raw, "nk-branch-2d")


def _checked_branch(monkeypatch, sc, to, step, max_points=200):
    """The branch, and per second-order check (warm used, its SecondOrder, a cold SecondOrder of the
    same point, computed here on the side)."""
    seen = []
    check = nc.NewtonKrylovCorrector.check

    def recording(self, scene, res, setup, prev):
        so, used = check(self, scene, res, setup, prev)
        seen.append((used, so, lobpcg.check(scene, res, setup, rotations=self.rotations)))
        return so, used
    monkeypatch.setattr(nc.NewtonKrylovCorrector, "check", recording)
    b = branch(sc, "reduced_volume", to=to, step=step, max_points=max_points, switch=False)
    return b, seen


def _assert_agree(b, seen, verdicts=("minimum", "saddle", "marginal")):
    pts = b.points()
    assert all(r["converged"] and r["second_order"] in verdicts for r in pts), [r["second_order"] for r in pts]
    warm = [(so, cold) for used, so, cold in seen if used]
    assert warm, "no warm check ran: the test would assert nothing"
    for so, cold in warm:
        assert so.verdict == cold.verdict
        # both Ritz values are within their own error bound of the least eigenvalue (Bauer-Fike)
        assert abs(so.relative_min_eigenvalue - cold.relative_min_eigenvalue) <= so.errors[0] + cold.errors[0], \
            (so.relative_min_eigenvalue, cold.relative_min_eigenvalue, so.errors[0], cold.errors[0])


def test_warm_checks_agree_with_cold_ones_2d(monkeypatch):
    """64^2 spectral, eps = 0.3 (one coarse level, 40^2, whose start the warm check takes from the
    previous point): seven points nu 0.9 -> 0.8, every warm check against a cold one."""
    b, seen = _checked_branch(monkeypatch, scene_2d(), 0.8, -0.02)
    assert b.stopped == {0: "reached"}
    # every point "marginal": the rotation stays in the check (``verify.verdict``), and on this
    # spectral grid its mode is flat to within the sign tolerance (measured |mu_min| 2e-8 .. 1.2e-7
    # mu_ref), while the rotation generator's own quotient is positive (measured 3.6e-5 .. 4.5e-5)
    _assert_agree(b, seen, ("marginal",))
    for r in b.points():
        assert abs(r["second_order_min_eigenvalue"]) < TOL_REL and r["rotation_rayleigh"] > 0


@pytest.mark.slow
def test_warm_checks_agree_with_cold_ones_3d_prolate(monkeypatch):
    """The study's coarsest 3D case (prolate, eps = 0.2, fitted 90 x 36 x 36 box; ~4 s a point): four
    points from v = 0.75, every warm check against a cold one (two coarse levels)."""
    case = next(c for c in ed.cases(False) if c["case"] == "prolate-3d-eps0.2")
    b, seen = _checked_branch(monkeypatch, ed.scene(case), case["to"], case["step"], max_points=4)
    assert len(b.points()) == 4
    _assert_agree(b, seen)


def test_warm_solve_lands_on_the_cold_point():
    """One warm solve (the previous point's multipliers and dual model) against the front door from
    the same start: the same KKT point to the certificate's tolerance."""
    sc0 = scene_2d()
    par = parameter(sc0, "reduced_volume")
    corr = nc.NewtonKrylovCorrector(sc0)
    first = corr.solve(sc0, None)
    assert first.converged and corr.warm[0].dual_model is not None
    sc1 = par.scene_at(sc0, 0.88)
    warm = corr.solve(sc1, first.phi, (first.lambda_volume, first.lambda_area))
    cold = solve(sc1, x0=first.phi)
    assert warm.converged and cold.converged
    # both KKT points to tol = 1e-8 (relative dual and constraint residuals): their energies agree
    # to O(tol) (measured 2.3e-9 relative), multipliers to ~tol / mu_min (measured 7e-10)
    assert abs(warm.energy - cold.energy) <= 1e-8 * abs(cold.energy)
    assert abs(warm.lambda_area - cold.lambda_area) <= 1e-6 * abs(cold.lambda_area)
    assert warm.extra["second_order"] == cold.extra["second_order"]
    assert warm.extra["second_order_warm"] is True  # the check started from the first point's levels
    assert abs(warm.extra["second_order_min_eigenvalue"] - cold.extra["second_order_min_eigenvalue"]) <= \
        warm.extra["second_order_error_bound"] + cold.extra["second_order_error_bound"]


def test_refuses_ipopt_options():
    from vesicle_opt.errors import NotSupported
    from vesicle_opt.nlp import IpoptOptions
    with pytest.raises(NotSupported, match="options"):
        nc.NewtonKrylovCorrector(scene_2d(), IpoptOptions.from_scene(scene_2d()))
    assert nc.NewtonKrylovCorrector(scene_2d(), NewtonKrylovOptions(tol=1e-8)).options.tol == 1e-8


def test_cold_check_every_cold_every_points(monkeypatch):
    """A warm check is reported at most COLD_EVERY - 1 times in a row (module docstring)."""
    monkeypatch.setattr(nc, "COLD_EVERY", 3)
    b, seen = _checked_branch(monkeypatch, scene_2d(), 0.8, -0.02)
    used = [u for u, *_ in seen]
    runs = "".join("w" if u else "c" for u in used).split("c")
    assert used[0] is False and max(len(r) for r in runs) <= 2 and "w" in "".join(runs), used
    assert np.all([so.verdict == cold.verdict for _, so, cold in seen])


def test_the_step_control_aims_at_the_corrector_kinds_own_iterations(monkeypatch):
    """The walk gets the Newton-Krylov corrector's TARGET_ITERATIONS (Newton steps), IPOPT keeps the
    arclength default (IPOPT iterations); captured at the walk's start, before any solve."""
    import importlib
    branch_run = importlib.import_module("vesicle_opt.branch.run")
    seen = []

    class Captured(Exception):
        pass

    def walk(settings, *a, **kw):
        seen.append(settings.target_iterations)
        raise Captured
    monkeypatch.setattr(branch_run.arc, "walk", walk)
    spectral = scene_2d()
    fd = spectral.replace(mesh=dataclasses.replace(spectral.mesh, kind="fd"))  # IPOPT takes no spectral mesh
    for sc, backend in ((spectral, "newton-krylov"), (fd, "ipopt")):
        with pytest.raises(Captured):
            branch(sc, "reduced_volume", to=0.8, step=-0.02, backend=backend, switch=False)
    assert seen == [nc.TARGET_ITERATIONS, branch_run.arc.Settings.target_iterations]
    assert nc.TARGET_ITERATIONS != branch_run.arc.Settings.target_iterations  # else nothing is tested
