"""Inexact Newton-CG with a backtracking line search for the augmented Lagrangian / penalty function

    f(phi) = rigidity E_h(phi) - lam . c(phi) + 1/2 sum_i rho_i c_i(phi)^2,   c = (A - alpha, B - beta).

lam = 0, rho = (M, M) is the paper's penalised energy (11) (rigidity on E only, M on the constraint
terms); otherwise it is the augmented Lagrangian of the exact-constraint problem. Its value is
``model.penalty.penalised_energy`` with the multiplier shift mu = lam. With
mu = lam - rho c, grad f = rig dE - mu_A dA - mu_B dB and

    Hess f = rig H_E - mu_B H_B + rho_A dA dA^T + rho_B dB dB^T        (A is linear: H_A = 0).

Steps come from ``krylov.projected_pcg`` with the Fourier/sparse model of ``precond`` (cE = rig,
cB = -mu_B, rho_A), forcing term eta = min(ETA_MAX, sqrt(rel)) (Eisenstat-Walker, superlinear), and
translation modes projected out on periodic boxes; on Fourier grids in the orthonormal Fourier
coordinates (``Objective.newton_system``, ``nk.system``), elsewhere on nodal values. Stationarity is measured in the dual norm of the
fixed model P0 (``precond.dual_norm``, the certificate's natural norm, ``model.metric``), two ways:

* the stopping test (``Objective.kkt``): |g|_* relative to the norms of the five elementary terms of
  g, rig (|dE_lap|_* + |dE_reac|_*) + |mu_A| |dA|_* + |mu_B| (|dB_grad|_* + |dB_well|_*)
  (``verify.kkt.terms_scale``): the quotient the certificate decides on (``kkt_dual``), so a solve
  stops where it can be certified rather than ending ``roundoff_stall`` after extra steps (issue
  25: the net terms below cancel 78x on a circle, 2800x on a sphere at its own targets);
* the step heuristics (forcing term, the round-off line search, ``Point.rel``): |g|_* relative to
  the net terms rig |dE|_* + |mu_A| |dA|_* + |mu_B| |dB|_* (never below the first), as before, so
  the iterates are those of the net test up to the step where the certificate's is met.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from vesicle_opt.blas import axpy
from vesicle_opt.model.penalty import penalised_energy
from vesicle_opt.nk.krylov import SubspacePreconditioner
from vesicle_opt.nk.system import FourierSystem, NodalSystem
from vesicle_opt.verify.kkt import terms_scale

log = logging.getLogger(__name__)  # one DEBUG line per Newton step (the CLI's -v)
ARMIJO = 1e-4  # sufficient-decrease constant (the usual textbook value)
ETA_MAX = 0.01  # CG relative tolerance cap of every Newton step (the forcing term above)
STEP_CAP = 1.0  # no Newton step changes a nodal value by more than 1 (phi lives in [-1, 1])
STALL = 1e-13  # an accepted step this small relative to |phi| changes phi only at round-off level
ROUNDOFF_REL = 1e-6  # below this relative stationarity f's decrease is under round-off: accept a full
# step when it reduces the dual gradient norm instead of testing Armijo
ROUNDOFF_F = 10.0  # ... and wherever the predicted decrease -slope is below ROUNDOFF_F sqrt(N) u |f|, the
# evaluation error of f (N nodal terms): at small multipliers that happens above ROUNDOFF_REL (issue 25:
# a c0 = 0.5 circle at eps 0.1, spectral 256^2, stalled at kkt_dual 1.1e-6 on Armijo's noise)


@dataclass
class Counters:
    newton: int = 0
    cg: int = 0
    evaluations: int = 0
    hvp: int = 0
    deriv_time: float = 0.0
    on_step: object = None  # called as on_step(relative dual stationarity) after every Newton step (progress)
    history: dict = field(default_factory=lambda: {"f": [], "dual_rel": [], "kkt_dual": [], "cg": [], "step": [],
                                                   "cg_status": []})

    def record(self, f: float, dual_rel: float, cg, step: float, kkt: float = float("nan")) -> None:
        """One Newton step done (numpy and ``nk_jax`` alike): its count and history row; ``cg`` the
        inner solve (iterations, status); ``step`` the accepted line-search step, 0 if none;
        ``dual_rel`` and ``kkt`` the two stationarity measures at its start (module docstring)."""
        self.newton += 1
        h = self.history
        h["f"].append(f)
        h["dual_rel"].append(dual_rel)
        h["kkt_dual"].append(kkt)
        h["cg"].append(cg.iterations)
        h["cg_status"].append(cg.status)
        h["step"].append(step)


@dataclass
class Point:
    phi: np.ndarray
    st: object
    f: float
    c: np.ndarray
    dE: np.ndarray
    dA: np.ndarray
    dB: np.ndarray
    mu: np.ndarray
    g: np.ndarray
    rel: float  # |g|_* relative to the net terms (the step heuristics; module docstring)
    gnorm: float = math.nan  # |g|_*
    extra_norm: float = 0.0  # |extra gradient|_* of a subclass's term (nk.proximal), 0 if none
    norms: tuple | None = None  # the five term norms of ``Objective.term_norms`` (on demand)
    kkt: float | None = None  # the stopping test's quotient (``Objective.kkt``, on demand)

    @property
    def E(self) -> float:
        """E_h at phi (``nk.stages``' extrapolation reads it here on numpy and ``nk_jax`` alike)."""
        return self.st.E


class Objective:
    def __init__(self, pf, prec, translations, rig: float, alpha: float, beta: float,
                 lam, rho, counters: Counters, coordinates: bool = True, coarse=None):
        self.pf, self.prec, self.translations = pf, prec, translations
        self.coarse = coarse  # mirror grids: the band's coarse space (``model.band_coarse.Lagged``), or None
        self.rig, self.target = float(rig), np.array([alpha, beta], float)
        self.lam, self.rho = np.asarray(lam, float), np.asarray(rho, float)
        self.cnt = counters
        self.coordinates = coordinates  # Fourier grids: CG in the orthonormal Fourier coordinates

    def value(self, phi) -> tuple[float, object]:
        st = self.pf.state(phi)
        c = np.array([st.A, st.B]) - self.target
        return penalised_energy(self.rig, st.E, c, self.rho[0], self.rho[1], self.lam), st

    def point(self, phi, f=None, st=None) -> Point:
        t0 = time.perf_counter()
        if st is None:
            f, st = self.value(phi)
        self.cnt.evaluations += 1
        c = np.array([st.A, st.B]) - self.target
        dE, dA, dB = self.pf.gradients(st)
        mu = self.lam - self.rho * c
        g = self.rig * dE
        axpy(-mu[0], dA, g)
        axpy(-mu[1], dB, g)
        dn = self.prec.dual_norm
        scale = self.rig * dn(dE) + abs(mu[0]) * dn(dA) + abs(mu[1]) * dn(dB)
        extra = self.extra_gradient(phi)
        extra_norm = 0.0
        if extra is not None:  # a term of a subclass's objective (nk.proximal), in the residual's scale too
            g = g + extra
            extra_norm = dn(extra)
            scale += extra_norm
        gnorm = dn(g)
        self.cnt.deriv_time += time.perf_counter() - t0
        return Point(phi, st, f, c, dE, dA, dB, mu, g, gnorm / max(scale, np.finfo(float).tiny), gnorm, extra_norm)

    def term_norms(self, pt: Point) -> tuple:
        """(|dE_lap|_*, |dE_reac|_*, |dA|_*, |dB_grad|_*, |dB_well|_*) at pt, the norms of the terms
        ``verify.kkt.terms_scale`` sums (``model.lumped.PhaseField.gradient_parts``); cached on pt."""
        if pt.norms is None:
            t0 = time.perf_counter()
            dn = self.prec.dual_norm
            if getattr(self, "_dn_dA", None) is None:
                self._dn_dA = dn(pt.dA)  # dA = m: one value for every point
            bend, reac, grad, well = self.pf.gradient_parts(pt.st)
            pt.norms = (dn(bend), dn(reac), self._dn_dA, dn(grad), dn(well))
            self.cnt.deriv_time += time.perf_counter() - t0
        return pt.norms

    def kkt(self, pt: Point) -> float:
        """The certificate's quotient at pt with the multipliers mu: |g|_* relative to the norms of
        g's elementary terms (``verify.kkt.terms_scale``, plus a subclass's term), i.e. ``kkt_dual``
        of ``verify.kkt`` in the preconditioner's copy of the natural norm; cached on pt."""
        if pt.kkt is None:
            scale = terms_scale(self.rig, pt.mu[0], pt.mu[1], self.term_norms(pt)) + pt.extra_norm
            pt.kkt = pt.gnorm / max(scale, np.finfo(float).tiny)
        return pt.kkt

    def kkt_at(self, pt: Point, lam) -> float:
        """The same quotient for r = rig dE - lam_A dA - lam_B dB at pt with other multipliers lam
        (the exact loop's least-squares ones, ``nk.solve._exact``)."""
        r = self.rig * pt.dE
        axpy(-lam[0], pt.dA, r)
        axpy(-lam[1], pt.dB, r)
        scale = terms_scale(self.rig, lam[0], lam[1], self.term_norms(pt))
        return self.prec.dual_norm(r) / max(scale, np.finfo(float).tiny)

    def stationarity(self, pt: Point) -> float:
        """What ``newton_minimize`` stops on: ``kkt`` (the certificate's quotient)."""
        return self.kkt(pt)

    def extra_gradient(self, phi):
        """The gradient of a term a subclass adds to the objective (None: none)."""
        return None

    def hvp(self, pt: Point):
        rA, rB = self.rho
        # the rank-one volume term rA dA dA^T (dA = m) is the product's own: on grids a constant
        # through the spectrum (``model.lumped.PhaseField.hvp_operator``)
        product = self.pf.hvp_operator(pt.st, self.pf.hessian_parts(pt.st), self.rig, -pt.mu[1], rA)
        dB = pt.dB

        def H(v):
            t0 = time.perf_counter()
            out = product(v)
            if rB:
                axpy(rB * float(dB @ v), dB, out)
            self.cnt.hvp += 1
            self.cnt.deriv_time += time.perf_counter() - t0
            return out
        return H

    def newton_system(self, pt: Point):
        """The Newton system at pt (``nk.system``): in the orthonormal Fourier coordinates on
        periodic Fourier grids (``coordinates``, the default there), else on nodal values."""
        fourier = self.pf.ops.fourier
        if not (self.coordinates and self.pf.uniform_weight is not None and hasattr(fourier, "coordinates")):
            return NodalSystem(self.hvp(pt), self.preconditioner(pt))
        w = self.pf.uniform_weight
        coords = fourier.coordinates
        product = self.pf.hvp_coordinates(pt.st, self.pf.hessian_parts(pt.st), self.rig, -pt.mu[1], self.rho[0])
        rank_one = (self.rho[1], coords.forward(pt.dB)) if self.rho[1] else None
        return FourierSystem(coords, product, fourier.multiplier(1.0 / self.fourier_symbol(pt)),
                             self.translation_coordinates(pt, w), rank_one, self.hessian_shift(), self.cnt)

    def fourier_symbol(self, pt: Point) -> np.ndarray:
        """p of the Fourier model of the Hessian at pt (``nk.precond.FourierPreconditioner.symbol``)."""
        return self.prec.symbol(self.rig, -pt.mu[1], self.rho[0])

    def translation_coordinates(self, pt: Point, w: float):
        """T(w d_i phi) as rows (``mesh.coordinates``), or None where no mode is projected out."""
        return self.translations(pt.phi, w, coordinates=True)

    def hessian_shift(self) -> float:
        """A multiple of the identity a subclass adds to the Hessian on one-weight grids (0 here)."""
        return 0.0

    def preconditioner(self, pt: Point) -> SubspacePreconditioner:
        """The bulk model P of ``precond`` (cE = rig, cB = -mu_B, rho_A), on mirror grids with the
        interface band's coarse space added (``coarse``: P^{-1} + Z Hc^{-1} Z^T, SPD, so CG keeps it;
        ``model.band_coarse``), reused while the state moves little (``band_coarse.Lagged``)."""
        pinv = self.prec.inverse(self.rig, -pt.mu[1], self.rho[0])
        if self.coarse is not None:
            made = self.coarse.band_coarse(self.pf.ops.fourier, pt.st.phi, pt.st.s, self.rig, -float(pt.mu[1]))
            pinv = made.additive(pinv)
        w = self.pf.uniform_weight  # grids: one weight, folded into the spectral derivatives
        if w is not None:
            C = self.translations(pt.phi, w)
        else:
            T = self.translations(pt.phi)
            C = None if T is None else self.pf.m[:, None] * T
        return SubspacePreconditioner(pinv, C)


def newton_minimize(obj: Objective, phi: np.ndarray, tol: float, max_iter: int, max_cg: int = 200):
    """Minimise obj from phi until its stationarity (``Objective.stationarity``) <= tol. Returns
    (Point, status)."""
    cnt = obj.cnt
    pt = obj.point(phi)
    for _ in range(max_iter):
        if not np.isfinite(pt.f) or not np.isfinite(pt.rel):
            return pt, "non_finite"
        stat = obj.stationarity(pt)  # the certificate's quotient; pt.rel (net terms) steers the step
        if stat <= tol:
            return pt, "converged"
        eta = min(ETA_MAX, np.sqrt(pt.rel))
        system = obj.newton_system(pt)
        cg = system.solve(-pt.g, eta, max_cg)
        cnt.cg += cg.iterations
        p = cg.x
        slope = float(pt.g @ p)
        if not slope < 0:  # cannot happen in exact arithmetic; fall back to the model gradient
            p = system.precondition(-pt.g)
            slope = float(pt.g @ p)
            if not slope < 0:
                return pt, "no_descent_direction"
        del system  # its operators and work fields are not held through the line search
        t = min(1.0, STEP_CAP / max(float(np.max(np.abs(p))), np.finfo(float).tiny))
        accepted = None
        noisy = pt.rel < ROUNDOFF_REL or -slope <= ROUNDOFF_F * np.sqrt(p.size) * np.finfo(float).eps * abs(pt.f)
        for _ls in range(40):
            trial = pt.phi + t * p
            f_new, st_new = obj.value(trial)
            if np.isfinite(f_new) and f_new <= pt.f + ARMIJO * t * slope:
                accepted = obj.point(trial, f_new, st_new)
                break
            if noisy and t == 1.0 and np.isfinite(f_new):
                full = obj.point(trial, f_new, st_new)  # t = 1: trial is phi + p
                if full.rel < pt.rel:
                    accepted = full
                    break
            t *= 0.5
        cnt.record(pt.f, pt.rel, cg, t if accepted is not None else 0.0, stat)
        log.debug("Newton %3d  f = %.12g  kkt_dual = %.2e (net %.2e)  cg = %3d (%s)  step = %.3g", cnt.newton, pt.f,
                  stat, pt.rel, cg.iterations, cg.status, t if accepted is not None else 0.0)
        if cnt.on_step is not None:
            cnt.on_step(stat)
        if accepted is None:
            return pt, "line_search_failed"
        if t * float(np.max(np.abs(p))) <= STALL * max(1.0, float(np.max(np.abs(pt.phi)))):
            return accepted, "stalled"  # steps below round-off of phi: no further progress possible
        pt = accepted
    return pt, "converged" if obj.stationarity(pt) <= tol else "max_iter"


def hessian_solves(obj: Objective, pt: Point, rhs, eta: float, max_cg: int = 200) -> list:
    """H^{-1} b for each b of ``rhs`` on the translation-free subspace, one Newton system (for the
    multipliers' Newton update)."""
    system = obj.newton_system(pt)
    out = [system.solve(b, eta, max_cg) for b in rhs]
    obj.cnt.cg += sum(cg.iterations for cg in out)
    return out
