"""Spatially discrete f, g of Section 4.1 and their Jacobians, built so the energy laws are exact.

Setting: a lumped discretisation (FD grid, or P1 with ``mesh.mass = "lumped"``) with nodal
quadrature. Then Delta_h = L = -diag(m)^{-1} K (Definition 2.2), the L^2 inner product is
<u, v> = sum_i m_i u_i v_i, and with F(phi) = f_c(phi) = eps L phi - p(phi), p(x) = (x^2-1)(x+C eps)/eps
(the paper's (12), (25)):

    E_h(phi) = 1/(2 eps) <F, F>,    A(phi) = <1, phi>,
    B(phi) = eps/2 phi^T K phi + 1/(4 eps) <(phi^2-1)^2, 1>.

Symmetric two-argument functions (Section 4.1, Delta -> L):

    f(phi, eta) = eps/2 L(phi + eta) - 1/(4 eps) (phi^2 + eta^2 - 2)(phi + eta)
    g(phi, eta) = 1/2 L S - 1/(2 eps^2) (phi^2 + phi eta + eta^2 - 1 + C eps (phi + eta)) S,
                  S = F(phi) + F(eta).

Derivation of the exact discrete chain rules (used by every scheme, checked by the tests):
* (phi^2-eta^2)(phi^2+eta^2-2) = (phi^2-1)^2 - (eta^2-1)^2 nodewise, and
  -<phi-eta, L(phi+eta)> = (phi-eta)^T K (phi+eta) = phi^T K phi - eta^T K eta (K symmetric), so
      B(phi) - B(eta) = -<phi - eta, f(phi, eta)>.
* F(phi) - F(eta) = eps L d - Q d with d = phi - eta and Q = (p(phi) - p(eta))/d, the exact
  difference quotient (1/eps)(phi^2 + phi eta + eta^2 + C eps (phi+eta) - 1); and
  <S, L d> = <L S, d> because diag(m) L = -K is symmetric, so
      E_h(phi) - E_h(eta) = 1/(2 eps) <S, F(phi) - F(eta)> = <phi - eta, g(phi, eta)>.
Both hold with no error term, so the schemes' energy laws hold to round-off.

One home per concept: the one-argument quantities (F = f_c, E_h, A, B, E_M, the gradients, and
p' = -g') are the model's (``model.functionals``, ``model.penalty.penalised_energy``; the NLPs
evaluate the same lines symbolically), and the Jacobian model on Fourier grids is built on
``model.lumped.bulk_symbol``. What is defined here is flow-specific: the symmetric two-argument
difference quotients f, g and their Jacobians (as matrices and as products).

Sign convention (differs from the paper as printed): f = eps Delta phi - (phi^2-1)phi/eps is
*minus* the variation of B, so the gradient of the penalised energy is
g + M (A - alpha) - M (B - beta) f; the paper's (14), (18), (23) print "+ M (B - beta) f", with which
the laws (16), (22), (24) fail. We use the sign that makes (22) hold (see issue notes in the README).
The rigidity kappa multiplies E_h: the flows use E = kappa E_h, E_M = E + M/2 (A-alpha)^2 + M/2 (B-beta)^2.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from vesicle_opt.mesh.base import Discretization
from vesicle_opt.model import functionals
from vesicle_opt.model.lumped import bulk_symbol
from vesicle_opt.model.penalty import penalised_energy

FEATURE = "the gradient flows"
WHY = "their exact discrete energy laws need Delta_h = -M_L^-1 K and nodal sums: FD, spectral or P1 lumped"
MODEL_FLOOR = 0.1  # jacobian_model_inverse: the model never drops below 10% of its bending part


@dataclass(frozen=True, eq=False)
class FlowModel:
    """The discrete model of a flow: discretisation, eps, C, rigidity kappa, alpha, beta, M, gamma."""

    disc: Discretization
    epsilon: float
    C: float
    rigidity: float
    alpha: float
    beta: float
    M: float
    gamma: float

    def __post_init__(self):
        self.disc.require_lumped(FEATURE, WHY)

    @property
    def matrix_free(self) -> bool:
        """True on Fourier grids (``spectral``): Delta_h is applied by FFT and never assembled, so
        the schemes' Jacobians are products (``jacobian_apply``) solved by GMRES."""
        return getattr(self.disc, "fourier", None) is not None

    # --- basic operators --------------------------------------------------------------------
    @property
    def m(self) -> np.ndarray:
        return self.disc.weights

    @property
    def L(self) -> sp.csr_matrix:
        return self.disc.laplacian

    @cached_property
    def ops(self) -> functionals.NumpyOps:
        return functionals.NumpyOps(self.disc)

    def inner(self, u: np.ndarray, v: np.ndarray) -> float:
        return float(np.dot(self.m * u, v))

    def norm2(self, u: np.ndarray) -> float:
        """||u||^2 = <u, u> (lumped L^2)."""
        return self.inner(u, u)

    def dp(self, x):
        """p'(x) = -g'(x) (``functionals.reaction_derivative``)."""
        return -functionals.reaction_derivative(x, self.epsilon, self.C)

    def F(self, phi: np.ndarray) -> np.ndarray:
        """f_c(phi) = eps L phi - p(phi), the paper's (12) (``functionals.curvature_residual``)."""
        return functionals.curvature_residual(phi, self.L @ phi, self.epsilon, self.C)

    # --- functionals (the model's: functionals.energy, volume_functional, area_functional) ----
    def E_h(self, phi: np.ndarray) -> float:
        """E_h(phi), (6) with nodal quadrature."""
        return functionals.energy(self.ops, phi, self.L @ phi, self.epsilon, self.C)

    def E(self, phi: np.ndarray) -> float:
        """kappa E_h(phi)."""
        return self.rigidity * self.E_h(phi)

    def A(self, phi: np.ndarray) -> float:
        return functionals.volume_functional(self.ops, phi)

    def B(self, phi: np.ndarray) -> float:
        return functionals.area_functional(self.ops, phi, self.epsilon)

    def residuals(self, phi: np.ndarray) -> tuple[float, float]:
        """(A - alpha, B - beta)."""
        return self.A(phi) - self.alpha, self.B(phi) - self.beta

    def E_M(self, phi: np.ndarray) -> float:
        """kappa E_h + M/2 (A - alpha)^2 + M/2 (B - beta)^2 (``penalty.penalised_energy``)."""
        return penalised_energy(self.rigidity, self.E_h(phi), self.residuals(phi), self.M, self.M)

    # --- symmetric f, g and their Jacobians in the first argument ---------------------------
    def f2(self, phi: np.ndarray, eta: np.ndarray) -> np.ndarray:
        eps = self.epsilon
        s = phi + eta
        return eps / 2 * (self.L @ s) - (phi * phi + eta * eta - 2) * s / (4 * eps)

    def df2(self, phi: np.ndarray, eta: np.ndarray) -> sp.csr_matrix:
        eps = self.epsilon
        diag = (2 * phi * (phi + eta) + phi * phi + eta * eta - 2) / (4 * eps)
        return sp.csr_matrix(eps / 2 * self.L - sp.diags(diag))

    def Q(self, phi, eta):
        """(p(phi) - p(eta)) / (phi - eta), exactly (module docstring); Q(phi, phi) = p'(phi)."""
        ce = self.C * self.epsilon
        return (phi * phi + phi * eta + eta * eta - 1 + ce * (phi + eta)) / self.epsilon

    def g2(self, phi: np.ndarray, eta: np.ndarray, F_eta: np.ndarray | None = None) -> np.ndarray:
        """kappa g(phi, eta): kappa E_h(phi) - kappa E_h(eta) = <phi - eta, kappa g(phi, eta)>."""
        S = self.F(phi) + (self.F(eta) if F_eta is None else F_eta)
        return self.rigidity * (0.5 * (self.L @ S) - self.Q(phi, eta) * S / (2 * self.epsilon))

    def dg2(self, phi: np.ndarray, eta: np.ndarray, F_eta: np.ndarray | None = None) -> sp.csr_matrix:
        eps = self.epsilon
        S = self.F(phi) + (self.F(eta) if F_eta is None else F_eta)
        dS = sp.csr_matrix(eps * self.L - sp.diags(self.dp(phi)))
        Q = self.Q(phi, eta)
        dQ = (2 * phi + eta + self.C * eps) / eps
        J = 0.5 * (self.L @ dS) - (sp.diags(Q / (2 * eps)) @ dS) - sp.diags(S * dQ / (2 * eps))
        return sp.csr_matrix(self.rigidity * J)

    # --- the same Jacobians as products, for matrix-free grids ---------------------------------
    def jacobian_apply(self, phi: np.ndarray, eta: np.ndarray, a: float, b: float,
                       F_eta: np.ndarray | None = None):
        """v -> (I + a dg2(phi, eta) + b df2(phi, eta)) v with two Delta_h applications (the
        Jacobian block of schemes (17) and (18); ``dg2``/``df2`` above are its matrices)."""
        eps = self.epsilon
        S = self.F(phi) + (self.F(eta) if F_eta is None else F_eta)
        dp, Q = self.dp(phi), self.Q(phi, eta)
        S_dQ = S * (2 * phi + eta + self.C * eps) / eps
        d_f = (2 * phi * (phi + eta) + phi * phi + eta * eta - 2) / (4 * eps)
        kap, L = self.rigidity, self.L

        def apply(v):
            Lv = L @ v
            dSv = eps * Lv - dp * v
            dg = kap * (0.5 * (L @ dSv) - Q / (2 * eps) * dSv - S_dQ / (2 * eps) * v)
            return v + a * dg + b * (eps / 2 * Lv - d_f * v)
        return apply

    def jacobian_model_inverse(self, a: float, b: float):
        """r -> P^{-1} r, P the constant-coefficient (bulk phi = eta = +-1, c0 = 0) model of
        I + a dg2 + b df2 on a Fourier grid: with q = ``bulk_symbol`` = -eps sigma + 2/eps (sigma <= 0
        the symbol of Delta_h), dg2 ~ kappa q^2/(2 eps) and df2 ~ -q/2, so
        p = 1 + a kappa q^2/(2 eps) - b q/2 (exact at phi = eta = +-1, c0 = 0), floored at
        1 + MODEL_FLOOR a kappa q^2/(2 eps) (b, a multiplier times k, may have either sign)."""
        fg = self.disc.fourier
        q = bulk_symbol(fg, self.epsilon)
        bend = a * self.rigidity * q * q / (2 * self.epsilon)
        p = np.maximum(1 + bend - b * q / 2, 1 + MODEL_FLOOR * bend)
        inv = fg.multiplier(1.0 / p)
        return lambda r: fg.apply_symbol(r, inv)

    # --- one-argument gradients (lumped-L^2 gradients, i.e. variational derivatives) ---------
    # the model's hand gradients divided by m; g(phi, phi) and f(phi, phi) equal them (tests)
    def g1(self, phi: np.ndarray) -> np.ndarray:
        """kappa grad E_h (lumped L^2) = kappa dE_h / m (``functionals.energy_gradient``)."""
        return self.rigidity * functionals.energy_gradient(self.disc, phi, self.epsilon, self.C) / self.m

    def f1(self, phi: np.ndarray) -> np.ndarray:
        """-grad B (lumped L^2) = -dB / m (``functionals.area_gradient``)."""
        return -functionals.area_gradient(self.disc, phi, self.epsilon) / self.m

    def grad_E_M(self, phi: np.ndarray) -> np.ndarray:
        """The lumped-L^2 gradient g + M (A - alpha) - M (B - beta) f of E_M."""
        res = self.residuals(phi)
        return self.g1(phi) + self.M * res[0] - self.M * res[1] * self.f1(phi)
