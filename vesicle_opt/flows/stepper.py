"""The time loop, physics-free: constant or adaptive k, rejection, steady state, checkpoints.

A scheme supplies ``step(phi_n, k, guess) -> StepOutcome`` and ``observe(phi) -> dict``; the stepper
never looks inside. Rules:

* a step is **rejected** when the nonlinear solve fails, the field is not finite, or the scheme's
  energy law is violated (``StepOutcome.law_ok``); k is halved and the step retried. Below ``dt_min``
  the run stops with status ``"failed"`` and the last accepted field (never a NaN field);
* **constant** k: after a rejection the next step returns to the nominal k; the last step is cut to
  land on t_end exactly;
* **adaptive** k ("dynamically adjusted", Section 5): after an accepted step, k grows by ``grow``
  when the solve took <= ``easy_iters`` iterations, shrinks by ``shrink`` when it took more than
  ``hard_iters``, capped by ``dt_max``;
* **steady state**: ||phi_t|| = ||phi^{n+1} - phi^n|| / k below ``steady_tol`` times its value at the
  first step of the run stops the run with status ``"steady"``. Note: (17) and (18) are symmetric
  (midpoint-like) and not L-stable: at k far above the stiff time scale (~ h^4 / (gamma kappa eps))
  stiff modes flip sign each step and decay slowly, so ||phi_t|| may stall while the energy still
  decreases monotonically; cap ``dt_max`` or use (23), which damps them, to reach the criterion;
* ``stop(row)``, if given, ends the run with status ``"stopped"`` when it returns True;
* **checkpoints**: every ``checkpoint_every`` accepted steps (and at the end) the state is written
  atomically to ``checkpoint.npz``; ``resume=True`` restarts from it bit-for-bit (the schemes are
  stateless given phi^n, the previous field and k).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from vesicle_opt.io.output import load_npz, save_npz


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
    checkpoint_every: int = 50
    progress: bool = False


@dataclass(frozen=True)
class RunOutcome:
    phi: np.ndarray
    t: float
    step: int
    status: str  # "t_end" | "steady" | "max_steps" | "stopped" | "failed"
    message: str
    rejections: int
    wall_time_s: float


def run(scheme, phi0: np.ndarray, opts: StepperOptions, *, checkpoint: Path | None = None,
        resume: bool = False, on_accept: Callable[[int, float, np.ndarray, dict], None] | None = None,
        stop: Callable[[dict], bool] | None = None) -> RunOutcome:
    """Advance ``phi0`` from t = 0 (or the checkpoint) to ``opts.t_end``; see the module docstring."""
    phi, phi_prev, t, step, k_try, rate0, rejections, wall0 = phi0.copy(), None, 0.0, 0, opts.dt, math.nan, 0, 0.0
    if resume and checkpoint is not None and checkpoint.exists():
        st = load_npz(checkpoint)
        phi, t, step = st["phi"], float(st["t"]), int(st["step"])
        phi_prev = st["phi_prev"] if st["phi_prev"].size else None
        k_try, rate0 = float(st["k_try"]), float(st["rate0"])
        rejections, wall0 = int(st["rejections"]), float(st["wall_time_s"])
        k_last = float(st["k_last"])
    else:
        k_last = float("nan")
    t_start = time.perf_counter()
    last_print = -math.inf

    def wall():
        return wall0 + time.perf_counter() - t_start

    def save():
        if checkpoint is not None:
            save_npz(checkpoint, phi=phi, phi_prev=phi_prev if phi_prev is not None else np.zeros(0), t=t,
                     step=step, k_try=k_try, k_last=k_last, rate0=rate0, rejections=rejections,
                     wall_time_s=wall())

    status, message = "max_steps", f"reached {opts.max_steps} steps"
    while step < opts.max_steps:
        remaining = opts.t_end - t
        if remaining <= 1e-12 * max(opts.t_end, opts.dt):  # round-off of the accumulated t
            status, message = "t_end", f"reached t = {t:.6g}"
            break
        k = min(k_try, remaining)
        guess = phi if phi_prev is None or not math.isfinite(k_last) else phi + (k / k_last) * (phi - phi_prev)
        out = scheme.step(phi, k, guess)
        ok = out.converged and out.law_ok and bool(np.all(np.isfinite(out.phi)))
        if not ok:
            rejections += 1
            k_try = k / 2
            if k_try < opts.dt_min:
                status = "failed"
                message = f"step {step + 1} rejected down to k = {k:.3g} < dt_min: {out.message}"
                break
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
        if on_accept is not None:
            on_accept(step, t, phi, row)
        if opts.adaptive:
            if out.iterations <= opts.easy_iters:
                k_try = min(k * opts.grow, opts.dt_max)
            elif out.iterations > opts.hard_iters:
                k_try = max(k * opts.shrink, opts.dt_min)
            else:
                k_try = k
        else:
            k_try = opts.dt
        if opts.progress and time.perf_counter() - last_print > 2.0:
            last_print = time.perf_counter()
            print(f"\r  step {step}  t = {t:.4g}/{opts.t_end:.4g}  dt = {k:.3g}  E = {row['energy']:.8g}  "
                  f"law = {out.law_residual:.1e}  rejected = {rejections}", end="", file=sys.stderr, flush=True)
        if stop is not None and stop(row):
            status, message = "stopped", "the caller's stop criterion was met"
            break
        if opts.steady_tol > 0 and out.rate <= opts.steady_tol * rate0:
            status, message = "steady", f"||phi_t|| fell to {out.rate / rate0:.3g} of its first value"
            break
        if opts.checkpoint_every and step % opts.checkpoint_every == 0:
            save()
    save()
    if opts.progress:
        print(file=sys.stderr)
    return RunOutcome(phi, t, step, status, message, rejections, wall())
