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
hand-written matrix-free form of the derivatives (the pointwise g, g', g'', W', W'' of
``functionals``, formed here in place, with as few passes over the field as the formulas allow:
the 64^3 fields do not stay in cache; tests compare it with ``functionals``' numpy gradients,
CasADi's AD gradient and Hessian, and finite differences). The penalised energy (11) and the augmented Lagrangian are
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

from vesicle_opt.blas import axpy
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


def pointwise(phi: np.ndarray, lap: np.ndarray, epsilon: float, C: float):
    """(r, g'(phi), 1 - phi^2): f_c = eps lap + g(phi) and g' of ``functionals`` (``curvature_residual``,
    ``reaction_derivative``), formed in place from one phi^2 (six passes over the field instead of
    sixteen; a test compares them with ``functionals`` to round-off); 1 - phi^2 gives the double well
    W = (1 - phi^2)^2 / 4."""
    one_minus_sq = np.multiply(phi, phi)
    s = np.multiply(one_minus_sq, -3.0 / epsilon)  # g' = (1 - 3 phi^2)/eps - 2 C phi
    s += 1.0 / epsilon
    np.subtract(1.0, one_minus_sq, out=one_minus_sq)
    r = np.multiply(phi, 1.0 / epsilon)  # g = (phi/eps + C)(1 - phi^2)
    if C:
        r += C
        axpy(-2.0 * C, phi, s)
    r *= one_minus_sq
    axpy(epsilon, lap, r)
    return r, s, one_minus_sq


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
        # the weights as the products use them: that scalar where there is one, else the array
        self.weight = self.uniform_weight if self.uniform_weight is not None else self.m

    def state(self, phi: np.ndarray) -> State:
        eps, m = self.eps, self.m
        lap = self.ops.lap(phi)
        r, s, one_minus_sq = pointwise(phi, lap, eps, self.C)
        w = self.uniform_weight
        # phi^T K phi = -m . (phi lap): B from the same Laplacian (functionals.area_functional uses K);
        # the double well W = (1 - phi^2)^2 / 4
        if w is None:
            E = float(m @ (r * r)) / (2 * eps)
            A = float(m @ phi)
            B = -eps / 2 * float(m @ (phi * lap)) + float(m @ (one_minus_sq * one_minus_sq)) / (4 * eps)
        else:  # one weight: the sums are dot products, no product array formed
            E = w * float(r @ r) / (2 * eps)
            A = w * float(phi.sum())
            B = -eps / 2 * w * float(phi @ lap) + w * float(one_minus_sq @ one_minus_sq) / (4 * eps)
        return State(phi, lap, r, s, E, A, B)

    def gradients(self, st: State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        eps, m, phi = self.eps, self.m, st.phi
        w = self.weight
        mr = w * st.r
        dE = self.ops.lapT(mr)  # (eps Delta_h^T (m r) + g' m r) / eps
        mr *= st.s
        axpy(1.0 / eps, mr, dE)
        dB = np.multiply(phi, phi)  # dB = m (W'(phi)/eps - eps Delta_h phi), W' = (phi^2 - 1) phi
        dB -= 1.0
        dB *= phi
        dB *= w / eps
        if self.uniform_weight is not None:
            axpy(-eps * w, st.lap, dB)
        else:
            dB -= (eps * m) * st.lap
        return dE, m.copy(), dB

    def gradient_parts(self, st: State) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The four terms ``gradients`` sums into dE and dB: (Delta_h^T (m r), m r g'/eps, eps K phi
        = -eps m Delta_h phi, m W'(phi)/eps), as ``functionals.energy_gradient_parts`` and
        ``area_gradient_parts`` split them (their norms are the stopping test's denominator,
        ``verify.kkt.terms_scale``)."""
        eps, w, phi = self.eps, self.weight, st.phi
        mr = w * st.r
        bend = self.ops.lapT(mr)
        mr *= st.s
        mr *= 1.0 / eps
        well = np.multiply(phi, phi)
        well -= 1.0
        well *= phi
        well *= w / eps
        return bend, mr, (-eps * w) * st.lap, well

    def hessian_parts(self, st: State) -> tuple[np.ndarray, np.ndarray]:
        """Diagonal coefficients reused by every product: m r g''/eps and m W''/eps
        (g'' = -6 phi/eps - 2C, W'' = 3 phi^2 - 1)."""
        eps, phi = self.eps, st.phi
        w = self.weight
        dE_diag = np.multiply(phi, -6.0 / eps)
        if self.C:
            dE_diag -= 2 * self.C
        dE_diag *= st.r
        dE_diag *= w / eps
        dB_diag = np.multiply(phi, phi)
        dB_diag *= 3.0
        dB_diag -= 1.0
        dB_diag *= w / eps
        return dE_diag, dB_diag

    def hvp_operator(self, st: State, parts, cE: float, cB: float, rho_A: float = 0.0, fused: bool = True):
        """v -> (cE H_E + cB H_B + rho_A dA dA^T) v at one state, its diagonal coefficients formed
        once (dA = m: the penalty's rank-one term of the volume, ``nk.newton_cg``).

        With u = m J v = m (eps Delta_h v + g' v) and the identity m (Delta_h v) = Delta_h^T (m v)
        (Delta_h^T = M_L Delta_h M_L^{-1}, K symmetric), the two Laplacian terms are one:

            (cE H_E + cB H_B) v = Delta_h^T (cE u - cB eps m v) + (cE/eps) g' u + (cE m r g''/eps + cB m W''/eps) v,

        two Laplacian applications (one FFT pair each on Fourier grids) and ten elementwise passes
        (the unfused form of ``hvp``'s docstring took eighteen). On grids with one weight m
        (Fourier and mirror grids; ``fused``) the scalars go into the two spectral multiplies,
        L = Delta_{m eps sigma} v and cE Delta_h u, and Delta_h (cB eps m v) = cB L, so with
        u = L + m g' v

            (cE H_E + cB H_B) v = cE Delta_h u + ((cE/eps) g' - cB) L + ((cE/eps) m g'^2 + diag) v,

        six elementwise passes (``_grid_apply``; equal to the general form to round-off, a test);
        there rho_A (m . v) m = rho_A m^2 sum(v) is a constant, added through the second product's
        k = 0 coefficient."""
        eps, s = self.eps, st.s
        m = self.weight  # a scalar on grids: one array less to read
        dE_diag, dB_diag = parts
        m_eps = eps * m
        fourier = self.ops.fourier
        if fused and self.uniform_weight is not None and fourier is not None:
            lap = fourier.laplacian_multiplier  # the symbol of Delta_h as apply_symbol multiplies it
            return self._grid_apply(fourier, m_eps * lap, cE * lap, *self._grid_coefficients(st, parts, cE, cB, rho_A))
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
            if rho_A:
                out += (rho_A * float(self.m @ v)) * self.m
            return out
        return apply

    def _grid_coefficients(self, st: State, parts, cE: float, cB: float, rho_A: float):
        """(m_s, coef_L, coef_v, rank_one) of the fused grid product (``hvp_operator``): m g',
        (cE/eps) g' - cB, (cE/eps) m g'^2 + cE dE_diag + cB dB_diag, rho_A m^2 (one weight m)."""
        m, dE_diag, dB_diag = self.uniform_weight, *parts
        m_s = m * st.s
        coef_L = (cE / self.eps) * st.s
        coef_v = coef_L * m_s
        axpy(cE, dE_diag, coef_v)
        if cB != 0.0:
            axpy(cB, dB_diag, coef_v)
        coef_L -= cB
        return m_s, coef_L, coef_v, rho_A * m * m

    def hvp_coordinates(self, st: State, parts, cE: float, cB: float, rho_A: float = 0.0):
        """The fused grid product of ``hvp_operator`` in the orthonormal coordinates y = T v of a
        Fourier grid (``mesh.coordinates``): y -> T (cE H_E + cB H_B + rho_A dA dA^T) T^{-1} y. With
        v = T^{-1} y, L = T^{-1}(m eps sigma y) (the symbol applied on the way back) and
        u = m g' v + L, t = coef_L L + coef_v v,

            T H v = (cE sigma sqrt(W)) u^ + sqrt(W) t^ + N rho_A m^2 y_0 e_0,

        four transforms (the nodal product takes four and its preconditioner two more, which here
        is a diagonal) and ten elementwise passes, into three work fields reused by every product
        (fresh 2 MB arrays cost a cold pass each at 64^3); the rank-one volume term is y_0's alone
        (y_0 = sum(v) / sqrt(N), T of a constant c is sqrt(N) c e_0)."""
        fourier = self.ops.fourier
        coords = fourier.coordinates
        m_s, coef_L, coef_v, rank_one = self._grid_coefficients(st, parts, cE, cB, rho_A)
        lap = fourier.laplacian_multiplier  # the grid's own: no symbol array is formed here
        # the scalars of the two symbols go into the coefficients: with L1 = T^{-1}(sigma y) (the
        # symbol alone, ``unscale`` left out) L = a L1, a = eps m / sqrt(W); u is formed times
        # b = cE sqrt(W), so that T(cE Delta_h u) = sigma (b u)^ (``forward`` with sigma alone)
        a, b = self.eps * self.uniform_weight * coords.unscale, cE * coords.scale
        m_s *= b
        coef_L *= a
        dc = rank_one * fourier.size
        work = []  # v, L1 (where the FFT library writes into them), u: reused by every product

        def apply(y: np.ndarray) -> np.ndarray:
            if not work:
                work.extend([fourier.empty_field(), fourier.empty_field(), np.empty(fourier.size)])
            v = coords.backward(y, out=work[0])
            L1 = coords.backward(y, lap, out=work[1])
            u = np.multiply(m_s, v, out=work[2])  # b m g' v
            axpy(a * b, L1, u)  # b u
            L1 *= coef_L
            v *= coef_v
            L1 += v  # t
            del v  # (scipy: its own array, not needed beside the transforms' outputs)
            out = coords.forward(u, lap)
            coords.forward_add(L1, out)
            if dc:
                out[0] += dc * y[0]
            return out
        return apply

    @staticmethod
    def _grid_apply(fourier, sym_L, sym_u, m_s, coef_L, coef_v, rank_one):
        """The fused product of ``hvp_operator`` on a one-weight grid: sym_L = m eps sigma,
        sym_u = cE sigma, coef_L = (cE/eps) g' - cB, coef_v = (cE/eps) m g'^2 + diag,
        rank_one = rho_A m^2 (the symbols as ``fourier.multiplier`` made them)."""
        def apply(v: np.ndarray) -> np.ndarray:
            L, total = fourier.apply_symbol(v, sym_L, with_sum=True)  # m eps Delta_h v, and sum(v)
            u = np.multiply(m_s, v)
            u += L  # u = m J v
            out = fourier.apply_symbol(u, sym_u, rank_one * total)  # cE Delta_h u + rho_A m^2 sum(v)
            L *= coef_L
            out += L
            np.multiply(coef_v, v, out=u)
            out += u
            return out
        return apply

    def hvp(self, st: State, parts, v: np.ndarray, cE: float, cB: float) -> np.ndarray:
        """(cE H_E + cB H_B) v with two Laplacian applications (``hvp_operator``, for one product)."""
        return self.hvp_operator(st, parts, cE, cB)(v)
