"""The penalised energy E_{M,h} of (11), in one place, with the exact evaluation of its residuals.

Section 5's convention (the rigidity multiplies the bending energy only):

    E_{M,h}(phi) = rigidity E_h(phi) + M1/2 (A - alpha)^2 + M2/2 (B - beta)^2
                   [ - mu_A (A - alpha) - mu_B (B - beta) ]

(``penalised_energy``; the paper's M1 = M2 = M; with multiplier shifts mu it is the augmented
Lagrangian, mu = lam, rho = (M1, M2)). It is plain arithmetic on its arguments, so the same lines
evaluate numbers (certification, the flows' E_M and history, the Newton-Krylov objective) and
build CasADi expressions (the lifted penalty NLP, the minimising movement (23)); ``penalty_terms``
is its constraint part. ``residuals`` evaluates (A - alpha, B - beta) with compensated sums, and
``roundoff_floor`` is the least stationarity residual double precision permits at a given M (why
the penalty cannot be pushed to M -> infinity). The limit M -> inf from a continuation's stages
(Theorem 3.2) is ``model.extrapolation`` (``extrapolation``, ``richardson`` are imported from here too).
"""

from __future__ import annotations

import math

import numpy as np

from vesicle_opt.model import functionals as F
from vesicle_opt.model.extrapolation import extrapolation, richardson  # noqa: F401 (imported from here)
from vesicle_opt.sums import total

AL_REDUCTION = 0.25  # augmented Lagrangian: increase M when a residual did not drop by this factor


def penalised_energy(rigidity, E, res, M1, M2, mu=None):
    """E_{M,h} of (11): rigidity times E_h plus ``penalty_terms`` (floats or CasADi expressions).

    ``res`` = (A - alpha, B - beta); ``mu`` = (mu_A, mu_B) shifts it into the augmented Lagrangian.
    """
    return rigidity * E + penalty_terms(res, M1, M2, mu)


def penalty_terms(res, M1, M2, mu=None, scale=(1.0, 1.0)):
    """M1/2 res_A^2 + M2/2 res_B^2 [- mu_A res_A - mu_B res_B]: the constraint part of (11).

    With ``scale`` = (s_A, s_B) the residuals are given in those units, (A - alpha, B - beta) =
    (s_A res_A, s_B res_B) (the lifted NLP's scaled unknowns u); a scale of 1 changes no digit.
    The operations are in the order the lifted NLP always used: its IPOPT paths are sensitive to
    round-off (ellipse-2d n = 16 continuation: another order ends at another KKT point, E 2.66
    against 2.08), so a reordering here is a change of results there.
    """
    s0, s1 = scale
    out = M1 * s0**2 / 2 * res[0] ** 2 + M2 * s1**2 / 2 * res[1] ** 2
    if mu is not None:
        out = out - mu[0] * s0 * res[0] - mu[1] * s1 * res[1]
    return out


def residuals(disc, phi: np.ndarray, epsilon: float, alpha: float, beta: float) -> tuple[float, float]:
    """(A - alpha, B - beta) evaluated with compensated sums (``sums.total``).

    At M = 1e8 the residuals are ~1e-8 while A, B are O(10-100): a plain sum loses ~1e-14 to
    cancellation, i.e. 1e-6 in M (A - alpha). The compensated sum of the nodal terms brings this to
    ~1e-16 (as math.fsum did, in a fifth of its time).
    """
    q = disc.at_quad(phi)
    w = disc.quad_w if disc.gauss else disc.weights
    A = total(disc.weights * phi, -alpha)
    grad = epsilon / 2 * phi * (disc.K @ phi)
    well = w * F.double_well(q) / epsilon
    B = total(grad, well, -beta)
    return A, B


def roundoff_floor(disc, phi, epsilon: float, C: float, rigidity: float, lam: tuple[float, float],
                   M: tuple[float, float], grads=None, norm=None, scale=None) -> float:
    """Least relative stationarity residual (verify.kkt) that double precision permits at penalty M.
    ``grads``: (dE, dA, dB) of ``functionals.gradients`` at phi, when the caller has them; ``norm``:
    the norm of the residual (default the L2 one, ``disc.dual_norm``; the certificate's is the natural
    norm of ``model.metric``, in which the same law holds with that norm's |dA|, |dB|); ``scale``: the
    denominator to be relative to (default the net terms below; the certificate passes kkt_dual's,
    ``verify.kkt.dual_scale``).

    The estimates lambda = mu - M (A - alpha) inherit the evaluation error of A and B inside the
    NLP (CasADi sums N nodal terms in order: error ~ sqrt(N) u_mach sum|terms|), multiplied by M:
    the floor is sqrt(N) M u (S_A |dA| + S_B |dB|) / (|rig dE| + |lambda_A dA| + |lambda_B dB|),
    S_A = sum |m_i phi_i|, S_B = B. (Measured on ellipse-2d 32^2 - 128^2, M = 1e4 ... 1e10: the
    L2 residuals sit at 0.05 - 2x of it.) It is why the penalty cannot be pushed to M -> inf: a stage
    whose floor reaches tol cannot be certified and is reported as not converged, with this reason;
    it is linear in M, so ``certifiable_M`` is the largest M a stage can be certified at.
    """
    dE, dA, dB = F.gradients(disc, phi, epsilon, C) if grads is None else grads
    norm = disc.dual_norm if norm is None else norm
    u = np.finfo(float).eps
    S_A = float(np.sum(np.abs(disc.weights * phi)))
    S_B = float(F.area_functional(F.NumpyOps(disc), phi, epsilon))
    if scale is None:
        scale = rigidity * norm(dE) + abs(lam[0]) * norm(dA) + abs(lam[1]) * norm(dB)
    num = np.sqrt(phi.size) * u * (M[0] * S_A * norm(dA) + M[1] * S_B * norm(dB))
    return float(num / max(scale, np.finfo(float).tiny))


