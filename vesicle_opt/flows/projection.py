"""Initial data on the constraint set {A = alpha, B = beta} for scheme (17), cheaply.

1. Volume, by a scalar root-find (exact for the lumped case): phi_A = clip(phi_0 + c, -1, 1) with c
   solving sum_i m_i clip(phi_0,i + c, -1, 1) = alpha. The left side is continuous, piecewise linear
   and non-decreasing in c, so bisection (brentq) brackets it and a final linear solve on the active
   set of unclipped nodes makes A(phi_A) = alpha to round-off. Bounds -1 <= phi <= 1 hold.
2. Area, by Gauss-Newton with minimal-L^2 steps: phi <- phi + mu_1 + mu_2 f(phi), the correction
   along span{1, f(phi)} (f = -grad B, the directions of the multipliers of (13)/(17)) with
   (mu_1, mu_2) from the 2x2 linearisation of A(phi) = alpha, B(phi) = beta, backtracking on the
   residual, f re-evaluated at every iterate; stops at 1e-14 relative. It moves the interface along
   its normal where f is large; it may leave |phi| slightly above 1, which the flow corrects.
Returns the projected field; raises ``SolverError`` if step 2 does not converge (e.g. beta far
from B(phi_0)), never a field off the constraint set.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.errors import SolverError
from vesicle_opt.flows.discrete import FlowModel


def project_volume(md: FlowModel, phi0: np.ndarray, alpha: float) -> np.ndarray:
    m = md.m
    total = float(m.sum())
    if not -total < alpha < total:
        raise SolverError(f"alpha = {alpha:.6g} outside (-|Omega|, |Omega|) = ({-total:.6g}, {total:.6g})")

    def A(c):
        return float(m @ np.clip(phi0 + c, -1.0, 1.0)) - alpha

    from scipy.optimize import brentq  # third-party, lazy: scipy.optimize costs 0.2-0.5 s at import
    c = brentq(A, -2.0 - np.max(phi0), 2.0 - np.min(phi0), xtol=1e-15, rtol=4 * np.finfo(float).eps)
    for _ in range(5):  # exact linear solve on the active set (piecewise-linear A)
        free = np.abs(phi0 + c) < 1.0
        if not free.any():
            break
        clipped = np.clip(phi0 + c, -1.0, 1.0)
        c_new = c + (alpha - float(m @ clipped)) / float(m[free].sum())
        if np.array_equal(np.abs(phi0 + c_new) < 1.0, free):
            c = c_new
            break
        c = c_new
    return np.clip(phi0 + c, -1.0, 1.0)


def project(md: FlowModel, phi0: np.ndarray, alpha: float, beta: float, rtol: float = 1e-14,
            max_iter: int = 200, volume_first: bool = True) -> np.ndarray:
    """Map phi0 onto A = alpha, B = beta (see the module docstring). ``volume_first=False`` skips
    step 1 (for a warm start near the set: an equilibrium overshoots |phi| = 1 slightly, and the
    clip of step 1 would move it by ~1e-2; step 2 alone corrects A and B by a tiny step)."""
    phi = project_volume(md, phi0, alpha) if volume_first else np.array(phi0, float)
    one = np.ones_like(phi)

    def G(p):
        return np.array([(md.A(p) - alpha) / abs(alpha), (md.B(p) - beta) / beta])

    r = G(phi)
    for _ in range(max_iter):
        if np.max(np.abs(r)) <= rtol:
            return phi
        f = md.f1(phi)  # -grad B (lumped L^2)
        Jm = np.array([[md.inner(one, one) / abs(alpha), md.inner(one, f) / abs(alpha)],
                       [-md.inner(f, one) / beta, -md.inner(f, f) / beta]])
        mu = np.linalg.solve(Jm, -r)
        s = 1.0
        while True:
            trial_phi = phi + s * (mu[0] * one + mu[1] * f)
            trial = G(trial_phi)
            if np.max(np.abs(trial)) < np.max(np.abs(r)) or s < 1e-6:
                break
            s /= 2
        if np.max(np.abs(trial)) >= np.max(np.abs(r)):
            break  # no decrease along the Gauss-Newton direction
        phi, r = trial_phi, trial
    if np.max(np.abs(r)) <= rtol:
        return phi
    raise SolverError(f"projection onto A = {alpha:.6g}, B = {beta:.6g} did not converge "
                      f"(relative residuals {r[0]:.2e}, {r[1]:.2e}); start closer to the target")
