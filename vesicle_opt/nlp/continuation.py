"""Penalty continuation M_k = M0 r^k -> M_max and the augmented-Lagrangian variant, on ONE solver.

Both drive the lifted penalty NLP of ``nlp.lifted`` (E_{M,h} of (11), M a CasADi parameter), so
the IPOPT solver is built once and every stage is warm-started from the previous one: primal x,
lam_g, lam_x, and IPOPT's ``warm_start_init_point`` (options in ``WARM_OPTIONS``).

* ``continuation`` (Theorem 3.2, 3.4): penalty stages at M0, M0 r, ... while the next stage's
  round-off floor (linear in M) stays below tol, then one at the certifiable M where M_max lies
  beyond it (``model.penalty.next_stage``), so the last stage is certified; the penalty's bias is
  O(1/M): A - alpha ~ -lambda_A / M, and the Richardson extrapolation in 1/M of energy and
  multipliers (``model.penalty.extrapolation``) is reported beside the last stage, which then gets
  the augmented polish (``polish_stage``: one stage with the extrapolated multipliers as shifts).
* ``augmented_lagrangian``: the natural fix of that bias. A warm ramp at mu = 0 through the
  schedule below M (``model.penalty.ramp_schedule``), then stages minimising
  E_{M,h} - mu_k (A - alpha, B - beta) with mu moved by Broyden's secant method on c(mu) = 0 from the
  first-order update mu - M (A - alpha, B - beta) (``model.penalty.DualSecant``); M is kept where its
  floor stays below tol (``model.penalty.raise_M``). Stops when the exact solve's feasibility test
  holds, so its ``converged`` means what the exact solve's does.
* ``penalty`` (``solve_penalised``): one stage at solver.M, again at the certifiable M where the
  floor at solver.M reached tol (``model.penalty.penalty_retry``; ``M_requested`` reported).

Every stage is recorded in ``result.history['stages']`` (M, energies, residuals, multiplier
estimates, iterations, wall time, status); ``stage_callback(k, result)`` sees each one as it ends.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from vesicle_opt.model.penalty import (DualSecant, certifiable_M, extrapolation, next_stage, penalty_retry, raise_M,
                                       ramp_schedule, schedule)
from vesicle_opt.nlp.ipopt import IpoptOptions, make_solver
from vesicle_opt.nlp.lifted import PenaltyNLP
from vesicle_opt.nlp.solve import solve_stage
from vesicle_opt.result import Result, combine_stages, polish_keys, stage_record

WARM_OPTIONS = (("ipopt.warm_start_init_point", "yes"), ("ipopt.warm_start_bound_push", 1e-9),
                ("ipopt.warm_start_mult_bound_push", 1e-9), ("ipopt.mu_init", 1e-6))
# The NLP is scaled by design (nlp.exact; IpoptOptions sets this for every solve, repeated here as the
# penalty's own reason): IPOPT's gradient-based rescaling of f would loosen the
# dual tolerance by the large u-gradient at a warm start with a 10x larger M (measured on 64^2:
# stationarity 5e-6 instead of 6e-8 at M = 1e6, and cold solves at M >= 1e8 ending off the minimiser).
# The lifted rows A - a, B - b must hold far below the penalty bias ~1/M, or M (A - alpha) is off
# by M |A - a|: with constr_viol_tol = tol IPOPT stopped at |B - b|/beta = 4e-12 on 128^2, i.e. an
# error 4e-5 in lambda_B at M = 1e6 and 1e-3 at 1e8. The rows are O(1)-scaled, so 1e-14 is a few
# ulps above their evaluation round-off (measured lift gaps 1e-16 ... 6e-15 on FD, P1 lumped,
# consistent and Gauss, M = 1e1 ... 1e8), reached by one extra Newton step on these rows.
POLISH_STAGES = 4  # the polish's augmented stages at most (1 on the default scene; 3 where the last M is
# small and the extrapolated multipliers are off by ~20%: circle-2d, M = 270)
PENALTY_OPTIONS = (("ipopt.nlp_scaling_method", "none"), ("ipopt.constr_viol_tol", 1e-14))


def penalty_options(nlp: PenaltyNLP, options: IpoptOptions | None = None, warm: bool = False) -> IpoptOptions:
    """The scene's IPOPT options plus PENALTY_OPTIONS (and WARM_OPTIONS); user extras win."""
    options = options or IpoptOptions.from_scene(nlp.scene)
    extra = PENALTY_OPTIONS + (WARM_OPTIONS if warm else ()) + tuple(options.extra)
    return dataclasses.replace(options, extra=extra)


