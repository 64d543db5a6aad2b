"""Inexact Newton-CG with a backtracking line search on the device: ``nk.newton_cg`` line for line.

f(phi) = rigidity E_h - lam . c + 1/2 sum_i rho_i c_i^2, c = (A - alpha, B - beta) (the penalty (11)
for lam = 0, rho = (M, M); else the augmented Lagrangian of the exact-constraint problem); the same
constants (``nk.newton_cg.ARMIJO``, ``ETA_MAX``, ``STEP_CAP``, ``STALL``, ``ROUNDOFF_REL``), the same
forcing term, step cap, line search and stopping tests in the dual norm of the Fourier model P0 (the
stop on the certificate's quotient, ``DeviceObjective.kkt``; the steps steered by the net one, ``rel``).
Fields stay on the device(s); the host holds the scalars (f, c, mu, the dual norms) that steer
the iteration, read back once per evaluation.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from vesicle_opt.model import functionals as F
from vesicle_opt.model.penalty import penalised_energy
from vesicle_opt.nk.newton_cg import ARMIJO, ETA_MAX, ROUNDOFF_REL, STALL, STEP_CAP, Counters
from vesicle_opt.nk_jax.krylov import DeviceKrylov
from vesicle_opt.verify.kkt import terms_scale


@dataclass
class Point:
    phi: object
    st: tuple  # (lap, r, s) on the device
    f: float
    c: np.ndarray
    dE: object
    dB: object
    mu: np.ndarray
    g: object
    rel: float  # |g|_* relative to the net terms (the step heuristics, as ``nk.newton_cg.Point.rel``)
    E: float = math.nan  # E_h at phi (host scalar: the continuation's extrapolation, ``nk.stages``)
    gnorm: float = math.nan  # |g|_*
    norms: tuple | None = None  # the five term norms (``DeviceObjective.term_norms``, on demand)
    kkt: float | None = None  # the stopping test's quotient (``DeviceObjective.kkt``, on demand)


class DeviceObjective:
    """``nk.newton_cg.Objective`` on a ``ops.GridOps``; lam and rho are host arrays set by the caller."""

    def __init__(self, ops, rig: float, alpha: float, beta: float, lam, rho, counters: Counters):
        self.ops, self.krylov = ops, DeviceKrylov(ops)
        self.rig, self.target = float(rig), np.array([alpha, beta], float)
        self.lam, self.rho = np.asarray(lam, float), np.asarray(rho, float)
        self.cnt = counters
        self.ones = ops.layout.put(np.full(ops.size, ops.m))  # dA = m
        self.dn_dA = float(ops.dual_norm(self.ones))
        self._derive = jax.jit(self._derive_kernel)
        self._parts = jax.jit(self._parts_kernel)
        self._axpy = jax.jit(lambda x, t, p: x + t * p)
        self._dot = jax.jit(ops.layout.dot)
        self._amax = jax.jit(lambda a: jnp.max(jnp.abs(a)))

    def _derive_kernel(self, phi, lap, r, s, mu0, mu1):
        ops = self.ops
        dE, dB = ops._gradients(phi, lap, r, s)
        g = ops.layout.constrain(self.rig * dE - mu0 * ops.m - mu1 * dB)
        return dE, dB, g, ops._dual_norm(dE), ops._dual_norm(dB), ops._dual_norm(g)

    def _parts_kernel(self, phi, lap, r, s):
        """The norms of the four terms summed into dE and dB (``model.lumped.PhaseField.gradient_parts``):
        Delta_h (m r), s m r / eps, -eps m Delta_h phi, m W'(phi) / eps."""
        ops, eps, m = self.ops, self.ops.eps, self.ops.m
        mr = m * r
        dn = ops._dual_norm
        return (dn(ops._lap(mr)), dn(s * mr / eps), dn(-eps * m * lap),
                dn(m * F.double_well_derivative(phi) / eps))

    def term_norms(self, pt: Point) -> tuple:
        """(|dE_lap|_*, |dE_reac|_*, |dA|_*, |dB_grad|_*, |dB_well|_*) at pt (``nk.newton_cg.Objective.term_norms``)."""
        if pt.norms is None:
            t0 = time.perf_counter()
            lap, r, s = pt.st
            bend, reac, grad, well = (float(x) for x in jax.device_get(self._parts(pt.phi, lap, r, s)))
            pt.norms = (bend, reac, self.dn_dA, grad, well)
            self.cnt.deriv_time += time.perf_counter() - t0
        return pt.norms

    def kkt(self, pt: Point) -> float:
        """The certificate's quotient at pt with the multipliers mu (``nk.newton_cg.Objective.kkt``)."""
        if pt.kkt is None:
            scale = terms_scale(self.rig, pt.mu[0], pt.mu[1], self.term_norms(pt))
            pt.kkt = pt.gnorm / max(scale, np.finfo(float).tiny)
        return pt.kkt

    def stationarity(self, pt: Point) -> float:
        """What ``newton_minimize`` stops on: ``kkt``."""
        return self.kkt(pt)

    def value(self, phi):
        lap, r, s, E, A, B = self.ops.state(phi)
        E, A, B = (float(x) for x in jax.device_get((E, A, B)))
        c = np.array([A, B]) - self.target
        return penalised_energy(self.rig, E, c, self.rho[0], self.rho[1], self.lam), (lap, r, s, E, A, B)

    def point(self, phi, f=None, st=None) -> Point:
        t0 = time.perf_counter()
        if st is None:
            f, st = self.value(phi)
        self.cnt.evaluations += 1
        lap, r, s, E, A, B = st
        c = np.array([A, B]) - self.target
        mu = self.lam - self.rho * c
        dE, dB, g, dnE, dnB, dng = self._derive(phi, lap, r, s, mu[0], mu[1])
        dnE, dnB, dng = (float(x) for x in jax.device_get((dnE, dnB, dng)))
        scale = self.rig * dnE + abs(mu[0]) * self.dn_dA + abs(mu[1]) * dnB
        self.cnt.deriv_time += time.perf_counter() - t0
        return Point(phi, (lap, r, s), f, c, dE, dB, mu, g, dng / max(scale, np.finfo(float).tiny), float(E), dng)

    def hess(self, pt: Point) -> tuple:
        lap, r, s = pt.st
        dE_diag, dB_diag = self.ops.hessian_parts(pt.phi, r)
        return (s, dE_diag, dB_diag, pt.dB, self.rig, -pt.mu[1], self.rho[0], self.rho[1])

    def model(self, pt: Point):
        """(coef, subspace) of the preconditioner at pt: cE = rig, cB = -mu_B, rho_A."""
        coef = (self.rig, -pt.mu[1], self.rho[0])
        return coef, self.krylov.subspace(pt.phi, *coef)

    def pcg(self, pt: Point, b, eta: float, max_cg: int):
        coef, sub = self.model(pt)
        cg = self.krylov.pcg(b, self.hess(pt), coef, sub, eta, max_cg)
        self.cnt.cg += cg.iterations
        self.cnt.hvp += cg.iterations
        return cg, coef, sub


