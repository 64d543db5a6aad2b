"""The one certification of a computed equilibrium, and the one place a ``Result`` is built.

Every backend (IPOPT, Newton-Krylov), every method (exact, penalty, continuation, augmented) and
every stage of a continuation hands its final field to :func:`build_result`, which recomputes, with
code that shares nothing with the solver's derivatives:

* E_h, A - alpha, B - beta (``model.functionals``; the residuals with compensated sums,
  ``model.penalty.residuals``);
* the multipliers of a penalty run, lambda = mu - M (A - alpha, B - beta) (exact runs pass theirs);
* the relative KKT residual in the natural norm, ``kkt_dual`` (``verify.kkt``, hand-derived
  gradients; the norm of the bulk Hessian model P0, ``model.metric``; relative to the norms of the
  residual's elementary terms, ``kkt_dual_scale``), which decides; the same against the net terms,
  ``kkt_dual_net``, and the relative L2 one, ``kkt_residual``, reported beside it;
* the round-off floor of each: the least residual double precision permits. In the natural norm
  (``kkt_dual_floor``, which decides) the round-off of phi through P0 (``verify.kkt.dual_floor``,
  ~ h^-2), and for a penalty run the larger ``model.penalty.roundoff_floor`` in that norm (the
  multiplier estimates carry M times the round-off of A and B). The L2 floor ``kkt_floor`` (the
  penalty's in L2, or one a solver passes: Newton-Krylov on Fourier grids, eps_mach k_max^4,
  ~ h^-4) is reported only.

:func:`certify` then decides, in this order (the first failure is the outcome):

1. the iterate is finite                                         else ``Status.NON_FINITE``
2. the solver reports success                                    else ``MAX_ITERATIONS`` / ``SOLVER_FAILED``
3. kkt_dual_floor < tol: a floor at or above tol can never be certified,
   whatever value the (noise-dominated) residual happens to take  else ``ROUNDOFF_FLOOR``
4. exact constraints (methods exact, augmented): |A - alpha| <= tol |Omega|,
   |B - beta| <= tol beta                                        else ``INFEASIBLE``
5. kkt_dual <= KKT_FACTOR tol                                     else ``KKT_NOT_MET``
6. the solver's own consistency checks (e.g. the lifted unknowns) else ``NOT_CERTIFIED``

``converged`` is True exactly when all hold (``Status.CONVERGED``); otherwise ``extra["reason"]``
says which test failed, in words. Nothing here depends on which BLAS kernel ran: a floor at tol is
refused before the residual is looked at. One rule, one quantity, on every backend and method: IPOPT
and Newton-Krylov results alike (``solver.tol`` means: kkt_dual <= KKT_FACTOR tol with its floor
below tol, and the constraints to tol where the method promises them).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from vesicle_opt import geometry
from vesicle_opt.model import functionals as F
from vesicle_opt.model.metric import natural_metric
from vesicle_opt.model.penalty import penalised_energy, residuals, roundoff_floor
from vesicle_opt.result import Result, Status
from vesicle_opt.verify.kkt import kkt_dual_report, kkt_residual

KKT_FACTOR = 100.0  # the deciding residual (kkt_dual since issue 25) may exceed IPOPT's scaled
# max-norm test by this: measured ratios for the relative L2 residual (nlp.exact scaling) 0.2-1.3 on
# ellipse-2d, ~12 on a sphere; kkt_dual against the net terms (kkt_dual_net) 0.73 on ellipse-2d 48^2
# (7.3e-9 at IPOPT's tol 1e-8), against the terms apart 3.99x less; a larger ratio means the iterate
# is not a KKT point
_ITERATION_LIMITS = ("Maximum_Iterations_Exceeded", "Maximum_CpuTime_Exceeded",
                     "Maximum_WallTime_Exceeded", "max_iter")


@dataclass(frozen=True)
class Certificate:
    converged: bool
    outcome: Status
    reason: str | None


def certifiable_tol(floor: float) -> float:
    """The least tolerance of the form 1, 2 or 5 x 10^k strictly above ``floor`` (the floor test)."""
    if not np.isfinite(floor) or floor <= 0:
        return float("nan") if not np.isfinite(floor) else 0.0
    k = int(np.floor(np.log10(floor)))
    return next(m * 10.0**e for e in (k, k + 1) for m in (1, 2, 5) if m * 10.0**e > floor)


def certify(*, solver_status: str, solver_success: bool, finite: bool, tol: float, kkt: float,
            floor: float = 0.0, constraints: tuple[float, float] | None = None,
            checks: Sequence[tuple[bool, str]] = ()) -> Certificate:
    """The rule of the module docstring. ``constraints`` = (|A - alpha| / |Omega|, |B - beta| / beta)
    when the method promises exact constraints (None for penalty stages); ``checks`` = the solver's
    own (passed, reason-if-not) pairs."""
    if not finite:
        return Certificate(False, Status.NON_FINITE, "the iterate is not finite")
    if not solver_success:
        limit = solver_status in _ITERATION_LIMITS
        return Certificate(False, Status.MAX_ITERATIONS if limit else Status.SOLVER_FAILED,
                           f"solver status {solver_status}")
    if not floor < tol:
        return Certificate(False, Status.ROUNDOFF_FLOOR,
                           f"round-off floor: stationarity is known only to ~{floor:.1e} here "
                           f"(>= tol = {tol:g}; kkt_dual {kkt:.2e}); tol >= {certifiable_tol(floor):.0e} "
                           f"can be certified: raise solver.tol (or lower solver.M for a penalty)")
    if constraints is not None and not (constraints[0] <= tol and constraints[1] <= tol):
        return Certificate(False, Status.INFEASIBLE,
                           f"constraint residuals {constraints[0]:.1e}, {constraints[1]:.1e} above tol = "
                           f"{tol:g} (relative to |Omega| and beta)")
    if not kkt <= KKT_FACTOR * tol:
        return Certificate(False, Status.KKT_NOT_MET,
                           f"recomputed kkt_dual {kkt:.2e} above {KKT_FACTOR:g} tol = {KKT_FACTOR * tol:g}")
    for passed, why in checks:
        if not passed:
            return Certificate(False, Status.NOT_CERTIFIED, why)
    return Certificate(True, Status.CONVERGED, None)


def dual_floor_of(disc, phi, epsilon: float, C: float, rigidity: float, lam, M=None, grads=None) -> float:
    """The floor ``build_result`` certifies against (``kkt_dual_floor``): the round-off of phi in
    the natural norm, and at a penalty M the larger multiplier floor ``model.penalty.roundoff_floor``
    in that norm. Solvers call it to plan stages (``model.penalty.next_stage``)."""
    return _dual_floor(kkt_dual_report(disc, phi, epsilon, C, rigidity, lam[0], lam[1], grads), disc, phi,
                       epsilon, C, rigidity, lam, M, grads)


def _dual_floor(report, disc, phi, epsilon, C, rigidity, lam, M, grads) -> float:
    floor = report["kkt_dual_floor"]
    if M is not None:  # relative to kkt_dual's own denominator, as the residual it guards
        floor = max(floor, roundoff_floor(disc, phi, epsilon, C, rigidity, lam, M, grads=grads,
                                          norm=natural_metric(disc, epsilon).dual_norm,
                                          scale=report["kkt_dual_scale"]))
    return floor


def _physical(disc, A: float, B: float, energy: float, rigidity: float, c0: float = 0.0) -> dict[str, float]:
    """volume, area, reduced_volume and reduced_energy of the field (geometry: sphere/circle = 1);
    in 3D also the literature's f = F / 8 pi kappa and c0_reduced = C0 R0 (``geometry.literature_units``)."""
    out = geometry.physical(A, B, disc.dim, disc.volume)
    ok = np.isfinite(out["area"]) and out["area"] > 0
    out["reduced_energy"] = geometry.reduced_energy(energy, out["area"], disc.dim, rigidity) if ok else np.nan
    if disc.dim == 3:
        out.update(geometry.literature_units(energy, out["area"], c0, rigidity) if ok
                   else {"f": np.nan, "c0_reduced": np.nan})
    return out