def continuation(nlp: PenaltyNLP, Ms: list[float] | None = None, *, options: IpoptOptions | None = None,
                 warm: bool = True, x0=None, lam_x0=None, lam_g0=None, solver=None,
                 stage_callback=None, polish: bool = True) -> Result:
    """Penalty stages at increasing M on one solver; the result is the last stage's (see module doc).

    Without ``Ms`` the scene's schedule runs while the next stage's floor stays below tol
    (``model.penalty.next_stage``), so the last stage is certifiable; given ``Ms`` run as they are
    (studies of the law beyond that). The Richardson extrapolation of the stages
    (``model.penalty.extrapolation``) and the augmented polish (``polish_stage``) go into ``extra``.
    warm=False restarts every stage from the initial guess (for measuring what warm starts buy).
    """
    s = nlp.scene.solver
    given = Ms is not None
    sched = list(Ms) if given else schedule(s.M0, s.M_factor, s.M_max)
    options = penalty_options(nlp, options, warm)
    solver = solver or make_solver(nlp, options)
    x, lam_x, lam_g = (nlp.x0 if x0 is None else x0), lam_x0, lam_g0
    stages: list[Result] = []
    t0 = time.perf_counter()
    i, M = 0, sched[0]
    while M is not None:
        p = nlp.parameters(M)
        if not warm:
            x, lam_x, lam_g = nlp.x0, None, None
        r = solve_stage(nlp, solver, p, x0=x, lam_x0=lam_x, lam_g0=lam_g, tol=options.tol,
                        method="continuation")
        stages.append(r)
        if stage_callback is not None:
            stage_callback(len(stages) - 1, r)
        if np.all(np.isfinite(r.x)):
            x, lam_x, lam_g = r.x, r.lam_x, r.lam_g
        nxt = (sched[i + 1] if i + 1 < len(sched) else None) if given else \
            next_stage(sched, i, r.extra["kkt_dual_floor"], options.tol)
        if nxt is not None and i + 1 < len(sched) and nxt == sched[i + 1]:
            i += 1
        elif nxt is not None:
            sched, i = [M, nxt], 1  # the last stage, at the certifiable M (nothing after it)
        M = nxt
    failed = sum(not r.success for r in stages)
    info = {"failed_stages": failed, **extrapolation([stage_record(r) for r in stages])}
    if polish and "lambda_volume_extrapolated" in info and stages[-1].converged:
        info.update(polish_stage(nlp, solver, stages[-1], info, options.tol))
    its = sum(r.iterations for r in stages) + info.get("polish_iterations", 0)  # the run's, as on NK
    return combine_stages(stages[-1], stages, "continuation", time.perf_counter() - t0, info, iterations=its)


def polish_stage(nlp: PenaltyNLP, solver, last: Result, ext: dict, tol: float) -> dict:
    """The augmented polish: augmented-Lagrangian stages at the last M with the multiplier shifts
    mu = the extrapolated multipliers, warm-started from the last stage (at most ``POLISH_STAGES``,
    moving mu by ``model.penalty.DualSecant`` until certified). Its minimiser holds
    A - alpha = (mu - lambda)/M, so with mu within O(1/M^2) of lambda* the constraints hold to
    O(1/M^3) and one stage is certified with exact constraints (2 IPOPT iterations on the default
    scene), at the cost of warm stages of the same solver (an exact polish would build and factor a
    second NLP). ``polish_*`` keys (``polish_iterations``: all its stages')."""
    mu = np.array([ext["lambda_volume_extrapolated"], ext["lambda_area_extrapolated"]])
    secant, x, lam_x, lam_g, its = DualSecant(), last.x, last.lam_x, last.lam_g, 0
    for _ in range(POLISH_STAGES):
        r = solve_stage(nlp, solver, nlp.parameters(last.M, mu=tuple(mu)), x0=x, lam_x0=lam_x, lam_g0=lam_g,
                        tol=tol, method="augmented", exact_constraints=True)
        its += r.iterations
        if r.converged or not np.all(np.isfinite(r.x)):
            break
        x, lam_x, lam_g = r.x, r.lam_x, r.lam_g
        mu = secant.step(mu, (r.volume_residual, r.area_residual), last.M)
    return {**polish_keys(r), "polish_iterations": its}


