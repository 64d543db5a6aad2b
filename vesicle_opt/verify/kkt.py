"""Independent first-order checks of a computed equilibrium, from the hand-derived gradients.

The residual is measured in L2 through the Riesz representative of a nodal-integral vector v,
i.e. M^{-1} v (lumped: v / m), and made relative:

    kkt_residual = |rigidity dE - lambda_A dA - lambda_B dB|_* / (|rigidity dE|_* + |lambda_A dA|_* + |lambda_B dB|_*)

with |v|_* = sqrt(v^T M^{-1} v) (the discrete L2 norm of the representative). Mesh-independent
and free of units; it cannot be met by a solver's say-so since it reuses nothing of the NLP graph.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.model import functionals as F


def dual_norm(disc, v: np.ndarray) -> float:
    """|v|_* of the module docstring (``Discretization.dual_norm``)."""
    return disc.dual_norm(v)


def kkt_residual(disc, phi, epsilon, C, rigidity, lam_A, lam_B, grads=None) -> float:
    """``grads``: (dE, dA, dB) of ``functionals.gradients`` at phi, when the caller has them."""
    dE, dA, dB = F.gradients(disc, phi, epsilon, C) if grads is None else grads
    terms = [rigidity * dE, lam_A * dA, lam_B * dB]
    scale = sum(dual_norm(disc, t) for t in terms)
    return dual_norm(disc, terms[0] - terms[1] - terms[2]) / max(scale, np.finfo(float).tiny)
