"""The time loop, physics-free and I/O-free: constant or adaptive k, rejection, steady state.

A scheme supplies ``step(phi_n, k, guess) -> StepOutcome`` and ``observe(phi) -> dict``; the stepper
never looks inside. Output, progress, checkpoints and caller's stop criteria are **trackers**
(``flows.trackers``, py-pde style) handed to ``run``. Rules:

* a step is **rejected** when the nonlinear solve fails, the field is not finite, or the scheme's
  energy law is violated (``StepOutcome.law_ok``); k is halved and the step retried. Below ``dt_min``
  the run stops with status ``failed`` and the last accepted field (never a NaN field);
* **constant** k: after a rejection the next step returns to the nominal k; the last step is cut to
  land on t_end exactly;
* **adaptive** k ("dynamically adjusted", Section 5): after an accepted step, k grows by ``grow``
  when the solve took <= ``easy_iters`` iterations, shrinks by ``shrink`` when it took more than
  ``hard_iters``, capped by ``dt_max``;
* **trackers**: ``start(state)`` before the first step, ``handle(state, row)`` after every accepted
  step (every tracker, in order; the state is the one a resumed run would start from), ``finish(state)``
  when the loop ends normally (not when an exception escapes: a killed run keeps its last periodic
  checkpoint). A ``handle`` returning True ends the run with status ``stopped``;
* **steady state**: ||phi_t|| = ||phi^{n+1} - phi^n|| / k below ``steady_tol`` times its value at the
  first step of the run stops the run with status ``steady``. It stays here, not in a tracker, because
  its reference value (``rate0``) is part of the resumable ``FlowState``. Note: (17) and (18) are
  symmetric (midpoint-like) and not L-stable: at k far above the stiff time scale
  (~ h^4 / (gamma kappa eps)) stiff modes flip sign each step and decay slowly, so ||phi_t|| may stall
  while the energy still decreases monotonically; cap ``dt_max`` or use (23), which damps them;
* **resume**: ``run(..., start=state)`` continues from a ``FlowState`` (e.g. one a
  ``CheckpointTracker`` saved) bit-for-bit: the schemes are stateless given phi^n, the previous field
  and k.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from vesicle_opt.result import Status

log = logging.getLogger(__name__)  # one DEBUG line per accepted step (the CLI's -v)


@dataclass(frozen=True)
class StepperOptions:
    dt: float
    t_end: float
    max_steps: int
    adaptive: bool = False
    dt_min: float = 1e-14
    dt_max: float = math.inf
    steady_tol: float = 0.0  # 0: never stop early
    grow: float = 1.5
    shrink: float = 0.7
    easy_iters: int = 4
    hard_iters: int = 10


@dataclass(frozen=True, eq=False)
class FlowState:
    """Everything the loop needs to continue exactly: the field, the previous field (extrapolated
    Newton guess), t, the accepted-step count, the next trial k, the last accepted k, ||phi_t|| of the
    run's first step (steady-state reference), rejections so far and the wall time spent."""

    phi: np.ndarray
    phi_prev: np.ndarray | None
    t: float
    step: int
    k_try: float
    k_last: float
    rate0: float
    rejections: int
    wall_time_s: float

    def as_arrays(self) -> dict:
        """The npz form (``phi_prev`` None as an empty array), as checkpoint.npz stores it."""
        return {"phi": self.phi, "phi_prev": self.phi_prev if self.phi_prev is not None else np.zeros(0),
                "t": self.t, "step": self.step, "k_try": self.k_try, "k_last": self.k_last,
                "rate0": self.rate0, "rejections": self.rejections, "wall_time_s": self.wall_time_s}

    @classmethod
    def from_arrays(cls, st: dict) -> FlowState:
        prev = np.asarray(st["phi_prev"])
        return cls(np.asarray(st["phi"]), prev if prev.size else None, float(st["t"]), int(st["step"]),
                   float(st["k_try"]), float(st["k_last"]), float(st["rate0"]), int(st["rejections"]),
                   float(st["wall_time_s"]))


@dataclass(frozen=True, eq=False)
class RunOutcome:
    phi: np.ndarray
    t: float
    step: int
    status: Status  # T_END | STEADY | MAX_STEPS | STOPPED | FAILED (a str enum: == "t_end" holds)
    message: str
    rejections: int
    wall_time_s: float
    state: FlowState  # the final state: ``run(..., start=outcome.state)`` continues the run


