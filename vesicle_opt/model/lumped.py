"""Matrix-free E_h (6), A (7), B (8), their gradients and Hessian-vector products (lumped mass).

For a lumped discretisation (weights m, stiffness K, Delta_h = -M_L^{-1} K; FD, spectral, or P1 with
mass lumping and nodal quadrature), with g(phi) = (phi/eps + C)(1 - phi^2), C = sqrt(2) c0:

    r = eps Delta_h phi + g(phi)                        (the paper's f_c, (12))
    E = 1/(2 eps) sum m r^2                             (6)
    A = sum m phi                                        (7)
    B = eps/2 phi^T K phi + 1/(4 eps) sum m (phi^2-1)^2  (8)

Euclidean gradients with respect to the nodal values, J = eps Delta_h + diag(g'(phi)):

    dE = (1/eps) J^T (m r)          dA = m          dB = eps K phi + (1/eps) m (phi^2 - 1) phi
    H_E v = (1/eps) [J^T (m J v) + m r g''(phi) v]   H_B v = eps K v + (1/eps) m (3 phi^2 - 1) v

with g' = (1 - 3 phi^2)/eps - 2 C phi and g'' = -6 phi/eps - 2 C. On Fourier grids Delta_h costs
one FFT pair, so an evaluation costs one pair and a Hessian-vector product two. This is the one
hand-written matrix-free form of the derivatives (the pointwise g, g', g'', W', W'' come from
``functionals``; tests compare it with ``functionals``' numpy gradients, CasADi's AD gradient and
Hessian, and finite differences). The penalised energy (11) and the augmented Lagrangian are
assembled from these pieces with ``penalty.penalised_energy`` in ``nk.newton_cg``.

The bulk model (``bulk_symbol``, ``bulk_stiffness``): in the bulk phi = +-1 with c0 = 0,
g'(+-1) = -2/eps, so -J = -eps Delta_h + 2/eps = M_L^{-1} S, S = eps K + (2/eps) M_L; on a Fourier
grid -J is diagonal with symbol q = eps sigma + 2/eps (sigma = -symbol of Delta_h >= 0). The
Newton-Krylov preconditioner (``nk.precond``) and the flows' Jacobian model
(``flows.discrete.FlowModel.jacobian_model_inverse``) are built on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from vesicle_opt.model import functionals as F

BULK_C = 0.0  # the bulk model linearises at phi = +-1 with c0 = 0 (where g'(+-1) = -2/eps)


def bulk_shift(epsilon: float) -> float:
    """-g'(+-1) = 2/eps at c0 = 0: the zeroth-order term of -J in the bulk (module docstring)."""
    return -F.reaction_derivative(1.0, epsilon, BULK_C)


def bulk_symbol(fourier, epsilon: float) -> np.ndarray:
    """q = eps sigma + 2/eps: the Fourier symbol of -J = -eps Delta_h - g'(+-1) (module docstring)."""
    return epsilon * -fourier.symbol + bulk_shift(epsilon)


def bulk_stiffness(K, m: np.ndarray, epsilon: float) -> sp.csr_matrix:
    """S = eps K + (2/eps) M_L = -M_L J in the bulk (module docstring), sparse."""
    return sp.csr_matrix(epsilon * K + sp.diags(bulk_shift(epsilon) * m))


class LumpedOperators:
    """Delta_h, Delta_h^T and K of a lumped discretisation as callables (FFT or sparse)."""

    def __init__(self, disc):
        disc.require_lumped("the matrix-free model (newton-krylov backend)",
                            "its products use Delta_h = -M_L^-1 K; use the ipopt backend")
        self.disc = disc
        self.m = np.asarray(disc.weights, float)
        self.fourier = getattr(disc, "fourier", None)
        if self.fourier is not None:
            self.lap = self.fourier.laplacian
            self.lapT = self.fourier.laplacian
        else:
            L = disc.laplacian.tocsr()
            LT = L.T.tocsr()
            self.lap = lambda v: L @ v
            self.lapT = lambda v: LT @ v

    def K(self, v: np.ndarray) -> np.ndarray:
        """K v = -M_L Delta_h v."""
        return -self.m * self.lap(v)

    def K_from_lap(self, lap_v: np.ndarray) -> np.ndarray:
        return -self.m * lap_v


