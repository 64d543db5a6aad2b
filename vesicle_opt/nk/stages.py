"""The stages of the penalised methods on the matrix-free backend (``nk.solve``; ``nk_jax`` reuses
them): penalty (one M), continuation (M0 r^k, stopped where the next stage's floor would reach tol,
ending on the augmented polish) and augmented (secant multiplier updates, floor-capped M); the rules
are ``model.penalty``'s, the same as the IPOPT path's (``nlp.continuation``)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from vesicle_opt.model.penalty import (AL_REDUCTION, DualSecant, certifiable_M, extrapolation, next_stage,
                                       penalty_retry, ramp_schedule, raise_M, schedule)
from vesicle_opt.nk.newton_cg import Objective, newton_minimize

POLISH_STAGES = 4  # as nlp.continuation.POLISH_STAGES


@dataclass
class Stage:
    """One inner solve of a level: its point, status, multiplier data, dual test and own counts."""

    pt: object
    status: str
    M: tuple[float, float] | None  # None for 'exact'
    mu: tuple[float, float]
    lam: np.ndarray | None  # the least-squares multipliers of 'exact' (penalty: mu - M c, recomputed)
    dual: float  # the stopping test's value (``kkt_dual_solver``: the certificate's quotient, ``verify.kkt.terms_scale``)
    newton: int
    wall_s: float
    deriv_s: float
    polish: bool = False  # continuation's augmented polish (``penalty_stages``): certified with exact constraints


def timed_stage(obj: Objective, solve_inner) -> tuple:
    cnt = obj.cnt
    t0, n0, d0 = time.perf_counter(), cnt.newton, cnt.deriv_time
    out = solve_inner()
    return out, cnt.newton - n0, time.perf_counter() - t0, cnt.deriv_time - d0


def penalty_stages(obj: Objective, phi, tol, opts, method, s, volume, beta,
                   minimize=newton_minimize, floor=None) -> list[Stage]:
    """penalty (one M), continuation (the schedule M0 ... M_max, every stage warm-started from the
    last, as on IPOPT) or augmented (mu updates; stops at the first stage that converged and holds
    the constraints to tol, at most solver.max_outer stages). ``minimize``: the inner Newton-CG,
    ``newton_cg.newton_minimize`` or ``nk_jax.newton.newton_minimize`` (the same loop on devices).

    ``floor(pt, M)``: the certificate's floor of a stage (``verify.certify.dual_floor_of``). Given,
    continuation stops raising M where the next stage's floor would reach tol
    (``model.penalty.next_stage``) and ends on the augmented polish (a last Stage with ``polish``:
    the multipliers extrapolated in 1/M as shifts, ``model.penalty.extrapolation``), and augmented
    keeps M where its floor stays below tol (``model.penalty.raise_M``); as on IPOPT."""
    stages: list[Stage] = []

    def run(M, mu, polish=False):
        obj.lam, obj.rho = np.asarray(mu, float).copy(), np.array([M, M], float)
        (pt, status), n, wall, deriv = timed_stage(
            obj, lambda: minimize(obj, phi, tol, opts.max_iter - obj.cnt.newton, opts.max_cg))
        stages.append(Stage(pt, status, (M, M), tuple(mu), None, obj.stationarity(pt), n, wall, deriv, polish))
        return pt, status

    if method == "augmented":
        M, mu, prev, secant = s.M_value, np.zeros(2), (math.inf, math.inf), DualSecant()
        if floor is not None:
            for Mk in ramp_schedule(s, M):  # warm-up stages at mu = 0 (model.penalty.ramp_schedule)
                if Mk >= M:  # M was lowered to the certifiable M by an earlier ramp stage's floor
                    break
                pt, status = run(Mk, mu)
                if not np.all(np.isfinite(pt.phi)):
                    return stages
                phi = pt.phi
                M = min(M, certifiable_M(floor(pt, Mk), Mk, tol))
            stages.clear()  # not multiplier stages: their Newton steps count, their records go
        for _ in range(s.max_outer):
            pt, status = run(M, mu)
            if not np.all(np.isfinite(pt.phi)):
                break
            phi = pt.phi
            res = (abs(pt.c[0]) / volume, abs(pt.c[1]) / abs(beta))
            if status == "converged" and res[0] <= tol and res[1] <= tol:
                break
            mu = secant.step(mu, pt.c, M)  # first step: lambda = mu - M c, then Broyden
            M = M if floor is None else raise_M(M, res, prev, floor(pt, M), tol, s.M_factor, s.M_max)
            if floor is None and any(rn > AL_REDUCTION * rp and rn > tol for rn, rp in zip(res, prev)):
                M = min(M * s.M_factor, s.M_max)
            prev = res
        return stages
    sched = [s.M_value] if method == "penalty" else schedule(s.M0, s.M_factor, s.M_max)
    i, M = 0, sched[0]
    while M is not None:
        pt, status = run(M, np.zeros(2))
        if not np.all(np.isfinite(pt.phi)):
            break
        phi = pt.phi
        if floor is None:
            nxt = sched[i + 1] if i + 1 < len(sched) else None
        elif method == "penalty":
            nxt = penalty_retry(M, floor(pt, M), tol, s.M_auto) if len(stages) == 1 and status == "converged" else None
        else:
            nxt = next_stage(sched, i, floor(pt, M), tol)
        if nxt is not None and i + 1 < len(sched) and nxt == sched[i + 1]:
            i += 1
        elif nxt is not None:
            sched, i = [M, nxt], 1  # the last stage, at the certifiable M (nothing after it)
        M = nxt
    if method == "continuation" and floor is not None and stages[-1].status == "converged":
        ext = extrapolation([{"M": st.M[0], "energy": obj.rig * st.pt.E, "lambda_volume": st.pt.mu[0],
                              "lambda_area": st.pt.mu[1], "volume_residual": st.pt.c[0],
                              "area_residual": st.pt.c[1], "converged": st.status == "converged"}
                             for st in stages])
        if ext:  # as nlp.continuation.polish_stage: secant stages from the extrapolated multipliers
            M, mu, secant = stages[-1].M[0], np.array([ext["lambda_volume_extrapolated"],
                                                        ext["lambda_area_extrapolated"]]), DualSecant()
            for _ in range(POLISH_STAGES):
                pt, status = run(M, mu, polish=True)
                if not np.all(np.isfinite(pt.phi)) or (status == "converged" and abs(pt.c[0]) <= tol * volume
                                                       and abs(pt.c[1]) <= tol * abs(beta)):
                    break
                phi = pt.phi
                mu = secant.step(mu, pt.c, M)
    return stages
