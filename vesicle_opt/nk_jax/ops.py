"""E_h (6), A (7), B (8), their gradients, Hessian-vector products and the Fourier preconditioner
on a periodic grid, in JAX (float64, ``jit``): the device form of ``model.lumped`` and
``nk.precond.FourierPreconditioner``, line for line (tests compare them to round-off).

Fields live in grid shape (n_0, ..., n_{d-1}), C order (``reshape`` of the numpy path's node
vectors), optionally split across devices along the first grid axis (``layout.GridLayout``):
every kernel constrains its field outputs to that sharding, the FFTs run slab-decomposed
(``layout``) and every sum goes through ``layout.total`` (a fixed order on any number of devices).

With m the constant cell weight (Fourier grids: nodal quadrature), sigma the symbol of Delta_h,
g(phi) = (phi/eps + C)(1 - phi^2) and s = g'(phi):

    r = eps Delta_h phi + g(phi),  E = m/(2 eps) sum r^2,  A = m sum phi,
    B = -eps/2 m sum phi Delta_h phi + m/eps sum W(phi),
    dE = (eps Delta_h (m r) + s m r)/eps,  dA = m,  dB = m (-eps Delta_h phi + W'(phi)/eps),
    (cE H_E + cB H_B) v = cE [(eps Delta_h u + s u)/eps + m r g'' v/eps] + cB [-eps m Delta_h v + m W'' v/eps],
    u = m (eps Delta_h v + s v),

and the model P(k) = max(cE p0 + cB m q, FLOOR cE p0) (+ rho_A m^2 N at k = 0), q = eps(-sigma) + 2/eps,
p0 = m q^2/eps (``nk.precond``). The symbols are rebuilt inside each kernel from the 1D wavenumbers
(broadcast, fused by XLA), so no full-size symbol array is stored (``memory_bytes_per_node``: the
device memory of a solve, a node).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from vesicle_opt.model import functionals as F
from vesicle_opt.model.lumped import bulk_shift
from vesicle_opt.nk.precond import FLOOR

jax.config.update("jax_enable_x64", True)  # float64 throughout: the certificate's tolerances need it


class GridOps:
    """Jitted kernels of one periodic grid (``mesh.spectral.FourierGrid``) at given eps, C."""

    def __init__(self, fourier, epsilon: float, C: float, layout):
        self.shape, self.dim, self.kind = fourier.shape, fourier.dim, fourier.kind
        self.size, self.h = fourier.size, tuple(float(x) for x in fourier.h)
        self.m, self.eps, self.C = float(fourier.cell), float(epsilon), float(C)
        self.layout = layout
        self._k = [np.ravel(k) for k in fourier.k]  # 1D wavenumbers (rfft layout on the last axis)
        self._ik = [np.ravel(ik.imag) for ik in fourier.ik]  # spectral d/dx_i, Nyquist zeroed
        self.shift = bulk_shift(self.eps)
        last = self.shape[-1]
        w = np.full(last // 2 + 1, 2.0)  # Parseval for rfft: interior columns count twice
        w[0] = 1.0
        if last % 2 == 0:
            w[-1] = 1.0
        self._parseval = w
        jit = jax.jit
        self.state = jit(self._state)
        self.gradients = jit(self._gradients)
        self.hessian_parts = jit(self._hessian_parts)
        self.hvp = jit(self._hvp)
        self.apply_inverse = jit(self._apply_inverse)
        self.dual_norm = jit(self._dual_norm)
        self.derivatives = jit(self._derivatives)
        self.lap = jit(self._lap)

    # --- symbols (rebuilt in each trace from the 1D wavenumbers) -------------------------------
    def _axis(self, values, d):
        return jnp.asarray(values).reshape([-1 if i == d else 1 for i in range(self.dim)])

    def symbol(self):
        """sigma of Delta_h, accumulated in ``FourierGrid``'s order (0 - k_0^2 - k_1^2 ...)."""
        sym = 0.0
        for d in range(self.dim):
            k = self._axis(self._k[d], d)
            if self.kind == "spectral":
                sym = sym - k**2
            else:
                sym = sym - (4 / self.h[d] ** 2) * jnp.sin(k * self.h[d] / 2) ** 2
        return sym

    def _q(self):
        return self.eps * -self.symbol() + self.shift  # model.lumped.bulk_symbol

    def _p0(self):
        return self.m / self.eps * self._q() ** 2

    # --- transforms ---------------------------------------------------------------------------
    def _fft(self, v):
        return self.layout.rfftn(v)

    def _ifft(self, vh):
        return self.layout.irfftn(vh)

    def _lap(self, v):
        return self._ifft(self.symbol() * self._fft(v))

    def _derivatives(self, v):
        vh = self._fft(v)
        return tuple(self._ifft(1j * self._axis(self._ik[d], d) * vh) for d in range(self.dim))

    # --- the functionals and their derivatives (model.lumped) -----------------------------------
    def _state(self, phi):
        eps, C, m = self.eps, self.C, self.m
        lap = self._lap(phi)
        r = F.curvature_residual(phi, lap, eps, C)
        s = F.reaction_derivative(phi, eps, C)
        total = self.layout.total  # the same bits on any device count (``reduce``)
        E = m * total(r * r) / (2 * eps)
        A = m * total(phi)
        B = -eps / 2 * (m * total(phi * lap)) + m * total(F.double_well(phi)) / eps
        return lap, r, s, E, A, B

    def _gradients(self, phi, lap, r, s):
        eps, m = self.eps, self.m
        mr = m * r
        dE = (eps * self._lap(mr) + s * mr) / eps
        dB = m * (-eps * lap + F.double_well_derivative(phi) / eps)
        return dE, dB

    def _hessian_parts(self, phi, r):
        eps, m = self.eps, self.m
        return (m * r * F.reaction_second_derivative(phi, eps, self.C) / eps,
                m * F.double_well_second_derivative(phi) / eps)

    def _hvp(self, s, dE_diag, dB_diag, dB, v, rig, cB, rho_A, rho_B):
        """(rig H_E + cB H_B + rho_A dA dA^T + rho_B dB dB^T) v: ``nk.newton_cg.Objective.hvp``."""
        eps, m = self.eps, self.m
        lv = self._lap(v)
        u = m * (eps * lv + s * v)
        out = rig * ((eps * self._lap(u) + s * u) / eps + dE_diag * v)
        out = out + cB * (eps * (-m * lv) + dB_diag * v)
        out = out + rho_A * self.layout.total(m * v) * m + rho_B * self.layout.dot(dB, v) * dB
        return self.layout.constrain(out)

    # --- the Fourier model of the Hessian (nk.precond.FourierPreconditioner) ---------------------
    def _inverse_symbol(self, cE, cB, rho_A):
        q = self._q()
        p0 = self.m / self.eps * q**2
        bend = cE * p0
        p = jnp.maximum(bend + cB * self.m * q, FLOOR * bend)
        p = p.at[(0,) * self.dim].add(rho_A * self.m**2 * self.size)
        return 1.0 / p

    def _apply_inverse(self, v, cE, cB, rho_A):
        return self._ifft(self._inverse_symbol(cE, cB, rho_A) * self._fft(v))

    def _dual_norm(self, v):
        vh = self._fft(v)
        w = self._axis(self._parseval, self.dim - 1)
        val = self.layout.spectrum_total(w / self._p0() * jnp.abs(vh) ** 2) / self.size
        return jnp.sqrt(jnp.maximum(val, 0.0))


