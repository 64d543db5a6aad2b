"""Projected preconditioned CG on the device: ``nk.krylov.projected_pcg`` as one ``lax.while_loop``.

The same iteration, stopping rules and results (x, iterations, status, rel_residual) as the numpy
path, with the constraint preconditioner z = P^{-1} r - U S^{-1} C^T P^{-1} r (U = P^{-1} C,
S = C^T U, C = m d_i phi: the translations projected out) of ``nk.krylov.SubspacePreconditioner``
in its residual-update form (r replaced by r - C S^{-1} U^T r, z = P^{-1} of it).
The whole loop is one compiled program: no host round trip per CG iteration (on a GPU a CG step
is then a handful of kernels); the Newton loop above it reads back scalars only.

Status codes of the loop: 0 running, 1 converged, 2 max_iter, 3 negative curvature.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp

STATUS = {1: "converged", 2: "max_iter", 3: "negative_curvature"}


@dataclass
class CGResult:
    x: object  # device field
    iterations: int
    status: str
    rel_residual: float


class DeviceKrylov:
    """Jitted subspace preconditioner and projected CG for one ``ops.GridOps``."""

    def __init__(self, ops):
        self.ops = ops
        self._dot = ops.layout.dot  # the same bits on any device count (``reduce``)
        self.subspace = jax.jit(self._subspace)
        self.precondition = jax.jit(self._precondition)
        self._pcg = jax.jit(self._pcg_loop)

    def _subspace(self, phi, cE, cB, rho_A):
        """(C, U, S): C_i = m d_i phi, U_i = P^{-1} C_i, S = C^T U (``SubspacePreconditioner``)."""
        ops = self.ops
        if ops.kind == "fd":  # no translation modes on FD grids (``nk.setup.prepare``)
            return (), (), jnp.zeros((0, 0))
        C = tuple(ops.m * t for t in ops._derivatives(phi))
        U = tuple(ops._apply_inverse(c, cE, cB, rho_A) for c in C)
        S = jnp.array([[self._dot(C[i], U[j]) for j in range(len(C))] for i in range(len(C))])
        return C, U, S

    def _reduce(self, r, sub):
        """The reduced residual r - C y, y = S^{-1} U^T r (the residual update of
        ``nk.krylov.SubspacePreconditioner``: P^{-1} of it is the projected z)."""
        C, U, S = sub
        if not C:
            return r
        y = jnp.linalg.solve(S, jnp.stack([self._dot(u, r) for u in U]))
        for j, c in enumerate(C):
            r = r - c * y[j]
        return self.ops.layout.constrain(r)

    def _reduce_and_precondition(self, r, coef, sub):
        """(r - C y, z = P^{-1} (r - C y)): the reduced residual (``_reduce``) and the projected
        preconditioned residual, as ``nk.krylov.SubspacePreconditioner`` forms them."""
        r = self._reduce(r, sub)
        return r, self.ops.layout.constrain(self.ops._apply_inverse(r, *coef))

    def _precondition(self, r, coef, sub):
        """z alone (``_reduce_and_precondition``)."""
        return self._reduce_and_precondition(r, coef, sub)[1]

    def _pcg_loop(self, b, hess, coef, sub, eta, max_iter):
        """hess = (s, dE_diag, dB_diag, dB, rig, cB, rho_A, rho_B); coef = (cE, cB, rho_A) of P."""
        ops = self.ops

        def H(v):
            return ops._hvp(*hess[:4], v, *hess[4:])

        def M(r):
            return self._reduce_and_precondition(r, coef, sub)

        x = jnp.zeros_like(b)
        r, z = M(b)
        rz = self._dot(r, z)
        code = jnp.where(rz <= 0.0, 1, 0)
        rz0 = jnp.where(rz <= 0.0, 1.0, rz)
        init = (jnp.int64(0), x, r, z, z, rz, rz0, jnp.float64(0.0), code)

        def cond(c):
            return c[-1] == 0

        def body(c):
            it, x, r, z, p, rz, rz0, rel, code = c
            it = it + 1
            Hp = H(p)
            curv = self._dot(p, Hp)

            def negative(_):
                first = it == 1
                xo = jnp.where(first, z, x)
                relo = jnp.where(first, 1.0, jnp.sqrt(rz / rz0))
                return (it, xo, r, z, p, rz, rz0, relo, jnp.int64(3))

            def step(_):
                a = rz / curv
                x2 = x + a * p
                r2, z2 = M(r - a * Hp)
                rz_new = self._dot(r2, z2)
                rel2 = jnp.sqrt(jnp.maximum(rz_new, 0.0) / rz0)
                done = jnp.where(rel2 <= eta, 1, jnp.where(it >= max_iter, 2, 0))
                p2 = z2 + (rz_new / rz) * p
                return (it, x2, r2, z2, p2, rz_new, rz0, rel2, done.astype(jnp.int64))

            return jax.lax.cond(curv <= 0.0, negative, step, None)

        out = jax.lax.while_loop(cond, body, init)
        return out[1], out[0], out[-1], out[-2]

    def pcg(self, b, hess, coef, sub, eta: float, max_iter: int) -> CGResult:
        x, it, code, rel = self._pcg(b, hess, coef, sub, eta, max_iter)
        return CGResult(x, int(it), STATUS[int(code)], float(rel))
