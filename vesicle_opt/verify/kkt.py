"""Independent first-order checks of a computed equilibrium, from the hand-derived gradients.

Two measures of the KKT residual r = rigidity dE - lambda_A dA - lambda_B dB (a nodal-integral
vector), both relative to the sizes of its terms and so free of units:

* ``kkt_dual`` (the certificate's, on every backend): in the natural norm |v|_nat =
  sqrt(v^T P0^{-1} v) of ``model.metric`` (P0 the Hessian of E_h at phi = +-1: a Fourier diagonal
  on Fourier and periodic FD grids, eps S^{-1} M_L S^{-1} on meshes),

      kkt_dual = |r|_nat / (|rigidity dE|_nat + |lambda_A dA|_nat + |lambda_B dB|_nat).

  Its round-off floor (``dual_floor``) grows like h^-2; to first order it bounds the error of the
  iterate in the energy norm (``model.metric``'s docstring).
* ``kkt_residual`` (reported beside it): the same in L2 through the Riesz representative
  M^{-1} v (lumped: v / m), |v|_* = sqrt(v^T M^{-1} v). Its round-off floor grows like h^-4
  (``nk.solve.l2_floor``), which is why it no longer decides.

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


def kkt_dual(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads=None) -> tuple[float, float]:
    """(kkt_dual, its round-off floor ``dual_floor``) in the natural norm (module docstring)."""
    grads = F.gradients(disc, phi, epsilon, C) if grads is None else grads
    metric = natural_metric(disc, epsilon)
    num, scale = _relative(metric.dual_norm, rigidity, lam_A, lam_B, grads)
    scale = max(scale, np.finfo(float).tiny)
    return num / scale, roundoff(metric, phi, rigidity, lam_B) / scale


def dual_floor(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads=None) -> float:
    """The least kkt_dual double precision permits at phi: the round-off of phi through the bulk
    Hessian (``model.metric.roundoff``), relative to the residual's own scale."""
    return kkt_dual(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads)[1]