def build_result(*, scene, disc, alpha: float, beta: float, phi: np.ndarray, tol: float,
                 solver_status: str, solver_success: bool, method: str,
                 lam: tuple[float, float] | None = None, M: tuple[float, float] | None = None,
                 mu: tuple[float, float] = (0.0, 0.0), exact_constraints: bool | None = None,
                 floor: float = 0.0, checks: Sequence[tuple[bool, str]] = (), w: np.ndarray | None = None,
                 iterations: int = 0, wall_time_s: float = float("nan"), derivative_time_s: float = 0.0,
                 hessian_nnz_per_row: float = float("nan"), history: dict | None = None,
                 x=None, lam_x=None, lam_g=None, extra: dict | None = None) -> Result:
    """Recompute, certify and pack one solve (see the module docstring).

    ``lam``: the multipliers of an exact-constraint solve; for penalty runs (``M`` given, with the
    multiplier shifts ``mu`` of an augmented Lagrangian) they are mu - M (A - alpha, B - beta).
    ``exact_constraints`` defaults to ``M is None``.
    """
    eps, C, rig = scene.model.epsilon, scene.model.C, scene.model.rigidity
    phi = np.asarray(phi, float)
    finite = all(bool(np.all(np.isfinite(v))) for v in (phi, x, w) if v is not None)
    if finite:
        E = F.evaluate(disc, phi, eps, C)["E"]
        res = residuals(disc, phi, eps, alpha, beta)
    else:
        E, res = np.nan, (np.nan, np.nan)
    if M is not None:
        lam = (mu[0] - M[0] * res[0], mu[1] - M[1] * res[1])
    lam_A, lam_B = (float(v) for v in lam)
    if finite:
        grads = F.gradients(disc, phi, eps, C)  # once, for the residuals and the penalty's floors
        kkt = kkt_residual(disc, phi, eps, C, rig, lam_A, lam_B, grads=grads)
        report = kkt_dual_report(disc, phi, eps, C, rig, lam_A, lam_B, grads=grads)
        dual = report["kkt_dual"]
        dual_floor = _dual_floor(report, disc, phi, eps, C, rig, (lam_A, lam_B), M, grads)
        if M is not None:
            floor = max(floor, roundoff_floor(disc, phi, eps, C, rig, (lam_A, lam_B), M, grads=grads))
    else:
        kkt, floor, dual, dual_floor = np.nan, np.inf, np.nan, np.inf
        report = {"kkt_dual_scale": np.nan, "kkt_dual_net": np.nan}
    exact_constraints = (M is None) if exact_constraints is None else exact_constraints
    rel = (abs(res[0]) / disc.volume, abs(res[1]) / abs(beta)) if exact_constraints else None
    cert = certify(solver_status=solver_status, solver_success=solver_success, finite=finite, tol=tol,
                   kkt=dual, floor=dual_floor, constraints=rel, checks=checks)
    info = {"alpha": alpha, "beta": beta, "epsilon": eps, "c0": scene.model.c0, "h": disc.h,
            "kkt_floor": floor, "kkt_dual_floor": dual_floor, **_physical(disc, alpha + res[0], beta + res[1], rig * E, rig, scene.model.c0),
            **(extra or {}), "kkt_dual": dual, "kkt_dual_scale": report["kkt_dual_scale"],
            "kkt_dual_net": report["kkt_dual_net"]}
    if M is not None:
        info.update({"M2": M[1], "mu_volume": mu[0], "mu_area": mu[1]})
    if cert.reason is not None:
        info["reason"] = cert.reason
    wall = float(wall_time_s)
    return Result(
        phi=phi, w=w, energy=rig * E, volume_residual=res[0], area_residual=res[1],
        lambda_volume=lam_A, lambda_area=lam_B, kkt_residual=kkt, status=solver_status,
        success=bool(solver_success) and finite, converged=cert.converged, outcome=cert.outcome,
        iterations=int(iterations), wall_time_s=wall, derivative_time_s=derivative_time_s,
        other_time_s=wall - derivative_time_s, n_nodes=disc.n_nodes,
        hessian_nnz_per_row=hessian_nnz_per_row, method=method, M=None if M is None else M[0],
        penalized_energy=None if M is None else penalised_energy(rig, E, res, M[0], M[1]),
        history=history or {}, x=x, lam_x=lam_x, lam_g=lam_g, extra=info, disc=disc)
