"""The shared interface of all spatial discretisations (Definition 2.2 and its FD special case).

A :class:`Discretization` holds nodes, nodal quadrature weights m (the lumped mass), the stiffness
K_ij = <grad psi_i, grad psi_j>, the consistent mass M_ij = <psi_i, psi_j> (FD: diag(m)), and the
quadrature that integrates nodal nonlinear terms:

* ``nodal`` (default): sum_i m_i F(phi_i), the mass-lumping rule; for FD this is the grid sum;
* ``gauss``: sum_q W_q F((P phi)_q) with P the P1 interpolation to Gauss points of each element.

The discrete Laplacian of Definition 2.2 is ``-M^{-1} K`` (consistent) or ``-M_L^{-1} K`` (lumped).
The consistent one is never formed: the NLP carries w = Delta_h phi with M w + K phi = 0 and numpy
evaluation solves with a cached sparse LU of M.

Several features need the lumped setting (Delta_h = -M_L^{-1} K and nodal quadrature): the
matrix-free model (``model.lumped``, hence the newton-krylov backend), the gradient flows and the
SCP baseline. :func:`require_lumped` is their one guard (on scene values, before any work) and
:meth:`Discretization.require_lumped` the same on a built discretisation; ``LUMPED`` is the
supported setting, which ``backends.SUPPORT`` reuses.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vesicle_opt.errors import NotSupported

LUMPED = {"mesh.mass": "lumped", "mesh.quadrature": "nodal"}  # the setting of require_lumped


def grid_points(axes) -> np.ndarray:
    """The nodes of a tensor grid (C order, the first axis slowest) as an (N, d) array: the
    coordinate arrays broadcast, written once (``meshgrid``'s copies and their ravels cost three
    passes more, 96 against 14 ms for a first 65^3 grid in a process, measured)."""
    return np.stack(np.meshgrid(*axes, indexing="ij", copy=False), axis=-1).reshape(-1, len(axes))


def require_lumped(feature: str, mass: str, quadrature: str, why: str = "") -> None:
    """NotSupported naming ``mesh.mass`` or ``mesh.quadrature`` unless they are ``LUMPED``'s values.

    ``feature`` names what needs them ("the gradient flows"); ``why`` is appended as a reason/hint.
    """
    for key, value in (("mesh.mass", mass), ("mesh.quadrature", quadrature)):
        if value != LUMPED[key]:
            raise NotSupported(key, f"{feature} support {key} = {LUMPED[key]!r} only, got {value!r}"
                                    f"{' (' + why + ')' if why else ''}")


@dataclass(frozen=True, eq=False)
class Discretization:
    kind: str  # "fem-p1" | "fd"
    dim: int
    nodes: np.ndarray  # (N, dim)
    weights: np.ndarray  # (N,) lumped mass = nodal quadrature weights
    K: sp.csr_matrix  # stiffness
    M: sp.csr_matrix  # consistent mass (FD: diag(weights))
    mass: str  # "lumped" | "consistent"
    h: float  # largest edge / grid spacing
    volume: float  # |Omega|
    box: tuple
    quad_P: sp.csr_matrix | None = None  # Gauss quadrature: interpolation (n_q x N); None = nodal
    quad_w: np.ndarray | None = None  # Gauss weights (n_q,)
    grid_shape: tuple[int, ...] | None = None  # structured periodic grids: nodes in C order
    mesh: object = None  # scikit-fem mesh (FEM), for output
    unfold: sp.csr_matrix | None = None  # periodic FEM: maps periodic dofs to all mesh nodes

    axisymmetric = False  # (class attribute) the meridian discretisation (``mesh.axisymmetric``) says True

    @property
    def n_nodes(self) -> int:
        return self.nodes.shape[0]

    @property
    def mesh_dim(self) -> int:
        """The mesh's dimension (columns of ``nodes``); ``dim`` is the geometry's (3 on the meridian
        half-plane of ``mesh.axisymmetric``, equal to this everywhere else)."""
        return self.nodes.shape[1]

    def scene_points(self):
        """(points, box) where the scene's shapes are evaluated (``scene.shapes.phase_field``): the
        nodes and the box; the meridian discretisation maps (r, z) to (r, 0, z)."""
        return self.nodes, self.box

    @property
    def consistent(self) -> bool:
        return self.mass == "consistent"

    @property
    def quadrature(self) -> str:
        """``nodal`` or ``gauss`` (the scene's ``mesh.quadrature``)."""
        return "gauss" if self.quad_P is not None else "nodal"

    def require_lumped(self, feature: str, why: str = "") -> None:
        """:func:`require_lumped` on this discretisation's mass and quadrature."""
        require_lumped(feature, self.mass, self.quadrature, why)

    @cached_property
    def laplacian(self) -> sp.csr_matrix:
        """The lumped discrete Laplacian -M_L^{-1} K (sparse). Only for ``mass == 'lumped'``."""
        if self.consistent:
            raise ValueError("the consistent-mass Laplacian is dense; use apply_laplacian")
        return sp.csr_matrix(-sp.diags(1.0 / self.weights) @ self.K)

    @cached_property
    def _mass_lu(self):
        return spla.splu(sp.csc_matrix(self.M))

    def apply_laplacian(self, phi: np.ndarray) -> np.ndarray:
        """Delta_h phi of Definition 2.2 (numpy evaluation)."""
        if self.consistent:
            return -self._mass_lu.solve(self.K @ phi)
        return self.laplacian @ phi

    def apply_laplacian_transpose(self, v: np.ndarray) -> np.ndarray:
        """(Delta_h)^T v, used by the adjoint (gradient) of the energy."""
        if self.consistent:
            return -(self.K @ self._mass_lu.solve(v))  # M, K symmetric
        return -(self.K @ (v / self.weights))

    def solve_mass(self, v: np.ndarray) -> np.ndarray:
        """M^{-1} v with the mass of this discretisation (lumped: diagonal)."""
        return self._mass_lu.solve(v) if self.consistent else v / self.weights

    # quadrature of nodal nonlinear terms
    @property
    def gauss(self) -> bool:
        return self.quad_P is not None

    def at_quad(self, v: np.ndarray) -> np.ndarray:
        return self.quad_P @ v if self.gauss else v

    def integrate(self, values_at_quad: np.ndarray) -> float:
        w = self.quad_w if self.gauss else self.weights
        return float(w @ values_at_quad)

    def quad_transpose(self, v: np.ndarray) -> np.ndarray:
        """P^T (W v): the adjoint of ``integrate(F(at_quad(phi)))`` with respect to phi."""
        if self.gauss:
            return self.quad_P.T @ (self.quad_w * v)
        return self.weights * v

    def dual_norm(self, v: np.ndarray) -> float:
        """|v|_* = sqrt(v^T M^{-1} v): the L2 norm of the Riesz representative of a nodal-integral vector."""
        return float(np.sqrt(max(v @ self.solve_mass(v), 0.0)))

    def l2_norm(self, v: np.ndarray) -> float:
        return float(np.sqrt(v @ (self.M @ v)))

    def h1_seminorm(self, v: np.ndarray) -> float:
        return float(np.sqrt(max(v @ (self.K @ v), 0.0)))


@dataclass(frozen=True, eq=False)
class TransformDiscretization(Discretization):
    """A lumped discretisation whose Delta_h is diagonal in a transform's basis and applied by the
    grid object ``fourier`` (``laplacian(v)``, symmetric): the periodic Fourier grids
    (``mesh.spectral``) and the mirror-symmetric cosine grids (``mesh.cosine``). K is a
    ``LinearOperator``, never a matrix."""

    fourier: object = None

    @classmethod
    def of_grid(cls, grid, kind: str, volume: float):
        """The discretisation of a transform grid (``size``, ``cell``, ``dim``, ``h``, ``shape``,
        ``box``, ``nodes()``, ``laplacian``): uniform weights m = cell, K = -m Delta_h, M = diag(m);
        ``volume`` is |Omega| (the mirror grid's is its doubled box's)."""
        N = grid.size
        weights = np.full(N, grid.cell)

        def K(v):
            return -grid.cell * grid.laplacian(np.ravel(v))

        Kop = spla.LinearOperator((N, N), matvec=K, rmatvec=K, dtype=float)
        return cls(kind=kind, dim=grid.dim, nodes=grid.nodes(), weights=weights, K=Kop,
                   M=sp.diags(weights, format="csr"), mass="lumped", h=float(grid.h.max()), volume=volume,
                   box=grid.box, grid_shape=grid.shape, fourier=grid)

    @property
    def laplacian(self) -> spla.LinearOperator:  # type: ignore[override]
        n = self.n_nodes
        return spla.LinearOperator((n, n), matvec=self.fourier.laplacian, rmatvec=self.fourier.laplacian,
                                   dtype=float)

    def apply_laplacian(self, phi: np.ndarray) -> np.ndarray:
        return self.fourier.laplacian(np.asarray(phi, float))

    def apply_laplacian_transpose(self, v: np.ndarray) -> np.ndarray:
        return self.fourier.laplacian(np.asarray(v, float))
