"""Initial data on the constraint set {A = alpha, B = beta} for scheme (17), cheaply.

1. Volume, by a scalar root-find (exact for the lumped case): phi_A = clip(phi_0 + c, -1, 1) with c
   solving sum_i m_i clip(phi_0,i + c, -1, 1) = alpha. The left side is continuous, piecewise linear
   and non-decreasing in c, so bisection (brentq) brackets it and a final linear solve on the active
   set of unclipped nodes makes A(phi_A) = alpha to round-off. Bounds -1 <= phi <= 1 hold.
2. Area, by Newton on two scalars: phi(mu) = phi_A + mu_1 + mu_2 f(phi_A), the minimal-L^2 correction
   along span{1, f} (f = -grad B, the directions of the multipliers of (13)/(17)), solving
   A(phi(mu)) = alpha, B(phi(mu)) = beta to 1e-14 relative with a 2x2 Jacobian and backtracking.
   Step 2 keeps the shape's geometry (it moves the interface along its normal where f is large);
   it may leave |phi| slightly above 1, which the flow corrects.
Returns the projected field; raises ``SolverError`` if step 2 does not converge (e.g. beta far
from B(phi_0)), never a field off the constraint set.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from ..errors import SolverError
from .discrete import FlowModel


def project_volume(md: FlowModel, phi0: np.ndarray, alpha: float) -> np.ndarray:
    m = md.m
    total = float(m.sum())
    if not -total < alpha < total:
        raise SolverError(f"alpha = {alpha:.6g} outside (-|Omega|, |Omega|) = ({-total:.6g}, {total:.6g})")

    def A(c):
        return float(m @ np.clip(phi0 + c, -1.0, 1.0)) - alpha

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
            max_iter: int = 50) -> np.ndarray:
    """Map phi0 onto A = alpha, B = beta (see the module docstring)."""
    phiA = project_volume(md, phi0, alpha)
    one, fA = np.ones_like(phiA), md.f1(phiA)

    def field(mu):
        return phiA + mu[0] * one + mu[1] * fA

    def G(mu):
        phi = field(mu)
        return np.array([(md.A(phi) - alpha) / abs(alpha), (md.B(phi) - beta) / beta])

    mu = np.zeros(2)
    r = G(mu)
    for _ in range(max_iter):
        if np.max(np.abs(r)) <= rtol:
            return field(mu)
        gB = -md.f1(field(mu))  # lumped-L^2 gradient of B
        Jm = np.array([[md.inner(one, one) / abs(alpha), md.inner(one, fA) / abs(alpha)],
                       [md.inner(gB, one) / beta, md.inner(gB, fA) / beta]])
        step = np.linalg.solve(Jm, -r)
        s = 1.0
        while s > 1e-4:
            trial = G(mu + s * step)
            if np.max(np.abs(trial)) < np.max(np.abs(r)):
                break
            s /= 2
        mu, r = mu + s * step, trial
    if np.max(np.abs(r)) <= rtol:
        return field(mu)
    raise SolverError(f"projection onto A = {alpha:.6g}, B = {beta:.6g} did not converge "
                      f"(relative residuals {r[0]:.2e}, {r[1]:.2e}); start closer to the target")
