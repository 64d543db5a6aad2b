"""Penalty (11), continuation and augmented Lagrangian against the exact solve and the O(1/M) law."""

import warnings

import numpy as np
import pytest

from vesicle_opt import scene as scene_mod
from vesicle_opt.cli import main as cli_main
from vesicle_opt.model.penalty import schedule
from vesicle_opt.nlp.continuation import augmented_lagrangian, continuation
from vesicle_opt.errors import InputError
from vesicle_opt.result import Status
from vesicle_opt.nlp import build_nlp
from vesicle_opt.api import solve

N = 48  # 48^2 FD ellipse: resolved (h = 0.17 < eps = 0.2) and ~1 s per solve
# Comparisons with the exact solve need its state to be a minimum: on 64^2 it is (second-order
# check), on 48^2 the symmetric state is a saddle (eigenvalue -0.02 mu_ref) that a continuation may
# leave for a lower asymmetric state (seen: E = 2.68224 against 2.68824), a different branch.
N_REF = 64


def _nlp(*over, n=N):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = scene_mod.load("ellipse-2d", [f"mesh.n={n}", 'solver.method="continuation"', *over])
        return build_nlp(sc)


@pytest.fixture(scope="module")
def runs():
    nlp = _nlp("solver.M_max=1e6", n=N_REF)
    exact = solve(nlp.exact)
    assert exact.converged and exact.extra["second_order"] == "minimum"
    # the law is studied past the certifiable M on purpose: the scene's own schedule stops where the
    # next stage's floor would reach tol (test_default_schedule_stops_at_the_floor...)
    cont = continuation(nlp, Ms=schedule(10, 10, 1e6))
    return nlp, exact, cont


def test_lifted_hessian_stays_sparse(runs):
    nlp, exact, cont = runs
    n_phi = nlp.disc.n_nodes
    # FD 2D: the Hessian of (6) is the 13-point bi-Laplacian stencil, exactly 13 per row
    assert exact.hessian_nnz_per_row == 13.0
    # the lift adds two unknowns with one diagonal entry each: (13 N + 2) / (N + 2) (12.9985 on 128^2);
    # the dense m m^T block of the unlifted penalty would add ~N per row. Exact counts: no tolerance
    assert cont.hessian_nnz_per_row == (13 * n_phi + 2) / (n_phi + 2)


def test_o_one_over_M_law(runs):
    nlp, exact, cont = runs
    st = {s["M"]: s for s in cont.history["stages"]}
    for key in ("volume_residual", "area_residual"):
        a, b = 1e5 * st[1e5][key], 1e6 * st[1e6][key]
        # M (A - alpha) = -lambda(M) and lambda(M) - lambda* = O(1/M): relative change between
        # M = 1e5 and 1e6 is ~ c/1e5 with c ~ 1 measured; 1e-3 leaves a factor 100
        assert abs(a - b) <= 1e-3 * abs(b), (key, a, b)


def test_multiplier_estimates_approach_exact_lambda(runs):
    nlp, exact, cont = runs
    st = {s["M"]: s for s in cont.history["stages"]}
    errs = [abs(st[M]["lambda_volume"] - exact.lambda_volume) + abs(st[M]["lambda_area"] - exact.lambda_area)
            for M in (1e2, 1e3, 1e4, 1e5)]
    slope = np.polyfit(np.log([1e2, 1e3, 1e4, 1e5]), np.log(errs), 1)[0]
    print("multiplier error against M:", errs, "slope", slope)
    # O(1/M): slope -1; 0.1 covers the O(1/M^2) curvature from M = 1e2 (measured -0.996 on 64^2)
    assert abs(slope + 1) < 0.1
    # sign convention of the exact solve: the estimate at M = 1e5 carries the exact lambda's sign
    # and agrees to O(1/M) = 1e-5 relative times a constant ~ 1 (measured), with 10x margin
    assert st[1e5]["lambda_volume"] == pytest.approx(exact.lambda_volume, rel=1e-4)
    assert st[1e5]["lambda_area"] == pytest.approx(exact.lambda_area, rel=1e-4)


def test_energy_is_bending_only_and_penalised_energy_consistent(runs):
    nlp, exact, cont = runs
    r = cont
    pen = r.energy + r.M / 2 * (r.volume_residual**2 + r.area_residual**2)
    assert r.penalized_energy == pytest.approx(pen, rel=1e-14)  # identity: round-off only
    # E* - E_M = O(1/M) (Theorem 3.2): at M = 1e6 relative 3.4e-7 measured on 64^2
    assert abs(r.energy - exact.energy) <= 1e-5 * exact.energy
    assert r.method == "continuation"
    # the last stage, M = 1e6, cannot be certified at tol 1e-8 on 64^2: its round-off floor
    # (measured 9.3e-7) is above tol, so it is refused with that reason (verify.certify), while
    # the stages whose floor lies below tol are certified
    assert r.extra["kkt_floor"] >= 1e-8 and not r.converged and r.outcome == Status.ROUNDOFF_FLOOR
    st = {s["M"]: s for s in cont.history["stages"]}
    assert st[1e2]["converged"] and st[1e3]["converged"]