CG_TEMP_BYTES = 88.8  # bytes a node of XLA temporaries inside the compiled CG loop (CG's x, r, z, p, Hp,
# the transforms of two products and the products that ``layout.total`` sums row by row):
# ``memory_analysis()`` of the program, 88.8 at 64^3, 89.6 at 32^3 (72.5 before the row-wise sums)


SLAB_BYTES = 0.6  # bytes a node (over D) of the slab FFT's all_to_all buffers on D > 1 devices: measured
# 93.11 bytes a global node per device for the CG program at 32^3 on two devices against 185.59 / 2


def memory_bytes_per_node(dim: int = 3, devices: int = 1) -> float:
    """Bytes each device holds per node of the whole grid at the peak of a Newton-CG solve on this
    backend (the CG loop), the grid split over ``devices`` (``layout``).

    Float64 fields: the compiled CG program's arguments (b, s, the two Hessian diagonals, dB, and the
    subspace preconditioner's C_i = m d_i phi and U_i = P^{-1} C_i: 5 + 2 dim) and output (x), the
    Newton point's phi, Delta_h phi, r, dE, g and dA = m held outside it (6), plus the program's
    temporaries ``CG_TEMP_BYTES``: 232.8 bytes a node in 3D (XLA's memory analysis of the program
    on the CPU; a GPU's FFT workspace comes on top and is not measured here), divided by D, plus
    ``SLAB_BYTES`` / D for the transposes when D > 1.
    """
    one = 8.0 * ((5 + 2 * dim) + 1 + 6) + CG_TEMP_BYTES
    return (one + (SLAB_BYTES if devices > 1 else 0.0)) / devices


def largest_grid_per_gib(gib: float = 1.0, dim: int = 3, devices: int = 1) -> int:
    """The largest n with n^dim nodes when each of ``devices`` has ``gib`` GiB (``memory_bytes_per_node``)."""
    return int((gib * 2**30 / memory_bytes_per_node(dim, devices)) ** (1 / dim))
