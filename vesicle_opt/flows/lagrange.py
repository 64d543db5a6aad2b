"""Scheme (17): the Lagrange-multiplier scheme that preserves A and B exactly (Lemma 4.2).

    (phi - phi^n)/k + gamma kappa g(phi, phi^n) - lambda_1 - lambda_2 f(phi, phi^n) = 0,
    plus two scalar equations fixing lambda_1, lambda_2.

The paper's second and third equations of (17) are <1, gamma kappa g - lambda_1 - lambda_2 f> = 0 and
<f, gamma kappa g - lambda_1 - lambda_2 f> = 0; given the first equation they are equivalent to
<1, phi - phi^n> = 0 and <f(phi, phi^n), phi - phi^n> = 0, i.e. (by the exact discrete chain rule
of ``discrete``) to A(phi) = A(phi^n) and B(phi) = B(phi^n). We impose them in that form:
    R_phi = phi - phi^n + k (gamma kappa g - lambda_1 - lambda_2 f),
    R_1 = A(phi) - A(phi^n),   R_2 = B(phi) - B(phi^n),
Newton on (phi, lambda_1, lambda_2) (sparse bordered Jacobian; on Fourier grids products and
GMRES). Lemma 4.2 then gives
E(phi) - E(phi^n) + ||phi - phi^n||^2/(gamma k) = 0 to round-off (E = kappa E_h, no penalty).
Initial multipliers: the L^2 projection of gamma kappa g(phi^n) onto span{1, f(phi^n)} (the
continuous-time multipliers), so the step is stateless and resumes exactly from a checkpoint.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from vesicle_opt.flows.base import Scheme, StepOutcome, equality_law
from vesicle_opt.flows.discrete import FlowModel
from vesicle_opt.flows.newton import KrylovBordered, newton

LAW = "Lemma 4.2"


def continuous_multipliers(md: FlowModel, phi: np.ndarray) -> np.ndarray:
    """(lambda_1, lambda_2) minimising ||gamma kappa g(phi) - lambda_1 - lambda_2 f(phi)|| (lumped L^2)."""
    g, f, one = md.gamma * md.g1(phi), md.f1(phi), np.ones_like(phi)
    G = np.array([[md.inner(one, one), md.inner(one, f)], [md.inner(f, one), md.inner(f, f)]])
    return np.linalg.solve(G, [md.inner(one, g), md.inner(f, g)])


class LagrangeScheme(Scheme):
    name = "lagrange"
    law = LAW
    penalised = False  # Lemma 4.2's law is for E itself: A and B are preserved exactly

    def __init__(self, model: FlowModel, law_tol: float, xtol: float = 1e-12, max_iter: int = 25):
        self.model, self.law_tol, self.xtol, self.max_iter = model, law_tol, xtol, max_iter

    def step(self, phi_n: np.ndarray, k: float, guess: np.ndarray) -> StepOutcome:
        md = self.model
        n = phi_n.size
        Fn = md.F(phi_n)
        An, Bn = md.A(phi_n), md.B(phi_n)
        ones = np.ones(n)

        def R(x):
            phi, l1, l2 = x[:n], x[n], x[n + 1]
            r = phi - phi_n + k * (md.gamma * md.g2(phi, phi_n, Fn) - l1 - l2 * md.f2(phi, phi_n))
            return np.concatenate([r, [md.A(phi) - An, md.B(phi) - Bn]])

        def J(x):
            phi, l2 = x[:n], x[n + 1]
            gradB = -md.m * md.f1(phi)
            U = np.column_stack([-k * ones, -k * md.f2(phi, phi_n)])
            V = np.column_stack([md.m, gradB])
            if md.matrix_free:
                return KrylovBordered(md.jacobian_apply(phi, phi_n, k * md.gamma, -k * l2, Fn), U, V,
                                      np.zeros((2, 2)), md.jacobian_model_inverse(k * md.gamma, -k * l2))
            Jpp = sp.identity(n) + k * (md.gamma * md.dg2(phi, phi_n, Fn) - l2 * md.df2(phi, phi_n))
            return Jpp, U, V, np.zeros((2, 2))

        lam0 = continuous_multipliers(md, phi_n)
        res = newton(R, J, np.concatenate([guess, lam0]), xtol=self.xtol, max_iter=self.max_iter,
                     watch=slice(0, n))
        phi = res.x[:n]
        extra = {"lambda_1": float(res.x[n]), "lambda_2": float(res.x[n + 1])}
        if not res.converged:
            return StepOutcome(phi, False, res.iterations, res.message,
                               linear_iterations=res.linear_iterations, extra=extra)
        law, rate = equality_law(md, self.energy, phi_n, phi, k)
        ok = bool(np.isfinite(law) and abs(law) <= self.law_tol)
        return StepOutcome(phi, True, res.iterations, res.message if ok else f"energy law {LAW} violated: {law:.3g}",
                           law_residual=law, law_ok=ok, rate=rate, linear_iterations=res.linear_iterations, extra=extra)
