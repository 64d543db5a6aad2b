"""Gauss-Newton sequential convex programming (SCP) baseline with cvxpy (optional; small meshes).

E_h (6) with nodal quadrature is a weighted sum of squares, E_h = 1/(2 eps) sum_i m_i r_i(phi)^2 with
r = eps Delta_h phi + (phi/eps + C)(1 - phi^2) (lumped mass / FD only). Each step solves the convex QP

    min_d  1/(2 eps) sum_i m_i (r_i + (J d)_i)^2 + nu (|A(phi + d) - alpha| + |B + dB.d - beta|)
    s.t.   |d|_inf <= Delta,

J = eps Delta_h + diag(g'(phi)) (``functionals.reaction_derivative``): the residual and B linearised, A exact (linear),
the constraints as an exact l1 penalty (nu > |lambda| makes it exact; nu = NU). The step is taken if
the actual reduction of the merit E + nu(|A - alpha| + |B - beta|) is at least RHO_ACCEPT of the
model's; the trust radius Delta halves or doubles accordingly. Gauss-Newton converges linearly on
this nonzero-residual problem: a baseline, not a method to use. Records after each iteration
(time, merit, residuals) so one run gives a whole error-against-time curve.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from vesicle_opt.model import functionals as F
from vesicle_opt.nlp.exact import NLP

NU = 10.0  # exceeds the multipliers |lambda| < 1 of the 2D scenes: the l1 penalty is then exact
RHO_ACCEPT = 0.1  # standard trust-region acceptance ratio


def _merit(disc, phi, eps, C, alpha, beta):
    v = F.evaluate(disc, phi, eps, C)
    return v["E"] + NU * (abs(v["A"] - alpha) + abs(v["B"] - beta)), v


def scp(nlp: NLP, *, max_iter: int = 50, tol: float = 1e-6, delta0: float = 0.5, record=None) -> dict:
    """Run SCP from nlp.x0; ``record(k, phi, info)`` is called after every iteration."""
    disc, sc = nlp.disc, nlp.scene
    disc.require_lumped("the SCP baseline", "its residual is nodal: E_h = 1/(2 eps) sum_i m_i r_i^2")
    import cvxpy as cp  # optional dependency (the SCP baseline only)
    eps, C = sc.model.epsilon, sc.model.C
    L, m = disc.laplacian, disc.weights
    phi = nlp.split(nlp.x0)[0].copy()
    delta = delta0
    t0 = time.perf_counter()
    merit, vals = _merit(disc, phi, eps, C, nlp.alpha, nlp.beta)
    sqrtw = np.sqrt(m / (2 * eps))
    status = "max_iter"
    for k in range(max_iter):
        r = F.curvature_residual(phi, L @ phi, eps, C)
        J = eps * L + sp.diags(F.reaction_derivative(phi, eps, C))  # Jacobian of f_c
        _, dA, dB = F.gradients(disc, phi, eps, C)
        d = cp.Variable(phi.size)
        res_lin = sqrtw * r + sp.diags(sqrtw) @ J @ d
        cA = vals["A"] - nlp.alpha
        cB = vals["B"] - nlp.beta
        obj = cp.sum_squares(res_lin) + NU * (cp.abs(cA + dA @ d) + cp.abs(cB + dB @ d))
        prob = cp.Problem(cp.Minimize(obj), [cp.norm(d, "inf") <= delta])
        prob.solve(solver=cp.CLARABEL)
        if d.value is None:
            status = f"qp_{prob.status}"
            break
        pred = merit - float(prob.value)
        trial = phi + d.value
        new_merit, new_vals = _merit(disc, trial, eps, C, nlp.alpha, nlp.beta)
        rho = (merit - new_merit) / pred if pred > 0 else -1.0
        if rho >= RHO_ACCEPT:
            phi, merit, vals = trial, new_merit, new_vals
            if rho > 0.75 and np.max(np.abs(d.value)) > 0.9 * delta:
                delta *= 2
        else:
            delta /= 2
        info = {"iterations": k + 1, "wall_time_s": time.perf_counter() - t0, "merit": merit,
                "energy": vals["E"], "volume_residual": vals["A"] - nlp.alpha,
                "area_residual": vals["B"] - nlp.beta, "step": float(np.max(np.abs(d.value))), "delta": delta}
        if record is not None:
            record(k, phi, info)
        if pred >= 0 and pred <= tol * max(merit, 1.0):
            status = "converged"
            break
        if delta < 1e-12:
            status = "trust_region_collapsed"
            break
    return {"phi": phi, "status": status, "wall_time_s": time.perf_counter() - t0, **vals}
