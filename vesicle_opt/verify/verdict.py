"""The one meaning of the second-order check and its one verdict rule (both backends call these).

The quantity: the smallest eigenvalue mu_min of the Hessian of the Lagrangian H on the tangent space
T = {v : dA.v = 0, dB.v = 0} in the L2 (mass) metric, H v = mu M v on T, with the excluded symmetry
modes (``SecondOrder.excluded``: none, translations, or translations and rotations) M-orthogonally
removed from T as well, reported as mu_min / mu_ref with

    mu_ref = rigidity * E_ref / (eps |Gamma|)   (``mu_ref``),

the Hessian's scale on an interface mode (E_ref: the sharp circle/sphere energy of area beta,
|Gamma| = 3 sqrt2 beta / 4). ``verify.second_order`` (assembled, shift-invert Lanczos) and
``verify.lobpcg`` (matrix-free LOBPCG) compute this same number.

The rule (``classify``), with mu = mu_min / mu_ref the least Rayleigh quotient found on T (a Ritz
value) and err a bound on its distance to an eigenvalue, in the same unit (the M^{-1}-norm of the
pair's residual on T for an M-normalised vector; Bauer-Fike for symmetric pencils):

    "saddle"       mu < -TOL_REL, or an excluded mode's Rayleigh quotient on T is < -TOL_REL: a
                   tangent direction of negative curvature, so the least eigenvalue is below
                   -TOL_REL (Courant-Fischer; no error bound needed);
    "minimum"      mu - err >= -TOL_REL: the least eigenvalue lies in [mu - err, mu] when mu
                   approximates it (Ritz values lie above the eigenvalues they approximate);
    "not checked"  otherwise (-TOL_REL <= mu < err - TOL_REL: undecided), or no check ran.

"saddle" is backed by an explicit direction, "minimum" is a numerical verdict: it trusts the
eigensolver to have found the least eigenvalue (a few eigenvalues, shift-invert or LOBPCG).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vesicle_opt.model import functionals as F

TOL_REL = 1e-6  # least eigenvalues measured: saddles -3.2 (FD 64^2), -9.9 (P1 32^2), -0.02 (FD 48^2,
# test_penalty); minima +0.17 (P1 41^2), +0.14 (torus 32^3) and the soft rotation mode where kept,
# +4.1e-3 (FD 64^2), +3.4e-4 (torus 32^3): negative means below -1e-6, far from all of them and far
# above the assembled check's error bounds (~1e-11)
NONE, TRANSLATIONS, TRANSLATIONS_ROTATIONS = "none", "translations", "translations, rotations"
# mirror grids (``mesh.cosine``, spectral with natural boundaries): the check sees only perturbations
# symmetric in every coordinate plane, so its "minimum" is a minimum within that class, no more
MIRROR_CLASS = "all but mirror-symmetric perturbations (mirror grid: minimum within the symmetric class only)"
# the meridian half-plane (``mesh.axisymmetric``): the check sees only axisymmetric perturbations (the
# translation along the axis among them, reported as an eigenvalue as on P1 meshes, not removed)
AXISYMMETRIC_CLASS = ("all but axisymmetric perturbations (meridian mesh: minimum within the axisymmetric "
                      "class only)")


def excluded_label(disc, modes) -> str:
    """``SecondOrder.excluded`` of a check on ``disc`` that removed ``modes`` (the translations, or
    none): the meridian mesh's class, else ``TRANSLATIONS`` or ``NONE``."""
    if getattr(disc, "axisymmetric", False):
        return AXISYMMETRIC_CLASS
    return TRANSLATIONS if modes else NONE


@dataclass(frozen=True)
class SecondOrder:
    """What either check found (eigenvalues in mu_ref units unless said otherwise)."""

    verdict: str  # "minimum" | "saddle" | "not checked" (``classify``)
    min_eigenvalue: float  # smallest mu on T minus the excluded modes, physical units
    relative_min_eigenvalue: float  # mu_min / mu_ref: extra["second_order_min_eigenvalue"]
    eigenvalues: tuple[float, ...]  # the smallest few, ascending
    excluded_rayleigh: tuple[float, ...]  # Rayleigh quotients of the excluded modes on T
    residual: float  # the largest error bound of the eigenvalues (``errors``)
    reason: str = ""
    lowest_mode: np.ndarray | None = field(default=None, repr=False)  # M-normalised phi direction
    excluded: str = NONE  # extra["second_order_excluded"]: which symmetry modes were removed from T
    errors: tuple[float, ...] = ()  # error bound of each eigenvalue (residual on T, M^{-1} norm)
    iterations: int | None = None  # the eigensolver's iterations (LOBPCG)


def mu_ref(rigidity: float, epsilon: float, beta: float, dim: int) -> float:
    """rigidity * E_ref / (eps |Gamma|): the unit of every reported eigenvalue."""
    return rigidity * F.sharp_energy_sphere(beta, dim) / (epsilon * F.surface_area(beta))


def excludes_rotations(scene) -> bool:
    """Whether the check of ``scene`` removes the rotations with the translations: on grids (FD,
    Fourier, cosine) they are the continuum's symmetries; a P1 scene keeps the P1 report,
    translations only, also where its tensor box runs on FFT (``second_order_excluded`` says which)."""
    return scene.mesh.kind != "fem-p1"


def classify(mu: float, err: float, excluded_rayleigh=()) -> tuple[str, str]:
    """(verdict, reason) for mu = mu_min / mu_ref with error bound err (module docstring)."""
    if not (math.isfinite(mu) and math.isfinite(err)):
        return "not checked", "no finite eigenvalue"
    if mu < -TOL_REL or any(q < -TOL_REL for q in excluded_rayleigh):
        return "saddle", ""
    if mu - err >= -TOL_REL:
        return "minimum", ""
    return "not checked", f"undecided: mu_min/mu_ref = {mu:.3g} with error bound {err:.2g}"
