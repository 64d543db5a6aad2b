"""Solve the discrete equilibrium NLP with IPOPT (exact constraints (7), (8)).

``solve(scene)`` or ``solve(nlp)`` returns a frozen :class:`~vesicle_opt.result.Result`. IPOPT runs
with the exact Hessian and MUMPS. A failure is reported honestly (status, residuals, the last
iterate) and ``converged`` is False; ``throw=True`` raises :class:`SolverError` instead.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from . import functionals as F
from .errors import SolverError
from .kkt import kkt_residual
from .nlp import NLP, build_nlp
from .result import Result
from .scene import Scene

KKT_FACTOR = 100.0  # kkt_residual (relative L2) may exceed IPOPT's scaled max-norm test by this:
# measured ratios (nlp.py scaling) 0.2-1.3 on ellipse-2d, ~12 on a sphere; a larger ratio means
# the iterate is not a KKT point.
_DERIV_KEYS = ("nlp_grad_f", "nlp_jac_g", "nlp_hess_l", "nlp_grad")


@dataclass(frozen=True)
class IpoptOptions:
    tol: float
    max_iter: int = 500
    print_level: int = 0
    extra: tuple = ()  # further ("ipopt.key", value) pairs

    def as_dict(self) -> dict:
        opts = {"ipopt.tol": self.tol, "ipopt.constr_viol_tol": self.tol,
                "ipopt.max_iter": self.max_iter, "ipopt.print_level": self.print_level,
                "ipopt.sb": "yes", "print_time": False, "ipopt.linear_solver": "mumps",
                "ipopt.mu_strategy": "adaptive",
                "ipopt.nlp_scaling_method": "none"}  # the NLP is scaled by design (nlp.py)
        opts.update(dict(self.extra))
        return opts


def failure_reason(status: str, success: bool, kkt: float, tol: float, feasible: bool = True,
                   floor: float = 0.0) -> str | None:
    """Why a result is not ``converged`` (None when it is): the first test that failed, in words."""
    if not success:
        return f"solver status {status}"
    if not feasible:
        return f"constraint residuals above tol = {tol:g} (relative to |Omega| and beta)"
    if not kkt <= KKT_FACTOR * tol:
        if floor >= tol:
            return (f"round-off floor: at this M the stationarity of E_M is known only to ~{floor:.1e} "
                    f"(>= tol = {tol:g}; kkt_residual {kkt:.2e}); lower solver.M or raise solver.tol")
        return f"recomputed kkt_residual {kkt:.2e} above {KKT_FACTOR:g} tol = {KKT_FACTOR * tol:g}"
    return None


def make_solver(nlp: NLP, options: IpoptOptions):
    return ca.nlpsol("equilibrium", "ipopt", nlp.as_dict(), options.as_dict())


def _times(stats: dict) -> tuple[float, float, float]:
    total = float(stats.get("t_wall_total", np.nan))
    deriv = sum(float(stats.get(f"t_wall_{k}", 0.0)) for k in _DERIV_KEYS)
    return total, deriv, total - deriv


def _hessian_nnz_per_row(solver, n: int) -> float:
    try:
        sp_h = solver.get_function("nlp_hess_l").sparsity_out(0)
    except RuntimeError:
        return float("nan")
    nnz = sp_h.nnz()
    if sp_h.is_triu() or sp_h.is_tril():  # one triangle stored: count the full symmetric pattern
        nnz = 2 * nnz - n
    return nnz / n


def run_ipopt(solver, nlp, x0, p=None, lam_x0=None, lam_g0=None):
    """One IPOPT call with the NLP's bounds: (sol, stats, wall seconds, x as a flat array)."""
    args = {"x0": x0, "lbx": nlp.lbx, "ubx": nlp.ubx, "lbg": nlp.lbg, "ubg": nlp.ubg}
    for key, value in (("p", p), ("lam_x0", lam_x0), ("lam_g0", lam_g0)):
        if value is not None:
            args[key] = value
    t0 = time.perf_counter()
    sol = solver(**args)
    wall = time.perf_counter() - t0
    return sol, solver.stats(), wall, np.asarray(sol["x"]).ravel()


def replace_extra(result: Result, **items) -> Result:
    from dataclasses import replace
    return replace(result, extra={**result.extra, **items})


def with_topology(disc, result: Result) -> Result:
    """Add the topology report of {phi > 0} (``topology.py``) to a result with a finite phi."""
    if not np.all(np.isfinite(result.phi)):
        return result
    from .topology import analyse
    topo = analyse(disc, result.phi)
    return replace_extra(result, topology=topo.describe(disc.dim), components=topo.components,
                         euler_characteristic=topo.euler_characteristic, cavities=topo.cavities,
                         wraps=None if topo.wraps is None else list(topo.wraps))


