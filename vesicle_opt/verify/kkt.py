"""Independent first-order checks of a computed equilibrium, from the hand-derived gradients.

Two measures of the KKT residual r = rigidity dE - lambda_A dA - lambda_B dB (a nodal-integral
vector), both relative and so free of units:

* ``kkt_dual`` (the certificate's, on every backend): in the natural norm |v|_nat =
  sqrt(v^T P0^{-1} v) of ``model.metric`` (P0 the Hessian of E_h at phi = +-1: a Fourier diagonal
  on Fourier and periodic FD grids, eps S^{-1} M_L S^{-1} on meshes), relative to the sum of the
  norms of the elementary terms the residual is summed from (``dual_scale``),

      kkt_dual = |r|_nat / (rig (|dE_lap|_nat + |dE_reac|_nat) + |lambda_A| |dA|_nat
                            + |lambda_B| (|dB_grad|_nat + |dB_well|_nat)),

  dE = dE_lap + dE_reac and dB = dB_grad + dB_well the two terms of each gradient
  (``functionals.energy_gradient_parts``, ``area_gradient_parts``). This is the normwise backward
  error of the residual (the Rigal-Gaches / Oettli-Prager denominator |A||x| + |b|, not |Ax| + |b|:
  Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed., Thm 7.1): the two terms of dE
  nearly cancel across an equilibrium's interface (f_c ~ kappa phi', J phi' ~ 0), by 78x on a
  circle and 2800x on a sphere at its own targets, whose net force vanishes in the sharp limit, so a
  denominator built on the net dE measured the residual against a near-zero of the problem rather than
  against the forces it balances. Its round-off floor (``dual_floor``, same denominator) grows like
  h^-2; to first order |r|_nat bounds the error of the iterate in the energy norm
  (``model.metric``'s docstring). ``kkt_dual_net`` is the same residual relative to the net terms
  rig |dE|_nat + |lambda_A| |dA|_nat + |lambda_B| |dB|_nat (the denominator up to issue 25; it is
  never below ``kkt_dual``, by the triangle inequality; once Newton-Krylov's stopping test, which now
  stops on ``kkt_dual``'s own quotient, ``terms_scale``).
* ``kkt_residual`` (reported beside it): the L2 residual through the Riesz representative
  M^{-1} v (lumped: v / m), |v|_* = sqrt(v^T M^{-1} v), relative to the net terms. Its round-off
  floor grows like h^-4 (``nk.solve.l2_floor``), which is why it no longer decides.

Neither reuses anything of the NLP graph or the solver's own derivatives, so neither can be met by a
solver's say-so.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.model import functionals as F
from vesicle_opt.model.metric import natural_metric, roundoff


def dual_norm(disc, v: np.ndarray) -> float:
    """|v|_* of the module docstring (``Discretization.dual_norm``, the L2 one)."""
    return disc.dual_norm(v)


def _relative(norm, rigidity, lam_A, lam_B, grads) -> tuple[float, float]:
    """(|r|, |rig dE| + |lam_A dA| + |lam_B dB|) in ``norm``."""
    dE, dA, dB = grads
    terms = [rigidity * dE, lam_A * dA, lam_B * dB]
    return norm(terms[0] - terms[1] - terms[2]), sum(norm(t) for t in terms)


def kkt_residual(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads=None) -> float:
    """The relative L2 residual. ``grads``: (dE, dA, dB) of ``functionals.gradients`` at phi, when
    the caller has them."""
    grads = F.gradients(disc, phi, epsilon, C) if grads is None else grads
    num, scale = _relative(disc.dual_norm, rigidity, lam_A, lam_B, grads)
    return num / max(scale, np.finfo(float).tiny)


def terms_scale(rigidity, lam_A, lam_B, norms) -> float:
    """The denominator of ``kkt_dual`` from the norms of the five elementary terms of r, ``norms`` =
    (|dE_lap|, |dE_reac|, |dA|, |dB_grad|, |dB_well|): the one formula the certificate
    (``dual_scale``) and Newton-Krylov's stopping test (``nk.newton_cg.Objective.kkt``,
    ``nk_jax.newton``) share."""
    bend, reac, vol, grad, well = norms
    return abs(rigidity) * (bend + reac) + abs(lam_A) * vol + abs(lam_B) * (grad + well)


def dual_scale(disc, phi, epsilon, C, rigidity, lam_A, lam_B, norm=None) -> float:
    """The denominator of ``kkt_dual`` (module docstring): the norms of the five elementary terms of
    r, summed (``terms_scale``); ``norm`` defaults to the natural one."""
    norm = natural_metric(disc, epsilon).dual_norm if norm is None else norm
    bend, reac = F.energy_gradient_parts(disc, phi, epsilon, C)
    grad, well = F.area_gradient_parts(disc, phi, epsilon)
    return terms_scale(rigidity, lam_A, lam_B,
                       (norm(bend), norm(reac), norm(F.volume_gradient(disc)), norm(grad), norm(well)))


def kkt_dual_report(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads=None) -> dict[str, float]:
    """``kkt_dual``, its floor ``kkt_dual_floor``, the denominator ``kkt_dual_scale`` (absolute,
    so kkt_dual * kkt_dual_scale = |r|_nat) and ``kkt_dual_net`` (module docstring)."""
    grads = F.gradients(disc, phi, epsilon, C) if grads is None else grads
    metric = natural_metric(disc, epsilon)
    num, net = _relative(metric.dual_norm, rigidity, lam_A, lam_B, grads)
    tiny = np.finfo(float).tiny
    scale = max(dual_scale(disc, phi, epsilon, C, rigidity, lam_A, lam_B, metric.dual_norm), tiny)
    return {"kkt_dual": num / scale, "kkt_dual_floor": roundoff(metric, phi, rigidity, lam_B) / scale,
            "kkt_dual_scale": scale, "kkt_dual_net": num / max(net, tiny)}


def kkt_dual_with(disc, phi, epsilon, C, rigidity, lam_A, lam_B, force: np.ndarray, scale: float) -> float:
    """|r + force|_nat / scale: ``kkt_dual`` (``scale`` its denominator, ``kkt_dual_scale``) of the
    problem with one more row, ``force`` that row's multiplier times its gradient (the axial pin's,
    ``nlp.reuse.unpinned``)."""
    dE, dA, dB = F.gradients(disc, phi, epsilon, C)
    r = rigidity * dE - lam_A * dA - lam_B * dB + force
    return natural_metric(disc, epsilon).dual_norm(r) / max(scale, np.finfo(float).tiny)


def kkt_dual(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads=None) -> tuple[float, float]:
    """(kkt_dual, its round-off floor ``dual_floor``) in the natural norm (module docstring)."""
    rep = kkt_dual_report(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads)
    return rep["kkt_dual"], rep["kkt_dual_floor"]


def dual_floor(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads=None) -> float:
    """The least kkt_dual double precision permits at phi: the round-off of phi through the bulk
    Hessian (``model.metric.roundoff``), relative to kkt_dual's own scale (``dual_scale``)."""
    return kkt_dual(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads)[1]
