"""IPOPT through CasADi: frozen options, building a solver once, one call, and its statistics.

IPOPT runs with the exact Hessian and MUMPS. The NLPs are scaled by design (``nlp.exact``), so
IPOPT's own gradient-based rescaling is off (it would rescale f by 100 / |grad f(x0)|, a test that
depends on the start).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from vesicle_opt.io import interrupt, progress
from vesicle_opt.nlp.iteration_progress import IterationProgress

_DERIV_KEYS = ("nlp_grad_f", "nlp_jac_g", "nlp_hess_l", "nlp_grad")
HISTORY_KEYS = ("obj", "inf_pr", "inf_du", "mu", "alpha_pr")
VERBOSE_PRINT_LEVEL = 5  # IPOPT's own iteration log (one line per iteration), shown at DEBUG (the CLI's -v)
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class IpoptOptions:
    """IPOPT's settings (optimistix style: frozen, tol required)."""

    tol: float
    max_iter: int = 500
    print_level: int = 0
    extra: tuple = ()  # further ("ipopt.key", value) pairs; they win over the defaults

    @classmethod
    def from_scene(cls, scene: "Scene") -> "IpoptOptions":
        """The scene's tolerances; IPOPT's iteration log on stdout when this module's logger is at
        DEBUG (``vesicle-opt -v``), silent otherwise."""
        level = VERBOSE_PRINT_LEVEL if log.isEnabledFor(logging.DEBUG) else 0
        return cls(tol=scene.solver.tol, max_iter=scene.solver.max_iter, print_level=level)

    def as_dict(self) -> dict:
        """The options as ``casadi.nlpsol`` takes them (``ipopt.*`` keys, ``extra`` last)."""
        opts = {"ipopt.tol": self.tol, "ipopt.constr_viol_tol": self.tol,
                "ipopt.max_iter": self.max_iter, "ipopt.print_level": self.print_level,
                "ipopt.sb": "yes", "print_time": False, "ipopt.linear_solver": "mumps",
                "ipopt.mu_strategy": "adaptive",
                "ipopt.nlp_scaling_method": "none"}  # the NLP is scaled by design (nlp.exact)
        opts.update(dict(self.extra))
        return opts


def make_solver(nlp, options: IpoptOptions):
    """``ca.nlpsol`` of an NLP's {"x", "f", "g", "p"} dict, built once; with progress on (the CLI),
    IPOPT's iterations drive a progress bar (``nlp.iteration_progress``)."""
    import casadi as ca  # third-party, lazy: only IPOPT paths need it (0.25 s at import)
    d, opts = nlp.as_dict(), options.as_dict()
    bar = None
    if progress.enabled():
        n_p = d["p"].numel() if "p" in d else 0
        bar = IterationProgress(d["x"].numel(), d["g"].numel(), n_p)
        opts["iteration_callback"] = bar
    solver = ca.nlpsol("equilibrium", "ipopt", d, opts)
    if bar is not None:
        solver.iteration_progress = bar  # the callback must live as long as the solver
    return solver


def run_ipopt(solver, nlp, x0, p=None, lam_x0=None, lam_g0=None):
    """One IPOPT call with the NLP's bounds: (sol, stats, wall seconds, x as a flat array)."""
    args = {"x0": x0, "lbx": nlp.lbx, "ubx": nlp.ubx, "lbg": nlp.lbg, "ubg": nlp.ubg}
    for key, value in (("p", p), ("lam_x0", lam_x0), ("lam_g0", lam_g0)):
        if value is not None:
            args[key] = value
    t0 = time.perf_counter()
    try:
        sol = solver(**args)
    finally:
        bar = getattr(solver, "iteration_progress", None)
        if bar is not None:
            bar.close()
    interrupt.check()  # CasADi turns a Ctrl-C inside IPOPT into a status: never a result (io.interrupt)
    wall = time.perf_counter() - t0
    return sol, solver.stats(), wall, np.asarray(sol["x"]).ravel()


def derivative_time(stats: dict) -> float:
    """Seconds IPOPT spent in gradient, Jacobian and Hessian evaluations."""
    return sum(float(stats.get(f"t_wall_{k}", 0.0)) for k in _DERIV_KEYS)


def history(stats: dict) -> dict:
    """IPOPT's per-iteration log (objective, infeasibilities, barrier parameter, step)."""
    it = stats.get("iterations", {})
    return {k: list(it.get(k, [])) for k in HISTORY_KEYS}


def hessian_nnz_per_row(solver, n: int) -> float:
    """Nonzeros per row of the Lagrangian Hessian IPOPT factorises (the full symmetric pattern)."""
    try:
        sp_h = solver.get_function("nlp_hess_l").sparsity_out(0)
    except RuntimeError:
        return float("nan")
    nnz = sp_h.nnz()
    if sp_h.is_triu() or sp_h.is_tril():  # one triangle stored: count the full symmetric pattern
        nnz = 2 * nnz - n
    return nnz / n