def run(scheme, phi0: np.ndarray, opts: StepperOptions, trackers=(), *,
        start: FlowState | None = None) -> RunOutcome:
    """Advance ``phi0`` (or the state ``start``) to ``opts.t_end``; see the module docstring.
    ``trackers``: objects with ``start(state)``, ``handle(state, row) -> bool | None``, ``finish(state)``.
    The loop runs with one BLAS thread (threadpoolctl, as ``nk.solve``): a step's dense work is dot
    products and N x few products, where OpenBLAS's second thread only spin-waits (measured, the 32^3
    backward-Euler path of ``torus_section5`` on a quiet machine, load 0.1: 134 s with the default
    threads against 9.0 s with one)."""
    with threadpool_limits(limits=1, user_api="blas"):
        return _run(scheme, phi0, opts, trackers, start)


def _run(scheme, phi0: np.ndarray, opts: StepperOptions, trackers, start: FlowState | None) -> RunOutcome:
    if start is None:
        phi, phi_prev, t, step, k_try, k_last = phi0.copy(), None, 0.0, 0, opts.dt, math.nan
        rate0, rejections, wall0 = math.nan, 0, 0.0
    else:
        phi, phi_prev, t, step = start.phi.copy(), start.phi_prev, start.t, start.step
        k_try, k_last, rate0, rejections, wall0 = start.k_try, start.k_last, start.rate0, start.rejections, \
            start.wall_time_s
    t_start = time.perf_counter()

    def wall():
        return wall0 + time.perf_counter() - t_start

    def state():
        return FlowState(phi, phi_prev, t, step, k_try, k_last, rate0, rejections, wall())

    trackers = tuple(trackers)
    for tr in trackers:
        tr.start(state())
    status, message = Status.MAX_STEPS, f"reached {opts.max_steps} steps"
    while step < opts.max_steps:
        remaining = opts.t_end - t
        if remaining <= 1e-12 * max(opts.t_end, opts.dt):  # round-off of the accumulated t
            status, message = Status.T_END, f"reached t = {t:.6g}"
            break
        k = min(k_try, remaining)
        guess = phi if phi_prev is None or not math.isfinite(k_last) else phi + (k / k_last) * (phi - phi_prev)
        out = scheme.step(phi, k, guess)
        ok = out.converged and out.law_ok and bool(np.all(np.isfinite(out.phi)))
        if not ok:
            rejections += 1
            if k / 2 < opts.dt_min:  # the saved state keeps k (>= dt_min): a resume retries it and
                status = Status.FAILED  # fails the same way, never below dt_min
                message = f"step {step + 1} rejected down to k = {k:.3g} < dt_min: {out.message}"
                break
            k_try = k / 2
            continue
        phi_prev, phi = phi, out.phi
        t += k
        step += 1
        k_last = k
        if not math.isfinite(rate0):
            rate0 = out.rate
        row = {"step": step, "t": t, "dt": k, **scheme.observe(phi), "energy_law_residual": out.law_residual,
               "newton_iterations": out.iterations, "krylov_iterations": out.linear_iterations,
               "wall_time_s": wall(), "rejections": rejections,
               "phi_t_norm": out.rate, **out.extra}
        if opts.adaptive:
            if out.iterations <= opts.easy_iters:
                k_try = min(k * opts.grow, opts.dt_max)
            elif out.iterations > opts.hard_iters:
                k_try = max(k * opts.shrink, opts.dt_min)
            else:
                k_try = k
        else:
            k_try = opts.dt
        if log.isEnabledFor(logging.DEBUG):
            log.debug("step %d  t = %.6g  dt = %.3g  E = %.10g  law = %.1e  newton = %d  rejected = %d",
                      step, t, k, row.get("energy", math.nan), out.law_residual, out.iterations, rejections)
        now = state()
        stop = [bool(tr.handle(now, row)) for tr in trackers]  # every tracker sees every accepted step
        if any(stop):
            status, message = Status.STOPPED, "the caller's stop criterion was met"
            break
        if opts.steady_tol > 0 and out.rate <= opts.steady_tol * rate0:
            status, message = Status.STEADY, f"||phi_t|| fell to {out.rate / rate0:.3g} of its first value"
            break
    final = state()
    for tr in trackers:
        tr.finish(final)
    return RunOutcome(phi, t, step, status, message, rejections, final.wall_time_s, final)