def solve_newton_krylov(scene: Scene, disc=None, throw: bool = False) -> Result:
    """The matrix-free backend (``newton_krylov.py``) with the same reports as the IPOPT path:
    topology, and for exact constraints the second-order check (``second_order_lobpcg``; on Fourier
    grids translations and rotations, the continuum's symmetries, excluded — rotations are soft but
    resolved only to LOBPCG's residual; on P1 meshes no direction excluded): "minimum" when the least eigenvalue
    exceeds 10x its residual, "saddle" when it is below -10x, else "not checked" (undecided)."""
    import warnings
    from . import newton_krylov
    from .discretization import discretize
    disc = disc or discretize(scene)
    result = with_topology(disc, newton_krylov.solve(scene, disc, throw=throw))
    verdict, least = "not checked", None
    if result.converged and scene.solver.second_order and scene.solver.method == "exact":
        from .second_order_lobpcg import reduced_hessian_eigenvalues
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # lobpcg warns when unwanted eigenvalues lag behind
            vals, res = reduced_hessian_eigenvalues(scene, result, k=3, rotations=True)
        least = float(vals[0])
        if vals[0] > 10 * res[0]:
            verdict = "minimum"
        elif vals[0] < -10 * res[0]:
            verdict = "saddle"
    return replace_extra(result, second_order=verdict, second_order_min_eigenvalue=least)


def solve(problem: Scene | NLP, *, x0=None, lam_x0=None, lam_g0=None, solver=None,
          options: IpoptOptions | None = None, throw: bool = False) -> Result:
    """Minimise rigidity * E_h subject to A = alpha, B = beta exactly; see the module docstring.

    A Scene whose ``solver.backend`` resolves to newton-krylov (``backend.choose_backend``) goes to
    ``newton_krylov.solve`` and returns the same Result (IPOPT-only arguments are then ignored).
    """
    if isinstance(problem, Scene):  # backend dispatch (issue 6)
        from .backend import choose_backend
        if choose_backend(problem) == "newton-krylov":
            return solve_newton_krylov(problem, throw=throw)
    nlp = problem if isinstance(problem, NLP) else build_nlp(problem)
    from .penalty import PenaltyNLP
    if isinstance(nlp, PenaltyNLP):  # penalty (11), continuation, augmented Lagrangian
        from .continuation import solve_penalised
        result = solve_penalised(nlp, x0=x0, lam_x0=lam_x0, lam_g0=lam_g0, solver=solver,
                                 options=options, throw=throw)
        # the tangent-space test belongs to the exact problem; for E_M it is not implemented
        return replace_extra(with_topology(nlp.disc, result), second_order="not checked")
    scene, disc = nlp.scene, nlp.disc
    options = options or IpoptOptions(tol=scene.solver.tol, max_iter=scene.solver.max_iter)
    solver = solver or make_solver(nlp, options)
    sol, stats, wall, x = run_ipopt(solver, nlp, nlp.x0 if x0 is None else x0,
                                    lam_x0=lam_x0, lam_g0=lam_g0)
    phi, w = nlp.split(x)
    lam_A, lam_B = nlp.multipliers(np.asarray(sol["lam_g"]))
    eps, C, rig = scene.model.epsilon, scene.model.C, scene.model.rigidity
    vals = F.evaluate(disc, phi, eps, C)  # independent re-evaluation (numpy, Definition 2.2)
    kkt = kkt_residual(disc, phi, eps, C, rig, lam_A, lam_B)
    res_A, res_B = vals["A"] - nlp.alpha, vals["B"] - nlp.beta
    finite = bool(np.all(np.isfinite(x)))
    success = bool(stats["success"]) and finite
    feasible = abs(res_A) <= options.tol * disc.volume and abs(res_B) <= options.tol * abs(nlp.beta)
    converged = success and feasible and kkt <= KKT_FACTOR * options.tol
    reason = failure_reason(stats["return_status"], success, kkt, options.tol, feasible)
    _, deriv, other = _times(stats)
    it = stats.get("iterations", {})
    history = {k: list(it.get(k, [])) for k in ("obj", "inf_pr", "inf_du", "mu", "alpha_pr")}
    result = Result(
        phi=phi, w=w, energy=rig * vals["E"], volume_residual=res_A, area_residual=res_B,
        lambda_volume=lam_A, lambda_area=lam_B, kkt_residual=kkt, status=stats["return_status"],
        success=success, converged=converged, iterations=int(stats.get("iter_count", 0)),
        wall_time_s=wall, derivative_time_s=deriv, other_time_s=wall - deriv,
        n_nodes=disc.n_nodes, hessian_nnz_per_row=_hessian_nnz_per_row(solver, x.size),
        history=history, x=x, lam_x=np.asarray(sol["lam_x"]).ravel(),
        lam_g=np.asarray(sol["lam_g"]).ravel(),
        extra={"alpha": nlp.alpha, "beta": nlp.beta, "epsilon": eps, "h": disc.h,
               **({"reason": reason} if reason else {})})
    result = with_topology(disc, result)
    if converged and scene.solver.second_order:
        from .second_order import check
        so = check(nlp, result)
        result = replace_extra(result, second_order=so.verdict,
                               second_order_min_eigenvalue=so.relative_min_eigenvalue)
    else:
        result = replace_extra(result, second_order="not checked")
    if throw and not converged:
        raise SolverError(f"not converged ({reason}): status {result.status}, kkt_residual {kkt:.3g}, "
                          f"A-alpha {res_A:.3g}, B-beta {res_B:.3g}", result)
    return result
