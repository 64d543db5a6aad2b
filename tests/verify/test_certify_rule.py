"""The one rule of ``verify.certify.certify``, table-driven (no solves): each test in its order, the
first failure is the outcome, and a floor at or above tol is refused whatever the residual."""

import math

import pytest

from vesicle_opt.result import Status
from vesicle_opt.verify.certify import KKT_FACTOR, certify

TOL = 1e-8
GOOD = dict(solver_status="Solve_Succeeded", solver_success=True, finite=True, tol=TOL, kkt=1e-10,
            floor=1e-12, constraints=(1e-10, 1e-10), checks=())

CASES = [  # (changes to GOOD, outcome): each row breaks one test, later tests still broken where given
    ({}, Status.CONVERGED),
    ({"finite": False, "solver_success": False}, Status.NON_FINITE),  # finiteness is tested first
    ({"solver_success": False, "solver_status": "Maximum_Iterations_Exceeded"}, Status.MAX_ITERATIONS),
    ({"solver_success": False, "solver_status": "max_iter"}, Status.MAX_ITERATIONS),
    ({"solver_success": False, "solver_status": "Restoration_Failed", "floor": 1.0}, Status.SOLVER_FAILED),
    ({"floor": TOL, "kkt": 1e-12}, Status.ROUNDOFF_FLOOR),  # at tol: refused though the kkt is tiny
    ({"floor": 1e-3, "kkt": 1e-12, "constraints": (1.0, 1.0)}, Status.ROUNDOFF_FLOOR),
    ({"constraints": (2 * TOL, 0.0)}, Status.INFEASIBLE),
    ({"constraints": (0.0, 2 * TOL), "kkt": 1.0}, Status.INFEASIBLE),
    ({"kkt": 2 * KKT_FACTOR * TOL}, Status.KKT_NOT_MET),
    ({"kkt": math.nan}, Status.KKT_NOT_MET),  # a NaN residual is not a small one
    ({"checks": [(True, "fine"), (False, "lifted unknowns off")]}, Status.NOT_CERTIFIED),
    ({"constraints": None, "kkt": KKT_FACTOR * TOL}, Status.CONVERGED),  # penalty stages: no A = alpha test
]


@pytest.mark.parametrize("changes, outcome", CASES)
def test_certify_order_and_outcomes(changes, outcome):
    cert = certify(**{**GOOD, **changes})
    assert cert.outcome is outcome
    assert cert.converged == (outcome is Status.CONVERGED)
    assert (cert.reason is None) == cert.converged
    if outcome is Status.ROUNDOFF_FLOOR:
        assert cert.reason.startswith("round-off floor")
    if outcome is Status.NOT_CERTIFIED:
        assert cert.reason == "lifted unknowns off"


def test_floor_just_below_tol_is_certifiable():
    assert certify(**{**GOOD, "floor": TOL * (1 - 1e-12)}).converged  # strict: floor < tol
