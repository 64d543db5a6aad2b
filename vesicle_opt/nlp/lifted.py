"""The penalty formulation (11) of Section 3.2-3.3 as a lifted CasADi NLP with M as a parameter.

Penalised (and, with multiplier shifts mu, augmented-Lagrangian) functional, the paper's
Section 5 convention (the rigidity multiplies the bending energy only):

    E_{M,h}(phi) = rigidity E_h(phi) + M1/2 (A - alpha)^2 + M2/2 (B - beta)^2
                   - mu_A (A - alpha) - mu_B (B - beta)                   (mu = 0: exactly (11))

Written naively the squares add a dense rank-one block m m^T to the Hessian. Lifting keeps it sparse:
two scalar unknowns u = (u_A, u_B), u_A = (a - alpha)/|Omega|, u_B = (b - beta)/beta, with the
equality rows of the exact NLP shifted by them,

    g_A = (A(phi) - alpha)/|Omega| - u_A = 0,   g_B = (B(phi) - beta)/beta - u_B = 0,

so the penalty (``model.penalty.penalty_terms`` in these units, the lines that evaluate E_M
everywhere else) is a diagonal 2 x 2 block in u and the Hessian keeps the bi-Laplacian stencil
(``hessian_nnz_per_row`` grows by 2/N). The scaling is the exact NLP's (``nlp.exact``): the same
f_scale and g_scale, and x = (phi [, w], u). Parameters p = (M1, M2, mu_A, mu_B), so one solver
serves every M of a continuation. At a stationary point IPOPT's lam_g of the two lifted rows give,
through ``NLP.multipliers``, exactly the multiplier estimates in the exact solve's convention
rigidity grad E_h = lambda_A grad A + lambda_B grad B:

    lambda_A = mu_A - M1 (A - alpha),   lambda_B = mu_B - M2 (B - beta)

(Theorem 3.2: as M -> inf, phi_M -> phi* and these -> the exact multipliers, with O(1/M) error).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from vesicle_opt.model.penalty import penalty_terms, residuals
from vesicle_opt.nlp.exact import NLP


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

    def from_phi(self, phi: np.ndarray) -> np.ndarray:
        """The lifted NLP vector of a field phi (w and u consistent with it)."""
        return self.lift(self.exact.from_phi(phi))

    def lift_gap(self, x: np.ndarray) -> float:
        """max_i |u_i - (A - alpha, B - beta)_i / g_scale_i|: the lifted unknowns against phi's own."""
        phi, _ = self.split(x)
        A, B = residuals(self.disc, phi, self.scene.model.epsilon, self.alpha, self.beta)
        u = self.lifted(x)
        return float(max(abs(u[0] - A / self.g_scale[0]), abs(u[1] - B / self.g_scale[1])))

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


def build_penalty_nlp(exact: NLP) -> PenaltyNLP:
    """Lift the exact NLP ``exact`` into the penalty NLP (see the module docstring)."""
    import casadi as ca  # third-party, lazy: only IPOPT paths need it (0.25 s at import)
    u = ca.MX.sym("u", 2)
    p = ca.MX.sym("p", 4)  # (M1, M2, mu_A, mu_B)
    s0, s1 = (float(v) for v in exact.g_scale)
    k = exact.f_scale
    pen = penalty_terms((u[0], u[1]), p[0], p[1], (p[2], p[3]), scale=(s0, s1)) / k  # the one E_M
    g = ca.vertcat(exact.g[0] - u[0], exact.g[1] - u[1], exact.g[2:])
    x0 = np.concatenate([exact.x0, np.zeros(2)])
    inf = np.full(2, np.inf)
    nlp = PenaltyNLP(scene=exact.scene, disc=exact.disc, alpha=exact.alpha, beta=exact.beta,
                     x=ca.vertcat(exact.x, u), f=exact.f + pen, g=g, p=p, x0=x0,
                     lbx=np.concatenate([exact.lbx, -inf]), ubx=np.concatenate([exact.ubx, inf]),
                     lbg=exact.lbg, ubg=exact.ubg, f_scale=k, g_scale=exact.g_scale, exact=exact)
    return dataclasses.replace(nlp, x0=nlp.lift(exact.x0))
