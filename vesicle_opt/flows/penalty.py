"""Scheme (18): the symmetric implicit penalty scheme with the discrete energy law (22).

    (phi - phi^n)/k = -gamma { kappa g(phi, phi^n) + M/2 (A(phi) + A(phi^n) - 2 alpha)
                               - M/2 (B(phi) + B(phi^n) - 2 beta) f(phi, phi^n) }

(f, g and the sign of the f term: see ``discrete``). Taking <., phi - phi^n> and the exact discrete
chain rules gives (22): E_M(phi) - E_M(phi^n) + ||phi - phi^n||^2/(gamma k) = 0, to round-off.

On Fourier grids (``FlowModel.matrix_free``) the same Jacobian goes to GMRES as products.
Newton on the bordered unknowns x = (phi, a, b) with a = A(phi), b = B(phi), so the Jacobian
stays sparse (the rank-one terms of the penalty become two extra rows/columns):
    R_phi = phi - phi^n + gamma k { kappa g + M/2 (a + A^n - 2 alpha) - M/2 (b + B^n - 2 beta) f },
    R_a = a - A(phi),   R_b = b - B(phi).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from vesicle_opt.flows.base import Scheme, StepOutcome, equality_law
from vesicle_opt.flows.discrete import FlowModel
from vesicle_opt.flows.newton import KrylovBordered, newton

LAW = "(22)"


class PenaltyScheme(Scheme):
    name = "penalty"
    law = LAW

    def __init__(self, model: FlowModel, law_tol: float, xtol: float = 1e-12, max_iter: int = 25):
        self.model, self.law_tol, self.xtol, self.max_iter = model, law_tol, xtol, max_iter

    def step(self, phi_n: np.ndarray, k: float, guess: np.ndarray) -> StepOutcome:
        md = self.model
        n = phi_n.size
        gk = md.gamma * k
        Fn = md.F(phi_n)
        An, Bn = md.A(phi_n), md.B(phi_n)
        ones = np.ones(n)

        def split(x):
            return x[:n], x[n], x[n + 1]

        def R(x):
            phi, a, b = split(x)
            G = (md.g2(phi, phi_n, Fn) + md.M / 2 * (a + An - 2 * md.alpha)
                 - md.M / 2 * (b + Bn - 2 * md.beta) * md.f2(phi, phi_n))
            return np.concatenate([phi - phi_n + gk * G, [a - md.A(phi), b - md.B(phi)]])

        def J(x):
            phi, a, b = split(x)
            cf = -gk * md.M / 2 * (b + Bn - 2 * md.beta)
            U = np.column_stack([gk * md.M / 2 * ones, -gk * md.M / 2 * md.f2(phi, phi_n)])
            gradB = -md.m * md.f1(phi)  # Euclidean gradient of B
            V = np.column_stack([-md.m, -gradB])
            if md.matrix_free:
                return KrylovBordered(md.jacobian_apply(phi, phi_n, gk, cf, Fn), U, V, np.identity(2),
                                      md.jacobian_model_inverse(gk, cf))
            Jpp = sp.identity(n) + gk * md.dg2(phi, phi_n, Fn) + cf * md.df2(phi, phi_n)
            return Jpp, U, V, np.identity(2)

        x0 = np.concatenate([guess, [md.A(guess), md.B(guess)]])
        res = newton(R, J, x0, xtol=self.xtol, max_iter=self.max_iter, watch=slice(0, n))
        phi = res.x[:n]
        if not res.converged:
            return StepOutcome(phi, False, res.iterations, res.message, linear_iterations=res.linear_iterations)
        law, rate = equality_law(md, self.energy, phi_n, phi, k)
        ok = bool(np.isfinite(law) and abs(law) <= self.law_tol)
        return StepOutcome(phi, True, res.iterations, res.message if ok else f"energy law {LAW} violated: {law:.3g}",
                           law_residual=law, law_ok=ok, rate=rate, linear_iterations=res.linear_iterations)
