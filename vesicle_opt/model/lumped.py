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
one FFT pair, so an evaluation costs one pair and a Hessian-vector product two. These are
independent of ``functionals.py`` (whose hand-derived gradients a test compares with these).
The penalised energy (11) with the paper's convention (rigidity on E only, M on the constraints)
and the augmented Lagrangian are assembled from these pieces in ``newton``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vesicle_opt.errors import InputError


class LumpedOperators:
    """Delta_h, Delta_h^T and K of a lumped discretisation as callables (FFT or sparse)."""

    def __init__(self, disc):
        if getattr(disc, "consistent", False):
            raise InputError("mesh.mass", "the newton-krylov backend needs 'lumped' (consistent mass "
                             "would need M^{-1} inside every product); use lumped or the ipopt backend")
        if getattr(disc, "gauss", False):
            raise InputError("mesh.quadrature", "the newton-krylov backend needs 'nodal' quadrature")
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

    def state(self, phi: np.ndarray) -> State:
        eps, C, m = self.eps, self.C, self.m
        lap = self.ops.lap(phi)
        p2 = phi * phi
        r = eps * lap + (phi / eps + C) * (1 - p2)
        s = (1 - 3 * p2) / eps - 2 * C * phi
        E = float(m @ (r * r)) / (2 * eps)
        A = float(m @ phi)
        B = -eps / 2 * float(m @ (phi * lap)) + float(m @ ((p2 - 1) ** 2)) / (4 * eps)
        return State(phi, lap, r, s, E, A, B)

    def gradients(self, st: State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        eps, m, phi = self.eps, self.m, st.phi
        mr = m * st.r
        dE = (eps * self.ops.lapT(mr) + st.s * mr) / eps
        dB = m * (-eps * st.lap + (phi * phi - 1) * phi / eps)
        return dE, m.copy(), dB

    def hessian_parts(self, st: State) -> tuple[np.ndarray, np.ndarray]:
        """Diagonal coefficients reused by every product: m r g''/eps and m (3 phi^2 - 1)/eps."""
        eps, m, phi = self.eps, self.m, st.phi
        return m * st.r * (-6 * phi / eps - 2 * self.C) / eps, m * (3 * phi * phi - 1) / eps

    def hvp(self, st: State, parts, v: np.ndarray, cE: float, cB: float) -> np.ndarray:
        """(cE H_E + cB H_B) v with two Laplacian applications."""
        eps, m = self.eps, self.m
        dE_diag, dB_diag = parts
        lv = self.ops.lap(v)
        Jv = eps * lv + st.s * v
        u = m * Jv
        out = cE * ((eps * self.ops.lapT(u) + st.s * u) / eps + dE_diag * v)
        if cB != 0.0:
            out += cB * (eps * self.ops.K_from_lap(lv) + dB_diag * v)
        return out
