"""The discrete energy (6) and constraints (7), (8): one definition each, for numpy and CasADi.

With f_c(phi) = eps Delta_h phi + (phi/eps + C)(1 - phi^2), C = sqrt(2) c0 (the paper's (12)):

* (6)  E_h(phi)  = 1/(2 eps) * integral f_c^2           (``energy``; the physical energy is rigidity * E_h)
* (7)  A(phi)    = integral phi = sum_i m_i phi_i        (``volume_functional``; exact for P1)
* (8)  B(phi)    = eps/2 phi^T K phi + 1/(4 eps) integral (phi^2 - 1)^2   (``area_functional``)

"integral" is the discretisation's quadrature of nodal nonlinear terms (nodal or Gauss). Each
function takes an ``ops`` object: :class:`NumpyOps` evaluates, :class:`CasadiOps` builds MX
expressions with sparse constant matrices, so the NLP and the numpy checks share these lines.
Helpers: volume = (|Omega| + A)/2 and area = 3 sqrt(2) B / 4 (Section 3.1).

The pointwise nonlinearities and their derivatives are defined here once, for every form (numpy,
CasADi, the matrix-free ``lumped`` model, the flows' Jacobians, the SCP baseline):

* the double well W(phi) = (phi^2 - 1)^2 / 4 of (8), W' = (phi^2 - 1) phi, W'' = 3 phi^2 - 1;
* the reaction term g(phi) = (phi/eps + C)(1 - phi^2) of f_c = eps Delta_h phi + g(phi),
  g' = (1 - 3 phi^2)/eps - 2 C phi, g'' = -6 phi/eps - 2 C (the flows write p = -g, p' = -g').
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.geometry import enclosed_volume, sphere_energy, surface_area  # noqa: F401 (Section 3.1, re-exported)
from vesicle_opt.mesh.base import Discretization


class NumpyOps:
    def __init__(self, disc: Discretization):
        self.disc = disc
        self.K = disc.K
        self.weights = disc.weights

    def at_quad(self, v):
        return self.disc.at_quad(v)

    def integrate(self, values):
        return self.disc.integrate(values)

    @staticmethod
    def dot(a, b):
        return float(a @ b)

    def matvec(self, A, v):
        return A @ v


def sparsity_of(A):
    """The CasADi Sparsity of a scipy CSC matrix with sorted indices (CasADi's CCS: rows ascending in a
    column), from its arrays."""
    import casadi as ca  # third-party, lazy: only the IPOPT path builds graphs (0.25 s at import)
    return ca.Sparsity(A.shape[0], A.shape[1], A.indptr.astype(np.int64).tolist(), A.indices.astype(np.int64).tolist())


def sparse_dm(A):
    """A scipy sparse matrix as a CasADi DM, built from its CSC arrays: ``ca.DM(csc)`` itself took 0.81 s
    against 0.13 s for a 40 k x 40 k matrix of 8 entries a row (measured; 0.17 s a call, 3.5 of a far
    phase-diagram case's 43.5 CPU s, in the NLP builds)."""
    import casadi as ca  # third-party, lazy: only the IPOPT path builds graphs (0.25 s at import)
    A = A.tocsc()
    A = A if A.has_sorted_indices else A.sorted_indices()
    return ca.DM(sparsity_of(A), np.asarray(A.data, float))


class CasadiOps:
    """Sparse constant matrices as CasADi DM inside MX graphs."""

    def __init__(self, disc: Discretization):
        import casadi as ca  # third-party, lazy: only the IPOPT path builds graphs (0.25 s at import)
        self.disc = disc
        self.K = sparse_dm(disc.K)
        self.weights = ca.DM(disc.weights)
        self.P = sparse_dm(disc.quad_P) if disc.gauss else None
        self.quad_w = ca.DM(disc.quad_w if disc.gauss else disc.weights)

    def at_quad(self, v):
        import casadi as ca
        return ca.mtimes(self.P, v) if self.P is not None else v

    def integrate(self, values):
        import casadi as ca
        return ca.dot(self.quad_w, values)

    @staticmethod
    def dot(a, b):
        import casadi as ca
        return ca.dot(a, b)

    @staticmethod
    def matvec(A, v):
        import casadi as ca
        return ca.mtimes(A, v)


def double_well(phi):
    """W(phi) = (phi^2 - 1)^2 / 4: B's bulk term is 1/eps integral W(phi)."""
    return (phi * phi - 1) ** 2 / 4


def double_well_derivative(phi):
    """W'(phi) = (phi^2 - 1) phi."""
    return (phi * phi - 1) * phi


def double_well_second_derivative(phi):
    """W''(phi) = 3 phi^2 - 1."""
    return 3 * phi * phi - 1


def reaction(phi, epsilon: float, C: float):
    """g(phi) = (phi/eps + C)(1 - phi^2), the nonlinear part of f_c."""
    return (phi / epsilon + C) * (1 - phi * phi)


def reaction_derivative(phi, epsilon: float, C: float):
    """g'(phi) = (1 - 3 phi^2)/eps - 2 C phi: J = eps Delta_h + diag(g'(phi)) is the Jacobian of f_c."""
    return (1 - 3 * (phi * phi)) / epsilon - 2 * C * phi


def reaction_second_derivative(phi, epsilon: float, C: float):
    """g''(phi) = -6 phi/eps - 2 C."""
    return -6 * phi / epsilon - 2 * C


def curvature_residual(phi, lap, epsilon: float, C: float):
    """f_c(phi) = eps Delta phi + (phi/eps + C)(1 - phi^2), the integrand of (3)/(6) (paper's (12))."""
    return epsilon * lap + reaction(phi, epsilon, C)


def energy(ops, phi, lap, epsilon: float, C: float):
    """E_h of (6), given lap = Delta_h phi (lumped: L phi; consistent: the unknown w)."""
    r = curvature_residual(ops.at_quad(phi), ops.at_quad(lap), epsilon, C)
    return ops.integrate(r * r) / (2 * epsilon)


def volume_functional(ops, phi):
    """A of (7): integral of phi, exact for P1 (row sums of M are the lumped weights)."""
    return ops.dot(ops.weights, phi)


def area_functional(ops, phi, epsilon: float):
    """B of (8): eps/2 |grad phi|^2 (exact, via K) + 1/(4 eps) integral (phi^2 - 1)^2."""
    q = ops.at_quad(phi)
    return epsilon / 2 * ops.dot(phi, ops.matvec(ops.K, phi)) + ops.integrate(double_well(q)) / epsilon


# --- numpy evaluation with the scene's model ----------------------------------------------------


def evaluate(disc: Discretization, phi: np.ndarray, epsilon: float, C: float) -> dict[str, float]:
    """E_h, A, B of a nodal field (Delta_h by Definition 2.2 with the discretisation's mass)."""
    ops = NumpyOps(disc)
    lap = disc.apply_laplacian(phi)
    return {"E": energy(ops, phi, lap, epsilon, C), "A": volume_functional(ops, phi),
            "B": area_functional(ops, phi, epsilon)}


def gradients(disc: Discretization, phi: np.ndarray, epsilon: float, C: float):
    """Euclidean gradients (dE_h, dA, dB) with respect to the nodal values, derived by hand.

    dE = 1/eps [ eps Delta_h^T P^T W r + P^T W (r g'(phi)) ],  r = f_c;
    dA = m;  dB = eps K phi + 1/eps P^T W W'(phi).
    """
    return energy_gradient(disc, phi, epsilon, C), volume_gradient(disc), area_gradient(disc, phi, epsilon)


def energy_gradient(disc: Discretization, phi: np.ndarray, epsilon: float, C: float) -> np.ndarray:
    """dE_h (see ``gradients``): the sum of its two ``energy_gradient_parts``."""
    bending, reaction_part = energy_gradient_parts(disc, phi, epsilon, C)
    return bending + reaction_part


def energy_gradient_parts(disc: Discretization, phi: np.ndarray, epsilon: float, C: float):
    """The two terms summed into dE_h: Delta_h^T P^T W f_c (through the Laplacian) and
    P^T W (f_c g'(phi)) / eps (through the reaction). Across the interface of an equilibrium they
    nearly cancel (f_c ~ kappa phi' and J phi' ~ 0 for J = eps Delta_h + g'), so each is far larger
    than their sum: the certificate's scale counts them apart (``verify.kkt.dual_scale``)."""
    lap = disc.apply_laplacian(phi)
    q = disc.at_quad(phi)
    r = curvature_residual(q, disc.at_quad(lap), epsilon, C)
    s = reaction_derivative(q, epsilon, C)
    return disc.apply_laplacian_transpose(disc.quad_transpose(r)), disc.quad_transpose(r * s) / epsilon


def volume_gradient(disc: Discretization) -> np.ndarray:
    """dA = m (A is linear)."""
    return disc.weights.copy()


def area_gradient(disc: Discretization, phi: np.ndarray, epsilon: float) -> np.ndarray:
    """dB (see ``gradients``): the sum of its two ``area_gradient_parts``."""
    grad, well = area_gradient_parts(disc, phi, epsilon)
    return grad + well


def area_gradient_parts(disc: Discretization, phi: np.ndarray, epsilon: float):
    """The two terms summed into dB: eps K phi and P^T W W'(phi) / eps (they cancel across a tanh
    profile, as ``energy_gradient_parts`` do)."""
    q = disc.at_quad(phi)
    return epsilon * (disc.K @ phi), disc.quad_transpose(double_well_derivative(q)) / epsilon


def sharp_energy_sphere(B: float, dim: int) -> float:
    """E of (3) for the tanh profile of a circle/sphere of area 3 sqrt(2) B/4, c0 = 0, eps -> 0
    (``geometry.sphere_energy``, derivation there)."""
    return sphere_energy(surface_area(B), dim)