def test_default_schedule_stops_at_the_floor_and_extrapolates_to_exact(runs):
    """Issue 25: without explicit M the schedule stops raising M where the next stage's floor (linear
    in M) would reach tol, so the last stage is certified; Richardson's extrapolation in 1/M of the
    stages and the augmented polish land on the exact solve."""
    nlp, exact, _ = runs
    r = continuation(nlp)
    Ms = [st["M"] for st in r.history["stages"]]
    assert r.converged, r.reason
    # next_stage aims the last stage at floor = tol / 2 by the linear law; the law holds to the change
    # of lambda between the stages (measured 5.0007e-9 at the aim 5e-9)
    assert r.extra["kkt_dual_floor"] == pytest.approx(1e-8 / 2, rel=0.01)
    assert Ms[-1] < 1e6 and Ms == sorted(Ms)  # stopped before M_max
    # O(1/M^4) after the multiplier correction and eliminating c2/M^2, c3/M^3 (measured 7.6e-14 on 64^2)
    assert r.extra["energy_extrapolated"] == pytest.approx(exact.energy, rel=1e-8)
    # (the multiplier-corrected fit, model.extrapolation: 7.6e-14 here against plain Richardson's
    # 6.9e-13, both at the exact solve's own accuracy; the comparison is circle-2d's test below)
    assert r.extra["lambda_volume_extrapolated"] == pytest.approx(exact.lambda_volume, rel=1e-5)  # O(1/M^3)
    # the polish holds the constraints exactly: the exact solve's energy to both tolerances (1e-8)
    assert r.extra["polish_converged"] and r.extra["polish_energy"] == pytest.approx(exact.energy, rel=1e-8)


def test_corrected_extrapolation_reaches_exact_at_the_isoperimetric_bound():
    """circle-2d (its own scene, P1 64^2): the data sit 1.5% above the feasibility bound, the multipliers
    are ill-conditioned and the floor stops the schedule at M = 1e4. Plain Richardson of the stage
    energies in 1/M is 7.5e-8 off exact's; the multiplier-corrected fit (model.extrapolation) 8e-10."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its epsilon/h warning: the scene's documented state
        sc = scene_mod.load("circle-2d", ['solver.method="continuation"'])
    nlp = build_nlp(sc)
    exact = solve(nlp.exact)
    r = continuation(nlp, polish=False)
    assert exact.converged and r.converged, (exact.reason, r.reason)
    err = abs(r.extra["energy_extrapolated"] - exact.energy) / exact.energy
    plain = abs(r.extra["energy_extrapolated_plain"] - exact.energy) / exact.energy
    assert err < 1e-8 and err < plain / 10, (err, plain)  # issue 25's target; measured 8.3e-10 vs 7.5e-8
    # its error estimate is of the error's size (measured 2.6e-10 relative: the M = 100 stage is
    # pre-asymptotic, observed order 1.2), so it is not a bound here; it is below the target too
    assert r.extra["energy_extrapolation_error"] / exact.energy < 1e-8


def test_warm_starts_save_iterations():
    # M0 = 10 (the default was 10 when the counts below were measured): a cold stage at M = 100 from
    # the ellipse start can reach the lower minimum (E 2.68215) instead of the symmetric point
    # (2.68814) depending on the BLAS kernel's rounding (seen in a fresh CI venv), and this test
    # compares warm and cold on one minimiser; at M = 10 the cold stages stay on it
    nlp = _nlp("solver.M_max=1e4", "solver.M0=10")
    warm = continuation(nlp, polish=False)  # the stages' counts (the polish is one more, warm either way)
    cold = continuation(nlp, warm=False, polish=False)
    print("iterations warm", warm.iterations, "cold", cold.iterations)
    assert warm.converged and cold.converged
    assert warm.iterations < cold.iterations  # measured 64^2 to 1e8: 34 against 230
    assert warm.energy == pytest.approx(cold.energy, rel=1e-8)  # same minimiser, tol 1e-8


def test_augmented_lagrangian_meets_exact_tolerance(runs):
    nlp, exact, _ = runs
    r = augmented_lagrangian(nlp, M=1e3)
    assert r.converged
    # feasibility as the exact solve's test (tol 1e-8 relative) and the same minimiser
    assert abs(r.volume_residual) <= 1e-8 * nlp.disc.volume
    assert abs(r.area_residual) <= 1e-8 * nlp.beta
    assert r.energy == pytest.approx(exact.energy, rel=1e-7)  # both to tol 1e-8; 10x margin
    assert r.lambda_volume == pytest.approx(exact.lambda_volume, rel=1e-5)


def test_schedule_and_bad_input():
    assert schedule(10, 10, 1e8) == [10.0 * 10**k for k in range(8)]
    assert schedule(1, 3, 10)[-1] == 10
    for bad in ("solver.M_max=1e13", "solver.M_factor=1.0", "solver.M0=1e9"):
        with pytest.raises(InputError):
            scene_mod.load("ellipse-2d", [bad])


def test_cli_writes_penalty_summary(tmp_path, capsys):
    import json
    rc = cli_main(["solve", "ellipse-2d", "--out", str(tmp_path), "--set", f"mesh.n={N}",
                   "--set", 'solver.method="penalty"', "--set", "solver.M=1e4"])
    s = json.loads((tmp_path / "summary.json").read_text())
    assert rc == 0 and s["converged"] and s["M"] == 1e4
    assert s["penalized_energy"] > s["energy"]  # the penalty terms are >= 0 and nonzero at finite M
    assert s["lambda_volume"] == pytest.approx(-1e4 * s["volume_residual"], rel=1e-12)  # definition
    assert cli_main(["solve", "ellipse-2d", "--set", "solver.M_max=1e13"]) == 2