def augmented_lagrangian(nlp: PenaltyNLP, M: float | None = None, *, options: IpoptOptions | None = None,
                         max_outer: int | None = None, x0=None, lam_x0=None, lam_g0=None, solver=None,
                         stage_callback=None) -> Result:
    """Multiplier updates between warm-started stages (``model.penalty.DualSecant``: first
    mu <- mu - M (A - alpha, B - beta), then Broyden secant steps on c(mu) = 0); M grows only while
    the floor stays below tol (``model.penalty.raise_M``). Every stage is certified with the exact
    constraints (the method's promise), so the first converged stage ends it."""
    s = nlp.scene.solver
    M = float(M or s.M_value)
    max_outer = max_outer or s.max_outer
    options = penalty_options(nlp, options, True)
    solver = solver or make_solver(nlp, options)
    tol, vol, beta = options.tol, nlp.disc.volume, abs(nlp.beta)
    mu = (0.0, 0.0)
    x, lam_x, lam_g = (nlp.x0 if x0 is None else x0), lam_x0, lam_g0
    prev = (math.inf, math.inf)
    secant = DualSecant()
    stages: list[Result] = []
    t0 = time.perf_counter()
    ramp_its = 0
    for Mk in ramp_schedule(s, M):  # warm starts up to M (a cold start at M = 1e4 took 63 iterations)
        if Mk >= M:  # M was lowered to the certifiable M by an earlier ramp stage's floor
            break
        r = solve_stage(nlp, solver, nlp.parameters(Mk), x0=x, lam_x0=lam_x, lam_g0=lam_g, tol=tol,
                        method="augmented", exact_constraints=True)
        ramp_its += r.iterations
        if not np.all(np.isfinite(r.x)):
            break
        x, lam_x, lam_g = r.x, r.lam_x, r.lam_g
        M = min(M, certifiable_M(r.extra["kkt_dual_floor"], Mk, tol))
    for k in range(max_outer):
        r = solve_stage(nlp, solver, nlp.parameters(M, mu=mu), x0=x, lam_x0=lam_x, lam_g0=lam_g,
                        tol=tol, method="augmented", exact_constraints=True)
        stages.append(r)
        if stage_callback is not None:
            stage_callback(k, r)
        if r.converged or not np.all(np.isfinite(r.x)):
            break
        x, lam_x, lam_g = r.x, r.lam_x, r.lam_g
        res = (abs(r.volume_residual) / vol, abs(r.area_residual) / beta)
        mu = tuple(secant.step(mu, (r.volume_residual, r.area_residual), M))  # first step: lambda = mu - M c
        M = raise_M(M, res, prev, r.extra["kkt_dual_floor"], tol, s.M_factor, s.M_max)
        prev = res
    last = stages[-1]
    return combine_stages(last, stages, "augmented", time.perf_counter() - t0, {"ramp_iterations": ramp_its},
                          iterations=ramp_its + sum(r.iterations for r in stages))


def solve_penalised(nlp: PenaltyNLP, *, x0=None, lam_x0=None, lam_g0=None, solver=None,
                    options: IpoptOptions | None = None) -> Result:
    """The methods penalty (one solve at solver.M; again, warm, at the certifiable M where the floor at
    solver.M reached tol: ``model.penalty.penalty_retry``), continuation and augmented on IPOPT."""
    s = nlp.scene.solver
    start = {"x0": x0, "lam_x0": lam_x0, "lam_g0": lam_g0}
    if s.method == "continuation":
        return continuation(nlp, options=options, solver=solver, **start)
    if s.method == "augmented":
        return augmented_lagrangian(nlp, options=options, solver=solver, **start)
    options = penalty_options(nlp, options)
    solver = solver or make_solver(nlp, options)
    r = solve_stage(nlp, solver, nlp.parameters(s.M_value), x0=x0, lam_x0=lam_x0, lam_g0=lam_g0, tol=options.tol)
    M = penalty_retry(s.M_value, r.extra["kkt_dual_floor"], options.tol, s.M_auto) if r.success else None
    if M is None:
        return r
    again = solve_stage(nlp, solver, nlp.parameters(M), x0=r.x, lam_x0=r.lam_x, lam_g0=r.lam_g, tol=options.tol)
    return combine_stages(again, [r, again], "penalty", r.wall_time_s + again.wall_time_s, {"M_requested": s.M_value})