def certifiable_M(floor: float, M: float, tol: float, margin: float = 2.0) -> float:
    """The M at which a penalty floor ``floor`` measured at ``M`` reaches tol / margin: the floor is
    linear in M (``roundoff_floor``), so M tol / (margin floor) (inf for a zero floor)."""
    return math.inf if not floor > 0 else M * tol / (margin * floor)


def schedule(M0: float, factor: float, M_max: float) -> list[float]:
    """M0, M0 r, M0 r^2, ... while <= M_max, with M_max itself appended as the last stage."""
    Ms = [float(M0)]
    while Ms[-1] * factor < M_max * (1 - 1e-12):
        Ms.append(Ms[-1] * factor)
    if Ms[-1] < M_max:
        Ms.append(float(M_max))
    return Ms


def next_stage(Ms: list[float], k: int, floor: float, tol: float, margin: float = 2.0) -> float | None:
    """The M of the stage after stage k of the schedule ``Ms`` (its floor ``floor`` at Ms[k]), or None
    to stop: the schedule stops raising M where the next stage's floor, linear in M
    (``roundoff_floor``), would reach tol / margin. Where the next M of the schedule is beyond that
    but the certifiable M (``certifiable_M``) is at least 1.5 Ms[k], a last stage runs there."""
    if k + 1 >= len(Ms):
        return None
    cap = certifiable_M(floor, Ms[k], tol, margin)
    if Ms[k + 1] <= cap:
        return Ms[k + 1]
    return float(cap) if cap >= 1.5 * Ms[k] else None


def penalty_retry(M: float, floor: float, tol: float, auto: bool) -> float | None:
    """The method penalty with ``solver.M = 'auto'`` (``auto``; M = its number, ``scene.ranges.M_DEFAULT``,
    read as "the largest M up to it that can be certified") whose floor reached tol: the M to solve at
    instead, warm-started, where the floor is tol / 2 (``certifiable_M``); None when the floor is below
    tol or M was a number (solved as given, and refused as ``roundoff_floor`` if its floor reaches
    tol). The result reports ``M_requested``."""
    if floor < tol or not auto:
        return None
    return float(certifiable_M(floor, M, tol))


class DualSecant:
    """The augmented Lagrangian's multiplier update: Broyden's secant method on c(mu) = 0, where
    c = (A - alpha, B - beta) at the minimiser of E_{M,h} - mu . c. Its Jacobian starts as I / M,
    which makes the first step the classical first-order update mu <- mu - M c = lambda (linear
    convergence, rate ~ 1 / (1 + M w), w the dual curvature); each later stage corrects it with the
    secant pair (delta mu, delta c), so on this 2 x 2 system the steps become Newton's on the dual
    (``nk.solve``'s exact loop takes that step with an assembled W = G^T H^-1 G; here nothing but the
    stages' own (mu, c) is needed). A new M restarts it at I / M (c(mu) changes with M)."""

    def __init__(self):
        self.J = None
        self.last = None  # (mu, c, M) of the previous stage

    def step(self, mu, c, M: float) -> np.ndarray:
        mu, c = np.asarray(mu, float), np.asarray(c, float)
        if self.last is not None and self.last[2] == M and self.J is not None:
            dmu, dc = mu - self.last[0], c - self.last[1]
            if float(dmu @ dmu) > 0:
                self.J = self.J + np.outer(dc - self.J @ dmu, dmu) / float(dmu @ dmu)
        else:
            self.J = np.eye(2) / M
        self.last = (mu, c, M)
        try:
            new = mu - np.linalg.solve(self.J, c)
        except np.linalg.LinAlgError:
            new = np.array([np.nan])
        if not np.all(np.isfinite(new)):  # a singular secant: the first-order step, and start over
            self.J = np.eye(2) / M
            new = mu - M * c
        return new


def ramp_schedule(solver, M: float) -> list[float]:
    """The augmented Lagrangian's warm-up: the continuation schedule's M0 r^k below M (mu = 0), each
    stage started from the last, so that the first multiplier stage starts near its minimiser (a cold
    start at M = 1e4 on the default scene took 63 IPOPT iterations; the ramp 10, 100, 1000 takes 25).
    Their floors also tell the largest certifiable M before any stage runs at M."""
    return [m for m in schedule(solver.M0, solver.M_factor, solver.M_max) if m < M]


def raise_M(M: float, res, prev, floor: float, tol: float, factor: float, M_max: float) -> float:
    """The augmented Lagrangian's penalty for the next stage: x ``factor`` (to M_max) when a relative
    residual did not drop by ``AL_REDUCTION``, but never beyond where the floor (linear in M) reaches
    tol / 2; lowered to there when the stage's own floor is within 3/4 of tol (kept otherwise, so that
    the secant's Jacobian stays valid)."""
    cap = certifiable_M(floor, M, tol)
    if floor >= 0.75 * tol:
        return float(cap)
    if any(rn > AL_REDUCTION * rp and rn > tol for rn, rp in zip(res, prev)):
        return float(max(M, min(M * factor, M_max, cap)))
    return float(M)
