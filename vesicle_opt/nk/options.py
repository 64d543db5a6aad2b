"""Frozen settings of the Newton-Krylov backend (optimistix style: tol required, the rest measured).

Each default is the value the backend's measurements were made with (``nk.solve`` docstring).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class NewtonKrylovOptions:
    tol: float  # relative stationarity in the dual norm, and the certificate's tol
    max_iter: int = 500  # Newton steps over all outer iterations and levels
    exact_max_outer: int = 30  # outer iterations of the method 'exact' (its own augmented Lagrangian with
    # dual Newton steps); solver.max_outer caps the method 'augmented', on both backends
    rho_hat: float = 10.0  # initial rho_i = rho_hat / (G_i^T P^{-1} G_i): the penalty dominates the model
    nested: bool = True  # nested iteration on Fourier grids (coarse levels first)
    coarse_min_n: int = 16  # nested iteration: coarsest grid side
    coarse_tol: float = 1e-5  # coarse levels only make a start; their error is far below the fine step's reach
    constraint_margin: float = 0.1  # 'exact' stops at |c| <= 0.1 tol (scaled as IPOPT's test): the energy
    # error lam . c then stays below the 1e-8 agreement with IPOPT (measured 7e-8 on a P1 ellipse with 1)
    w_refresh: float = 0.1  # a reused dual Hessian must cut |c| 10x per outer iteration, else recomputed
    w_tol: float = 1e-4  # CG tolerance of the two solves H^{-1} dA, H^{-1} dB of the dual Newton step: its
    # error only slows the (otherwise quadratic) multiplier convergence by ~1e-4 per outer iteration
    max_cg: int = 200  # CG iterations per Newton step
    fourier_coordinates: bool = True  # periodic Fourier grids: each Newton system's CG runs in the
    # orthonormal Fourier coordinates (``nk.system.FourierSystem``: four transforms a CG step, not six);
    # False runs it on nodal values (``NodalSystem``), the same iteration in exact arithmetic
    band_coarse: bool = True  # mirror grids: the interface band's coarse space in the Newton-CG preconditioner
    # (``model.band_coarse``, ``nk.solve.band_coarse_of``)
    tensor_fft: bool = True  # lumped P1 on a periodic tensor box runs on the FFT path it equals (the FD
    # stencil, ``nk.setup.fft_equivalent``); False keeps it on the sparse (Chebyshev) path of unstructured meshes

    @classmethod
    def from_scene(cls, scene: "Scene", **changes) -> "NewtonKrylovOptions":
        """The scene's ``solver.tol`` and ``solver.max_iter``, with ``changes`` to other fields."""
        return cls(tol=scene.solver.tol, max_iter=scene.solver.max_iter, **changes)
