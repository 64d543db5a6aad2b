"""IPOPT solves of the NLPs of ``nlp.exact`` (6)-(8) and ``nlp.lifted`` (11), certified.

``solve_exact`` is one IPOPT call on the exact-constraint NLP; ``solve_stage`` one call on the lifted
penalty NLP at parameters p = (M1, M2, mu_A, mu_B) (a penalty solve, or one stage of a continuation
or an augmented Lagrangian, ``nlp.continuation``). Both hand the final iterate to
``verify.certify.build_result``, which recomputes every residual and decides ``converged``; a failure
is reported honestly (status, residuals, the last iterate), never returned as a solution.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.nlp.exact import NLP
from vesicle_opt.nlp.ipopt import (IpoptOptions, derivative_time, hessian_nnz_per_row, history, make_solver,
                                   run_ipopt)
from vesicle_opt.nlp.lifted import PenaltyNLP
from vesicle_opt.result import Result
from vesicle_opt.verify.certify import build_result


def _pack(nlp: NLP, solver, sol, stats, wall, x, *, tol: float, method: str, **kw) -> Result:
    phi, w = nlp.split(x)
    return build_result(
        scene=nlp.scene, disc=nlp.disc, alpha=nlp.alpha, beta=nlp.beta, phi=phi, w=w, tol=tol,
        solver_status=stats["return_status"], solver_success=bool(stats["success"]), method=method,
        iterations=int(stats.get("iter_count", 0)), wall_time_s=wall, derivative_time_s=derivative_time(stats),
        hessian_nnz_per_row=hessian_nnz_per_row(solver, x.size), history=history(stats), x=x,
        lam_x=np.asarray(sol["lam_x"]).ravel(), lam_g=np.asarray(sol["lam_g"]).ravel(), **kw)


def solve_exact(nlp: NLP, *, x0=None, lam_x0=None, lam_g0=None, solver=None,
                options: IpoptOptions | None = None, p=None) -> Result:
    """Minimise rigidity E_h subject to A = alpha, B = beta exactly (one IPOPT call); ``p``: the
    parameter values of a parametric NLP (``nlp.exact.parameter_values``)."""
    options = options or IpoptOptions.from_scene(nlp.scene)
    solver = solver or make_solver(nlp, options)
    sol, stats, wall, x = run_ipopt(solver, nlp, nlp.x0 if x0 is None else x0, p=p, lam_x0=lam_x0,
                                    lam_g0=lam_g0)
    lam = nlp.multipliers(np.asarray(sol["lam_g"]))
    return _pack(nlp, solver, sol, stats, wall, x, tol=options.tol, method="exact", lam=lam)


def solve_stage(nlp: PenaltyNLP, solver, p: np.ndarray, *, x0=None, lam_x0=None, lam_g0=None,
                tol: float, method: str = "penalty", exact_constraints: bool = False) -> Result:
    """One IPOPT solve of the penalised functional at p = (M1, M2, mu_A, mu_B).

    The multiplier estimates are lambda = mu - M (A - alpha, B - beta), recomputed; besides the
    common certificate the lifted unknowns must agree with phi (they enter only through the NLP):
    a gap |B - b| shifts the estimate by M |B - b|, so the lifted rows run at a constraint
    tolerance far below tol (``continuation.PENALTY_OPTIONS``). ``exact_constraints`` asks the
    certificate for A = alpha, B = beta too (the augmented Lagrangian's promise).
    """
    x0 = nlp.x0 if x0 is None else np.asarray(x0, float)
    sol, stats, wall, x = run_ipopt(solver, nlp, x0, p=p, lam_x0=lam_x0,
                                    lam_g0=nlp.initial_lam_g(x0, p) if lam_g0 is None else lam_g0)
    M1, M2, muA, muB = (float(v) for v in p)
    lift_gap = nlp.lift_gap(x) if np.all(np.isfinite(x)) else np.inf
    ipopt_lam = nlp.multipliers(np.asarray(sol["lam_g"]))
    return _pack(nlp, solver, sol, stats, wall, x, tol=tol, method=method, M=(M1, M2), mu=(muA, muB),
                 exact_constraints=exact_constraints,
                 checks=[(lift_gap <= tol, f"lifted unknowns off A, B by {lift_gap:.1e} (> tol)")],
                 extra={"lift_gap": lift_gap, "ipopt_lambda_volume": ipopt_lam[0],
                        "ipopt_lambda_area": ipopt_lam[1]})