def newton_minimize(obj: DeviceObjective, phi, tol: float, max_iter: int, max_cg: int = 200):
    """``nk.newton_cg.newton_minimize`` on the device. Returns (Point, status)."""
    cnt = obj.cnt
    pt = obj.point(phi)
    for _ in range(max_iter):
        if not math.isfinite(pt.f) or not math.isfinite(pt.rel):
            return pt, "non_finite"
        stat = obj.stationarity(pt)  # the certificate's quotient; pt.rel (net terms) steers the step
        if stat <= tol:
            return pt, "converged"
        eta = min(ETA_MAX, math.sqrt(pt.rel))
        cg, coef, sub = obj.pcg(pt, -pt.g, eta, max_cg)
        p = cg.x
        slope = float(obj._dot(pt.g, p))
        if not slope < 0:  # cannot happen in exact arithmetic; fall back to the model gradient
            p = obj.krylov.precondition(-pt.g, coef, sub)
            slope = float(obj._dot(pt.g, p))
            if not slope < 0:
                return pt, "no_descent_direction"
        pmax = float(obj._amax(p))
        t = min(1.0, STEP_CAP / max(pmax, np.finfo(float).tiny))
        accepted = None
        for _ls in range(40):
            trial = obj._axpy(pt.phi, t, p)
            f_new, st_new = obj.value(trial)
            if math.isfinite(f_new) and f_new <= pt.f + ARMIJO * t * slope:
                accepted = obj.point(trial, f_new, st_new)
                break
            if pt.rel < ROUNDOFF_REL and t == 1.0 and math.isfinite(f_new):
                cand = obj.point(trial, f_new, st_new)
                if cand.rel < pt.rel:
                    accepted = cand
                    break
            t *= 0.5
        cnt.record(pt.f, pt.rel, cg, t if accepted is not None else 0.0, stat)
        if accepted is None:
            return pt, "line_search_failed"
        if t * pmax <= STALL * max(1.0, float(obj._amax(pt.phi))):
            return accepted, "stalled"
        pt = accepted
    return pt, "converged" if obj.stationarity(pt) <= tol else "max_iter"
