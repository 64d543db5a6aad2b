"""The penalty formulation (11) of Section 3.2-3.3 as a lifted CasADi NLP with M as a parameter.

Penalised (and, with multiplier shifts mu, augmented-Lagrangian) functional, the paper's
Section 5 convention (the rigidity multiplies the bending energy only):

    E_{M,h}(phi) = rigidity E_h(phi) + M1/2 (A - alpha)^2 + M2/2 (B - beta)^2
                   - mu_A (A - alpha) - mu_B (B - beta)                   (mu = 0: exactly (11))

Written naively the squares add a dense rank-one block m m^T to the Hessian. Lifting keeps it sparse:
two scalar unknowns u = (u_A, u_B), u_A = (a - alpha)/|Omega|, u_B = (b - beta)/beta, with the
equality rows of the exact NLP shifted by them,

    g_A = (A(phi) - alpha)/|Omega| - u_A = 0,   g_B = (B(phi) - beta)/beta - u_B = 0,

so the penalty is a diagonal 2 x 2 block in u and the Hessian keeps the bi-Laplacian stencil
(``hessian_nnz_per_row`` grows by 2/N). The scaling is the exact NLP's (``nlp.py``): the same
f_scale and g_scale, and x = (phi [, w], u). Parameters p = (M1, M2, mu_A, mu_B), so one solver
serves every M of a continuation. At a stationary point IPOPT's lam_g of the two lifted rows give,
through ``NLP.multipliers``, exactly the multiplier estimates in the exact solve's convention
rigidity grad E_h = lambda_A grad A + lambda_B grad B:

    lambda_A = mu_A - M1 (A - alpha),   lambda_B = mu_B - M2 (B - beta)

(Theorem 3.2: as M -> inf, phi_M -> phi* and these -> the exact multipliers, with O(1/M) error).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from . import functionals as F
from .kkt import kkt_residual
from .nlp import NLP
from .result import Result


@dataclass(frozen=True, eq=False)
class PenaltyNLP(NLP):
    """The lifted penalty NLP; ``exact`` is the exact-constraint NLP it was built from."""

    exact: NLP | None = None

    @property
    def n_base(self) -> int:
        return self.exact.x.shape[0]

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        return self.exact.split(np.asarray(x, float).ravel()[: self.n_base])

    def lifted(self, x: np.ndarray) -> np.ndarray:
        """The scaled residual unknowns u = (u_A, u_B) of a full NLP vector."""
        return np.asarray(x, float).ravel()[self.n_base:]

    def lift(self, x_base: np.ndarray) -> np.ndarray:
        """Append the u consistent with phi, so every lifted row holds exactly at the start."""
        x_base = np.asarray(x_base, float).ravel()
        phi, _ = self.exact.split(x_base)
        A, B = residuals(self.disc, phi, self.scene.model.epsilon, self.alpha, self.beta)
        return np.concatenate([x_base, [A / self.g_scale[0], B / self.g_scale[1]]])

    @staticmethod
    def parameters(M1: float, M2: float | None = None, mu: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """p = (M1, M2, mu_A, mu_B); M2 defaults to M1 (the paper's M1 = M2 = M)."""
        return np.array([M1, M1 if M2 is None else M2, mu[0], mu[1]], float)

    def initial_lam_g(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """lam_g making the u-rows of the Lagrangian stationary at x (zero for the w rows)."""
        u = self.lifted(x)
        lam = np.zeros(self.lbg.size)
        for i in range(2):
            lam[i] = self.g_scale[i] * (p[i] * self.g_scale[i] * u[i] - p[2 + i]) / self.f_scale
        return lam


def residuals(disc, phi: np.ndarray, epsilon: float, alpha: float, beta: float) -> tuple[float, float]:
    """(A - alpha, B - beta) evaluated with compensated sums (math.fsum).

    At M = 1e8 the residuals are ~1e-8 while A, B are O(10-100): a plain sum loses ~1e-14 to
    cancellation, i.e. 1e-6 in M (A - alpha). fsum of the nodal terms brings this to ~1e-16.
    """
    q = disc.at_quad(phi)
    w = disc.quad_w if disc.gauss else disc.weights
    A = math.fsum(np.concatenate([disc.weights * phi, [-alpha]]))
    grad = epsilon / 2 * phi * (disc.K @ phi)
    well = w * (q * q - 1) ** 2 / (4 * epsilon)
    B = math.fsum(np.concatenate([grad, well, [-beta]]))
    return A, B


def roundoff_floor(disc, phi, epsilon: float, C: float, rigidity: float, lam: tuple[float, float],
                   M: tuple[float, float]) -> float:
    """Least relative stationarity residual (kkt.py) that double precision permits at penalty M.

    The estimates lambda = mu - M (A - alpha) inherit the evaluation error of A and B inside the
    NLP (CasADi sums N nodal terms in order: error ~ sqrt(N) u_mach sum|terms|), multiplied by M:
    the floor is sqrt(N) M u (S_A |dA|_* + S_B |dB|_*) / (|rig dE|_* + |lambda_A dA|_* + |lambda_B dB|_*),
    S_A = sum |m_i phi_i|, S_B = B. (Measured on ellipse-2d 32^2 - 128^2, M = 1e4 ... 1e10: the
    residuals sit at 0.05 - 2x of it.) It is why the penalty cannot be pushed to M -> inf: a stage
    whose floor reaches tol cannot be certified and is reported as not converged, with this reason.
    """
    from .kkt import dual_norm
    dE, dA, dB = F.gradients(disc, phi, epsilon, C)
    u = np.finfo(float).eps
    S_A = float(np.sum(np.abs(disc.weights * phi)))
    S_B = float(F.area_functional(F.NumpyOps(disc), phi, epsilon))
    scale = (dual_norm(disc, rigidity * dE) + abs(lam[0]) * dual_norm(disc, dA)
             + abs(lam[1]) * dual_norm(disc, dB))
    num = np.sqrt(phi.size) * u * (M[0] * S_A * dual_norm(disc, dA) + M[1] * S_B * dual_norm(disc, dB))
    return float(num / max(scale, np.finfo(float).tiny))


def build_penalty_nlp(exact: NLP) -> PenaltyNLP:
    """Lift the exact NLP ``exact`` into the penalty NLP (see the module docstring)."""
    u = ca.MX.sym("u", 2)
    p = ca.MX.sym("p", 4)  # (M1, M2, mu_A, mu_B)
    s0, s1 = (float(v) for v in exact.g_scale)
    k = exact.f_scale
    pen = (p[0] * s0**2 / 2 * u[0] ** 2 + p[1] * s1**2 / 2 * u[1] ** 2
           - p[2] * s0 * u[0] - p[3] * s1 * u[1]) / k
    g = ca.vertcat(exact.g[0] - u[0], exact.g[1] - u[1], exact.g[2:])
    x0 = np.concatenate([exact.x0, np.zeros(2)])
    inf = np.full(2, np.inf)
    nlp = PenaltyNLP(scene=exact.scene, disc=exact.disc, alpha=exact.alpha, beta=exact.beta,
                     x=ca.vertcat(exact.x, u), f=exact.f + pen, g=g, p=p, x0=x0,
                     lbx=np.concatenate([exact.lbx, -inf]), ubx=np.concatenate([exact.ubx, inf]),
                     lbg=exact.lbg, ubg=exact.ubg, f_scale=k, g_scale=exact.g_scale, exact=exact)
    return dataclasses.replace(nlp, x0=nlp.lift(exact.x0))


def penalised_energy(rigidity: float, E: float, res: tuple[float, float], M1: float, M2: float) -> float:
    """E_{M,h} of (11) (rigidity times E_h plus the penalty terms; no multiplier shift)."""
    return rigidity * E + M1 / 2 * res[0] ** 2 + M2 / 2 * res[1] ** 2


def solve_stage(nlp: PenaltyNLP, solver, p: np.ndarray, *, x0=None, lam_x0=None, lam_g0=None,
                tol: float, method: str = "penalty") -> Result:
    """One IPOPT solve of the penalised functional at p = (M1, M2, mu_A, mu_B).

    ``converged`` = IPOPT success, the independently recomputed (numpy) stationarity residual of
    E_{M,h} (kkt.py with lambda = mu - M (A - alpha), mu - M (B - beta)) at most KKT_FACTOR * tol,
    the same test as the exact solve's, and the lifted unknowns consistent with phi (they enter
    only through the NLP). When it fails with the round-off floor of ``roundoff_floor`` at or above
    tol, extra["reason"] says so: such an M cannot be certified at this tol (it is never accepted
    on the solver's say-so). The lifted rows need a constraint tolerance far below tol
    (continuation.PENALTY_OPTIONS): a gap |B - b| shifts the estimate by M |B - b|, which this test
    then (rightly) reports.
    """
    from .solve import KKT_FACTOR, _hessian_nnz_per_row, _times, failure_reason, run_ipopt
    scene, disc = nlp.scene, nlp.disc
    x0 = nlp.x0 if x0 is None else np.asarray(x0, float)
    sol, stats, wall, x = run_ipopt(solver, nlp, x0, p=p, lam_x0=lam_x0,
                                    lam_g0=nlp.initial_lam_g(x0, p) if lam_g0 is None else lam_g0)
    phi, w = nlp.split(x)
    eps, C, rig = scene.model.epsilon, scene.model.C, scene.model.rigidity
    finite = bool(np.all(np.isfinite(x)))
    vals = F.evaluate(disc, phi, eps, C) if finite else {"E": np.nan}
    res = residuals(disc, phi, eps, nlp.alpha, nlp.beta) if finite else (np.nan, np.nan)
    M1, M2, muA, muB = (float(v) for v in p)
    lam_A, lam_B = muA - M1 * res[0], muB - M2 * res[1]
    kkt = kkt_residual(disc, phi, eps, C, rig, lam_A, lam_B) if finite else np.nan
    floor = roundoff_floor(disc, phi, eps, C, rig, (lam_A, lam_B), (M1, M2)) if finite else np.inf
    u = nlp.lifted(x)
    lift_gap = max(abs(u[0] - res[0] / nlp.g_scale[0]), abs(u[1] - res[1] / nlp.g_scale[1])) if finite else np.inf
    success = bool(stats["success"]) and finite
    converged = success and kkt <= KKT_FACTOR * tol and lift_gap <= tol
    reason = failure_reason(stats["return_status"], success, kkt, tol, True, floor)
    if reason is None and not lift_gap <= tol:
        reason = f"lifted unknowns off A, B by {lift_gap:.1e} (> tol)"
    _, deriv, _ = _times(stats)
    it = stats.get("iterations", {})
    history = {k: list(it.get(k, [])) for k in ("obj", "inf_pr", "inf_du", "mu", "alpha_pr")}
    ipopt_lam = nlp.multipliers(np.asarray(sol["lam_g"]))
    return Result(
        phi=phi, w=w, energy=rig * vals["E"], volume_residual=res[0], area_residual=res[1],
        lambda_volume=lam_A, lambda_area=lam_B, kkt_residual=kkt, status=stats["return_status"],
        success=success, converged=converged, iterations=int(stats.get("iter_count", 0)),
        wall_time_s=wall, derivative_time_s=deriv, other_time_s=wall - deriv, n_nodes=disc.n_nodes,
        hessian_nnz_per_row=_hessian_nnz_per_row(solver, x.size), method=method, M=M1,
        penalized_energy=penalised_energy(rig, vals["E"], res, M1, M2), history=history, x=x,
        lam_x=np.asarray(sol["lam_x"]).ravel(), lam_g=np.asarray(sol["lam_g"]).ravel(),
        extra={"alpha": nlp.alpha, "beta": nlp.beta, "epsilon": eps, "h": disc.h, "M2": M2,
               "mu_volume": muA, "mu_area": muB, "lift_gap": lift_gap, "kkt_floor": floor,
               "ipopt_lambda_volume": ipopt_lam[0], "ipopt_lambda_area": ipopt_lam[1],
               **({"reason": reason} if not converged else {})})
