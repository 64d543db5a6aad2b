"""The one meaning of the second-order check and its one verdict rule (both backends call these).

The quantity: the smallest eigenvalue mu_min of the Hessian of the Lagrangian H on the tangent space
T = {v : dA.v = 0, dB.v = 0} in the L2 (mass) metric, H v = mu M v on T, with the excluded symmetry
modes (``SecondOrder.excluded``) M-orthogonally removed from T as well, reported as mu_min / mu_ref with

    mu_ref = rigidity * E_ref / (eps |Gamma|)   (``mu_ref``),

the Hessian's scale on an interface mode (E_ref: the sharp circle/sphere energy of area beta,
|Gamma| = 3 sqrt2 beta / 4). ``verify.second_order`` (assembled, shift-invert Lanczos) and
``verify.lobpcg`` (matrix-free LOBPCG) compute this same number.

Excluded modes (``SecondOrder.excluded``): only the discrete problem's null modes. On periodic grids the
translations d_i phi ("translations"): the discrete energy is exactly invariant under shifts by
whole cells, and d_i phi is the tangent of the trigonometric interpolant's shifts through them
(their Rayleigh quotients on T are reported and still enter the rule). Rotations are never excluded:
no grid in a periodic box is invariant under them, so the rotation generator is a soft mode at
best, and projecting it out can remove a real descent direction (the FD 48^2 ellipse: -0.0195 mu_ref
with it kept, +1.09 without). Their quotients are reported beside the verdict (``rotation_rayleigh``).
Mirror grids keep their class (``MIRROR_CLASS``).

The rule (``classify``), with mu = mu_min / mu_ref the least Rayleigh quotient found on T (a Ritz
value, computed from exact products) and err a bound on its distance to an eigenvalue, in the same
unit (``block_eig.error_bounds``: the M^{-1}-norm of the pair's residual on T, Kato-Temple's
r^2 / gap where the next Ritz value is separated), so that the least eigenvalue lies in
[mu - err, mu] when the solver found the least pair (Ritz values lie above the eigenvalues):

    "saddle"       mu < -TOL_REL, or an excluded mode's Rayleigh quotient on T is < -TOL_REL: an
                   explicit tangent direction of negative curvature (Courant-Fischer), the least
                   eigenvalue in [mu - err, mu] (the reason says so);
    "minimum"      mu - err >= TOL_REL: the least eigenvalue is positive beyond its error bound;
    "marginal"     -TOL_REL <= mu and mu - err < TOL_REL with err <= MARGINAL_ERR: the least
                   eigenvalue is zero within its error bound (a flat direction: a nearly free
                   rotation in a periodic box, a bifurcation): neither a strict minimum nor a saddle
                   that the check can show;
    "not checked"  otherwise (undecided: err too large to tell), the eigensolver's own check failed
                   (``failure``), or no check ran; the reason says which.

"saddle" is backed by an explicit direction, "minimum" and "marginal" are numerical verdicts: they
trust the eigensolver to have found the least eigenvalue (a few eigenvalues, shift-invert or LOBPCG).
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
MARGINAL_ERR = 1e-3  # "marginal" needs an error bound below this (mu_ref units): a thousandth of the
# Hessian's scale on an interface mode (shape modes measured >= 0.14); a wider bound says nothing
# about a flat direction's sign: undecided
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

    verdict: str  # "minimum" | "saddle" | "marginal" | "not checked" (``classify``)
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
    rotation_rayleigh: tuple[float, ...] = ()  # the rotation generators' Rayleigh quotients on T (mu_ref
    # units; a report only: rotations stay in the check), extra["rotation_rayleigh"] holds the least
    axial_rayleigh: float = float("nan")  # meridian mesh: the axial slide d_z phi's Rayleigh quotient on
    # {dA.v = dB.v = 0} (mu_ref units; extra["axial_rayleigh"]), pinned or not (``axial_note``)


def mu_ref(rigidity: float, epsilon: float, beta: float, dim: int) -> float:
    """rigidity * E_ref / (eps |Gamma|): the unit of every reported eigenvalue."""
    return rigidity * F.sharp_energy_sphere(beta, dim) / (epsilon * F.surface_area(beta))


def excludes_rotations(scene) -> bool:
    """Whether the check of ``scene`` removes the rotations with the translations: nowhere (module
    docstring, excluded modes). Kept as the one place that says so; the callers pass it on."""
    return False


PINNED = ("axial position pinned (the solve's row c . phi = d holds the slide along the axis: T is the "
          "tangent space of all its constraints, the slide excluded as constrained, not as a symmetry)")
SLIDE_OVERLAP = 0.95  # |<slide, least mode>_M| (normalised) above which the least mode is called the
# axial slide; measured 1.000 (prolate, eps 0.1, h = eps/2), 0.989 (h = eps), and 0.933 where a shape
# mode is nearly as soft (c0 = 2.4, v = 0.72, next eigenvalue 9e-5 mu_ref: the pear's bifurcation), a
# mix the reason then does not call the slide


def axial_note(verdict: str, reason: str, pinned: bool, axial: float, overlap: float, mus) -> str:
    """The verdict's reason on a meridian mesh: "axial position pinned" where the solve held the
    slide (``PINNED``); unpinned, where the least mode is the axial slide (M-overlap above
    ``SLIDE_OVERLAP``), that it is the slide between the natural end walls (a near-null mode, +-1e-5
    mu_ref: not an exact symmetry, so it stays in the check), with the next eigenvalue, the least
    shape mode's."""
    if verdict == "not checked":
        return reason
    note = ""
    if pinned:
        note = PINNED
    elif math.isfinite(overlap) and overlap > SLIDE_OVERLAP:
        nxt = f"; the next eigenvalue {mus[1]:.3g} mu_ref" if len(mus) > 1 else ""
        quotient = f", axial_rayleigh {axial:.3g} mu_ref" if math.isfinite(axial) else ""
        note = (f"the least mode is the axial slide (overlap {overlap:.3f}{quotient}): the vesicle sliding "
                f"between the end walls, not a shape instability{nxt}")
    return "; ".join(x for x in (reason, note) if x)


def classify(mu: float, err: float, excluded_rayleigh=(), failure: str = "") -> tuple[str, str]:
    """(verdict, reason) for mu = mu_min / mu_ref with error bound err (module docstring);
    ``failure``: why the eigensolver's result cannot be trusted ('' where it can)."""
    if failure:
        return "not checked", f"undecided: {failure}"
    if not (math.isfinite(mu) and math.isfinite(err)):
        return "not checked", "undecided: no finite eigenvalue or error bound"
    bound = f"mu_min/mu_ref = {mu:.3g} with error bound {err:.2g}"
    if mu < -TOL_REL:
        return "saddle", f"least eigenvalue in [{mu - err:.3g}, {mu:.3g}] mu_ref"
    bad = [q for q in excluded_rayleigh if q < -TOL_REL]
    if bad:
        return "saddle", f"an excluded mode's Rayleigh quotient {min(bad):.3g} mu_ref < 0"
    if mu - err >= TOL_REL:
        return "minimum", ""
    if err <= MARGINAL_ERR:
        return "marginal", f"least eigenvalue zero within its error bound: {bound}"
    return "not checked", f"undecided: {bound}"
