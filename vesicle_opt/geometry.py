"""Physical quantities of a vesicle and the constraint targets (alpha, beta) they mean (Section 3.1).

Scaling conventions (the paper's, with phi = +1 inside and -1 outside):

* enclosed volume (3D) or area (2D)  V = (|Omega| + A) / 2, so alpha = 2 V - |Omega|  (4);
* membrane area (3D) or perimeter (2D) S = 3 sqrt(2) B / 4, so beta = 4 S / (3 sqrt 2)  (5), the
  sharp-interface value of B for the tanh profile: integral of (eps/2)|grad phi|^2 + (phi^2 - 1)^2/(4 eps)
  across the interface is 2 sqrt(2)/3 per unit area;
* reduced volume  3D: v = V / ((4 pi / 3) R0^3) with R0 = sqrt(S / (4 pi));  2D: nu = 4 pi V / S^2;
  both are 1 for the sphere / circle and < 1 for every other closed shape (isoperimetric inequality);
* reduced energy: E / (rigidity E_sphere), E_sphere the eps -> 0 limit of (3) for the sphere of area S
  (16 sqrt(2) pi / 3 for every radius) or the circle of perimeter S (2 sqrt(2) pi / (3 R), R = S / 2 pi),
  both at c0 = 0; so the sphere / circle has reduced energy 1 (``sphere_energy``).

Literature units (Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991); 3D only): the bending
energy F = (kappa/2) int (C1 + C2 - C0)^2 dA, f = F / (8 pi kappa), c0 = C0 R0, R0 = sqrt(S / 4 pi)
(``literature_units``). With phi = +1 inside, the tanh profile gives f_c = (1 - phi^2)(C - H/sqrt 2),
H = C1 + C2 > 0 on a sphere (the normal points from phi = +1 to phi = -1, outwards), so (3) tends to
(sqrt(2)/3) int (H - sqrt(2) C)^2 = (2 sqrt(2)/3) F / kappa with

    C0 = + sqrt(2) C = 2 c0 (the scene's ``model.c0``, the paper's c0 of the mean curvature (k1 + k2)/2),

the literature's sign (its sphere has f = (1 - c0/2)^2); the physical energy is rigidity E_h with
kappa = rigidity, hence f = E / (rigidity (2 sqrt(2)/3) 8 pi) = ``reduced_energy`` in 3D, for every c0.
A test pins the sign on the sphere (f at c0 = +0.5 is (1 - 1/4)^2, not (1 + 1/4)^2).

The tanh profile of a shape on a mesh has A_h, B_h that differ from these sharp values by O(eps^2)
curvature terms and the mesh error; a scene that gives ``constraints.reduced_volume`` and
``constraints.area`` is converted with the sharp formulas above (``targets``), so the diffuse vesicle
reaches the stated V and S through its A and B, not through a tanh profile's.

numpy-free, imports nothing of the package but errors: every layer may use it.
"""

from __future__ import annotations

import math

SQRT2 = math.sqrt(2.0)


def enclosed_volume(A: float, domain_volume: float) -> float:
    """Volume (3D) or area (2D) of {phi > 0} implied by A (Section 3.1): (|Omega| + A)/2."""
    return (domain_volume + A) / 2


def surface_area(B: float) -> float:
    """Area (3D) or length (2D) implied by B (Section 3.1): 3 sqrt(2) B / 4."""
    return 3 * SQRT2 * B / 4


def alpha_of_volume(volume: float, domain_volume: float) -> float:
    """alpha = 2 V - |Omega|, the inverse of ``enclosed_volume``."""
    return 2 * volume - domain_volume


def beta_of_area(area: float) -> float:
    """beta = 4 S / (3 sqrt 2), the inverse of ``surface_area``."""
    return 4 * area / (3 * SQRT2)


def reduced_volume(volume: float, area: float, dim: int) -> float:
    """v = V / ((4 pi/3) R0^3), R0 = sqrt(S / 4 pi) (3D); nu = 4 pi V / S^2 (2D)."""
    if dim == 3:
        return volume / (4 * math.pi / 3 * (area / (4 * math.pi)) ** 1.5)
    return 4 * math.pi * volume / area**2


def volume_of_reduced(reduced: float, area: float, dim: int) -> float:
    """The volume with reduced volume ``reduced`` at area (perimeter) ``area``: the inverse of
    ``reduced_volume`` in V."""
    if dim == 3:
        return reduced * 4 * math.pi / 3 * (area / (4 * math.pi)) ** 1.5
    return reduced * area**2 / (4 * math.pi)


def sphere_energy(area: float, dim: int) -> float:
    """E of (3) in the sharp-interface limit for the sphere of area S (3D) or circle of perimeter S
    (2D), c0 = 0, rigidity 1.

    Derivation: f_c = (1 - phi^2)(C - kappa/sqrt(2)) for phi = tanh(-d/(sqrt 2 eps)), and the integral
    of (1 - phi^2)^2 across the interface is 4 sqrt(2) eps / 3, so E -> (sqrt(2)/3) integral_Gamma
    (kappa - sqrt(2) C)^2 with kappa the sum of principal curvatures: 2D circle of radius R:
    2 sqrt(2) pi / (3 R); 3D sphere: 16 sqrt(2) pi / 3 for every R.
    """
    if dim == 3:
        return 16 * SQRT2 * math.pi / 3
    R = area / (2 * math.pi)
    return 2 * SQRT2 * math.pi / (3 * R)


def reduced_energy(energy: float, area: float, dim: int, rigidity: float = 1.0) -> float:
    """energy / (rigidity * sphere_energy(area, dim)): 1 for the sphere / circle of that area."""
    return energy / (rigidity * sphere_energy(area, dim))


def literature_units(energy: float, area: float, c0: float, rigidity: float = 1.0) -> dict[str, float]:
    """f = F / (8 pi kappa) and c0_reduced = C0 R0 of a 3D vesicle (module docstring: C0 = 2 c0,
    f = the reduced energy), the summary's ``f`` and ``c0_reduced``."""
    R0 = math.sqrt(area / (4 * math.pi))
    return {"f": reduced_energy(energy, area, 3, rigidity), "c0_reduced": 2.0 * c0 * R0}


def targets(reduced: float, area: float, dim: int, domain_volume: float) -> tuple[float, float]:
    """(alpha, beta) of the vesicle with reduced volume ``reduced`` and area (perimeter) ``area``."""
    return (alpha_of_volume(volume_of_reduced(reduced, area, dim), domain_volume), beta_of_area(area))


def physical(A: float, B: float, dim: int, domain_volume: float) -> dict[str, float]:
    """volume, area and reduced_volume implied by the values A, B of a field (the summary's keys)."""
    V, S = enclosed_volume(A, domain_volume), surface_area(B)
    nu = reduced_volume(V, S, dim) if S > 0 else math.nan
    return {"volume": V, "area": S, "reduced_volume": nu}
