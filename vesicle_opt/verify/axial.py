"""The axial slide of a meridian mesh (``mesh.kind = "axisymmetric"``) in the second-order checks.

Between the natural end walls a free vesicle's slide along the axis, d_z phi, is only nearly null
(+-1e-5 mu_ref): not an exact symmetry, so it is never removed from T as one (``verdict``'s module
docstring). Both checks (assembled ``verify.second_order``, matrix-free ``verify.lobpcg``) measure
how much of their least mode it is (``overlap``) and ``verdict.axial_note`` names it in the reason.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.mesh.axisymmetric import axial_translation
from vesicle_opt.model import functionals as F


def onto_volume_area(disc, phi, eps: float, C: float):
    """v -> the M-orthogonal projection of v onto {dA.v = dB.v = 0} (eqs. (7)-(8) linearised)."""
    G = np.column_stack(F.gradients(disc, phi, eps, C)[1:])
    MG = np.column_stack([disc.solve_mass(g) for g in G.T])
    S = G.T @ MG
    return lambda v: v - MG @ np.linalg.solve(S, G.T @ v)


def overlap(disc, phi, mode, eps: float, C: float, Mphi=None) -> float:
    """|<P d_z phi, mode>_M| / (||P d_z phi||_M ||mode||_M), P the projection onto {dA.v = dB.v = 0}:
    1 where the least mode is the slide itself; nan off meridian meshes."""
    if not getattr(disc, "axisymmetric", False):
        return float("nan")
    M = Mphi if Mphi is not None else disc.M if disc.consistent else None
    mass = (lambda v: M @ v) if M is not None else (lambda v: disc.weights * v)
    u = onto_volume_area(disc, np.asarray(phi, float), eps, C)(axial_translation(disc, phi))
    v = np.asarray(mode, float)
    return float(abs(u @ mass(v)) / np.sqrt(max((u @ mass(u)) * (v @ mass(v)), 1e-300)))
