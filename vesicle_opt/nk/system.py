"""The Newton system H x = b of one Newton step, solved by projected PCG (``nk.krylov``) in one of
two coordinate systems; x is returned as nodal values either way.

* ``NodalSystem``: CG on the nodal values, with the Hessian product and the preconditioner given
  (every mesh; the mirror grids of ``mesh.cosine``).
* ``FourierSystem``: CG in the orthonormal Fourier coordinates y = T v of a periodic grid
  (``mesh.coordinates``; spectral and FFT-applied FD grids). T is orthogonal, so this is the same
  iteration in exact arithmetic (the same iterates, residuals and stopping test, mapped by T), but
  the Fourier preconditioner P^{-1} = F^{-1} diag(1/p) F is diag(1/p) there, the translation modes
  T(m d_i phi) come from one transform and U = P^{-1} C from a multiply, and the Hessian product
  (``PhaseField.hvp_coordinates``) takes four transforms: a CG step costs four transforms instead
  of six (64^3 torus, pyFFTW, one thread: the solve's CG time from 0.86 to ~0.7 s, see the README).
  The right-hand side and the solution cost one transform each per solve.
"""

from __future__ import annotations

import time

import numpy as np

from vesicle_opt.blas import axpy
from vesicle_opt.nk.krylov import CGResult, SubspacePreconditioner, projected_pcg


class NodalSystem:
    """H x = b on nodal values: ``hvp`` a product, ``precond`` a ``SubspacePreconditioner``."""

    def __init__(self, hvp, precond: SubspacePreconditioner):
        self.hvp, self.precond = hvp, precond

    def solve(self, b: np.ndarray, eta: float, max_cg: int) -> CGResult:
        return projected_pcg(self.hvp, b, self.precond, eta, max_cg)

    def precondition(self, v: np.ndarray) -> np.ndarray:
        """P^{-1} v on the translation-free subspace (a descent direction's fallback)."""
        return self.precond(v.copy())


class FourierSystem:
    """H x = b in the coordinates y = T v of a Fourier grid (module docstring).

    ``product``: y -> T H_grid T^{-1} y (``PhaseField.hvp_coordinates``); ``inv_symbol``: 1/p of the
    Fourier model, paired (``FourierGrid.multiplier``); ``rows``: T of the translation modes as
    (k, size) rows, or None; ``rank_one``: (rho_B, T dB) of the penalty's rank-one area term, or None;
    ``shift``: a multiple c of the identity added to H (``nk.proximal``: c m, m the grid weight);
    ``counters``: the ``newton_cg.Counters`` whose hvp count and derivative time the products add to."""

    def __init__(self, coords, product, inv_symbol, rows=None, rank_one=None, shift: float = 0.0,
                 counters=None):
        self.coords, self.product = coords, product
        self.rank_one, self.shift, self.cnt = rank_one, float(shift), counters
        inv = inv_symbol.ravel()

        def pinv(r: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
            """diag(1/p) r, projected onto T's range (``FourierCoordinates.project``: the directions
            stay in it whatever round-off r carries outside it). A closure, not a bound method: a
            system holding its own method is a reference cycle, which only the cyclic collector
            frees, so spent systems (a dozen fields each) piled up (64^3: peak RSS 184 -> 346 MB)."""
            return coords.project(np.multiply(inv, r, out=out))
        self.precond = SubspacePreconditioner(pinv, None if rows is None else rows.T, writes_into=True)

    def hvp(self, y: np.ndarray) -> np.ndarray:
        t0 = time.perf_counter()
        out = self.product(y)
        if self.rank_one is not None:
            rho, d = self.rank_one
            axpy(rho * float(d @ y), d, out)
        if self.shift:
            axpy(self.shift, y, out)
        if self.cnt is not None:
            self.cnt.hvp += 1
            self.cnt.deriv_time += time.perf_counter() - t0
        return out

    def solve(self, b: np.ndarray, eta: float, max_cg: int) -> CGResult:
        cg = projected_pcg(self.hvp, self.coords.forward(b), self.precond, eta, max_cg)
        return CGResult(self.coords.backward(cg.x), cg.iterations, cg.status, cg.rel_residual)

    def precondition(self, v: np.ndarray) -> np.ndarray:
        """P^{-1} v on the translation-free subspace (a descent direction's fallback)."""
        return self.coords.backward(self.precond(self.coords.forward(v)))