@dataclass
class State:
    """Everything the derivatives at phi need, computed with one Laplacian application."""

    phi: np.ndarray
    lap: np.ndarray  # Delta_h phi
    r: np.ndarray  # f_c
    s: np.ndarray  # g'(phi)
    E: float
    A: float
    B: float


class PhaseField:
    """E_h, A, B and derivatives at given eps, C on a :class:`LumpedOperators`."""

    def __init__(self, ops: LumpedOperators, epsilon: float, C: float):
        self.ops, self.eps, self.C = ops, float(epsilon), float(C)
        self.m = ops.m
        # the common value of equal weights (Fourier and FD grids): products by it are the same bits
        # as by the array, read from a register instead of memory; None on meshes
        self.uniform_weight = float(self.m[0]) if self.m.size and np.all(self.m == self.m[0]) else None

    def state(self, phi: np.ndarray) -> State:
        eps, C, m = self.eps, self.C, self.m
        lap = self.ops.lap(phi)
        r = F.curvature_residual(phi, lap, eps, C)
        s = F.reaction_derivative(phi, eps, C)
        E = float(m @ (r * r)) / (2 * eps)
        A = float(m @ phi)
        # phi^T K phi = -m . (phi lap): B from the same Laplacian (functionals.area_functional uses K)
        B = -eps / 2 * float(m @ (phi * lap)) + float(m @ F.double_well(phi)) / eps
        return State(phi, lap, r, s, E, A, B)

    def gradients(self, st: State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        eps, m, phi = self.eps, self.m, st.phi
        mr = m * st.r
        dE = (eps * self.ops.lapT(mr) + st.s * mr) / eps
        dB = m * (-eps * st.lap + F.double_well_derivative(phi) / eps)
        return dE, m.copy(), dB

    def hessian_parts(self, st: State) -> tuple[np.ndarray, np.ndarray]:
        """Diagonal coefficients reused by every product: m r g''/eps and m W''/eps."""
        eps, m, phi = self.eps, self.m, st.phi
        return (m * st.r * F.reaction_second_derivative(phi, eps, self.C) / eps,
                m * F.double_well_second_derivative(phi) / eps)

    def hvp_operator(self, st: State, parts, cE: float, cB: float):
        """v -> (cE H_E + cB H_B) v at one state, its diagonal coefficients formed once.

        With u = m J v = m (eps Delta_h v + g' v) and the identity m (Delta_h v) = Delta_h^T (m v)
        (Delta_h^T = M_L Delta_h M_L^{-1}, K symmetric), the two Laplacian terms are one:

            (cE H_E + cB H_B) v = Delta_h^T (cE u - cB eps m v) + (cE/eps) g' u + (cE m r g''/eps + cB m W''/eps) v,

        two Laplacian applications (one FFT pair each on Fourier grids) and ten elementwise passes
        (the unfused form of ``hvp``'s docstring took eighteen)."""
        eps, s = self.eps, st.s
        m = self.uniform_weight if self.uniform_weight is not None else self.m  # a scalar: one array less to read
        dE_diag, dB_diag = parts
        m_eps = eps * m
        m_s = m * s
        s_over = (cE / eps) * s
        cB_m_eps = cB * m_eps
        diag = cE * dE_diag + cB * dB_diag if cB != 0.0 else cE * dE_diag
        lap, lapT = self.ops.lap, self.ops.lapT

        def apply(v: np.ndarray) -> np.ndarray:
            u = m_eps * lap(v)
            u += m_s * v
            w = cE * u
            if cB != 0.0:
                w -= cB_m_eps * v
            out = lapT(w)
            u *= s_over
            out += u
            out += diag * v
            return out
        return apply

    def hvp(self, st: State, parts, v: np.ndarray, cE: float, cB: float) -> np.ndarray:
        """(cE H_E + cB H_B) v with two Laplacian applications (``hvp_operator``, for one product)."""
        return self.hvp_operator(st, parts, cE, cB)(v)
