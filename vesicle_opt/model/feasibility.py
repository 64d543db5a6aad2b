"""Feasibility of the constraint data (alpha, beta) before any solve.

Condition (9) of the paper, as printed, has its inequality the wrong way round against the
isoperimetric inequality (the paper's own Section 5 data, volume 22.69 and area 48.19, violate it as
printed); the sharp-interface condition is area >= the area of the ball of the given volume. At finite
eps that sharp bound is off by O(eps), so we use the phase-field bound itself:

    beta_min(alpha) = min { B(phi) : A(phi) = alpha }.

Symmetric decreasing rearrangement of phi + 1 keeps A and the well term and does not increase the
gradient term (Polya-Szego), so on R^d the minimiser is radially symmetric and beta_min is a 1D
minimisation over radial profiles, solved here by IPOPT on a fine 1D grid. In a box the candidates
are the radial profiles in k = d, d-1, ..., 1 dimensions (ball, cylinder, slab; on a periodic box
across the box, with natural boundaries as a corner/edge/wall piece, whose interface meets the wall
at a right angle), and beta_min is the least of them. This is the classical isoperimetric profile
of the box lifted to the phase field; it is exact in R^d and the standard conjecture in boxes.

A small mass in a large box may also spread into a shallow bump or the constant state (k = 0),
which are feasible phase fields of low B; they are candidates too. We refuse beta < beta_min and
warn within ``WARN`` of it. We also require |alpha| < |Omega| and beta > 0.
"""

from __future__ import annotations

import math
import warnings
from functools import lru_cache

import numpy as np

from vesicle_opt.errors import InfeasibleError

WARN = 0.05  # warn when beta is within 5% of the bound: the minimiser is then nearly a sphere
ACCEPTED = ("Solve_Succeeded", "Solved_To_Acceptable_Level", "Search_Direction_Becomes_Too_Small")
N_RADIAL = 400  # 1D grid points; the bound converges at O(dr^2), measured 1e-5 relative at 400


def _sphere_measure(k: int) -> float:
    """Surface measure of the unit sphere in R^k (k = 1: two points)."""
    return 2 * math.pi ** (k / 2) / math.gamma(k / 2)


def _radial_grid(k: int, mass: float, epsilon: float, r_box: float):
    """The 1D grid of the k-dimensional radial problem: (r, dr, node weights wn, midpoint weights
    wm, the sharp radius R). r_out = max(R + 12 eps, r_box): a small mass may spread into a shallow
    bump of lower B than a saturated ball (the phase field is not a sharp interface), so the profile
    gets the box's room."""
    S = _sphere_measure(k)
    R = (mass / 2 / (S / k)) ** (1 / k)  # sharp radius: |ball_R| = mass / 2
    r_out = max(R + 12 * epsilon, r_box)
    n = max(N_RADIAL, int(20 * r_out / epsilon))
    r = np.linspace(0.0, r_out, n)
    dr = r[1] - r[0]
    rm = 0.5 * (r[1:] + r[:-1])
    wn = np.full(n, dr)
    wn[[0, -1]] = dr / 2
    wn = S * wn * r ** (k - 1)  # trapezoid weights of the radial measure
    wm = S * dr * rm ** (k - 1)
    return r, dr, wn, wm, R


def _tanh_profile(r: np.ndarray, radius: float, epsilon: float) -> np.ndarray:
    """The optimal 1D profile tanh((radius - r) / (sqrt 2 eps)), with phi(r_out) = -1."""
    phi = np.tanh((radius - r) / (math.sqrt(2) * epsilon))
    phi[-1] = -1.0
    return phi


def radial_competitor(k: int, mass: float, epsilon: float, r_box: float) -> float:
    """The radial B of one feasible profile of ``radial_minimum``'s problem, on its grid: the tanh
    profile whose radius is set (bisection, to round-off) so that integral (phi + 1) = mass. An
    upper bound of that problem's minimum, in closed form up to the radius (no NLP); inf when the
    mass does not fit the grid."""
    if mass <= 0:
        return 0.0
    r, dr, wn, wm, R = _radial_grid(k, mass, epsilon, r_box)

    def excess(radius):
        return float(wn @ (_tanh_profile(r, radius, epsilon) + 1)) - mass
    lo, hi = -12 * epsilon, r[-1] + 12 * epsilon  # the mass grows with the radius from ~0 to ~the grid's
    if excess(lo) > 0 or excess(hi) < 0:
        return math.inf
    for _ in range(200):  # bisection to adjacent doubles (each step halves the bracket)
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        lo, hi = (mid, hi) if excess(mid) < 0 else (lo, mid)
    phi = _tanh_profile(r, hi, epsilon)
    grad = np.diff(phi) / dr
    return float(epsilon / 2 * (wm @ grad**2) + wn @ (phi**2 - 1) ** 2 / (4 * epsilon))


@lru_cache(maxsize=256)
def radial_minimum(k: int, mass: float, epsilon: float, r_box: float) -> float:
    """min of the k-dimensional radial B subject to integral (phi + 1) = mass, phi(r_out) = -1
    (grid: ``_radial_grid``)."""
    if mass <= 0:
        return 0.0
    r, dr, wn, wm, R = _radial_grid(k, mass, epsilon, r_box)
    n = r.size
    import casadi as ca  # third-party, lazy (0.25 s at import): only this bound's small NLP needs it
    phi = ca.SX.sym("phi", n)
    grad = (phi[1:] - phi[:-1]) / dr
    B = epsilon / 2 * ca.dot(ca.DM(wm), grad**2) + ca.dot(ca.DM(wn), (phi**2 - 1) ** 2) / (4 * epsilon)
    g = ca.vertcat(ca.dot(ca.DM(wn), phi + 1) - mass, phi[-1] + 1)
    solver = ca.nlpsol("radial", "ipopt", {"x": phi, "f": B, "g": g},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.tol": 1e-12,
                        "ipopt.sb": "yes"})
    x0 = np.tanh((R - r) / (math.sqrt(2) * epsilon))
    sol = solver(x0=x0, lbg=0, ubg=0)
    status = solver.stats()["return_status"]
    violation = float(np.max(np.abs(np.asarray(sol["g"]))))
    # IPOPT may stop on steps below machine precision at the minimiser ("search direction too
    # small"); the value is then as good as converged if the mass constraint holds
    if status in ACCEPTED and violation <= 1e-8 * max(mass, 1.0):
        return float(sol["f"])
    return math.nan  # no bound: check_feasible then warns instead of refusing


def _least_radial_b(alpha: float, epsilon: float, box, boundary: str, radial) -> float:
    """The least B over the constant state and the ball/cylinder/slab candidates at A = alpha, each
    k-dimensional radial value from ``radial(k, mass, epsilon, r_box)`` (NaN: no bound)."""
    lengths = sorted(b - a for a, b in box)
    d = len(box)
    volume = math.prod(lengths)
    mass = alpha + volume  # integral of (phi + 1) = 2 * enclosed volume
    best = volume / (4 * epsilon) * ((alpha / volume) ** 2 - 1) ** 2  # k = 0: phi constant
    for k in range(d, 0, -1):
        cross = math.prod(lengths[: d - k])  # the d - k shortest box lengths
        # natural boundaries: a piece of the k-ball in a corner of 2^k orthants (interface meets
        # the walls at right angles); periodic: the whole k-ball, repeated across the box
        pieces = 2**k if boundary == "natural" else 1
        r_box = lengths[d - k] * (1.0 if boundary == "natural" else 0.5)
        value = cross * radial(k, pieces * mass / cross, epsilon, r_box) / pieces
        if math.isnan(value):
            return math.nan
        best = min(best, value)
    return best


def beta_min(alpha: float, epsilon: float, box, boundary: str) -> float:
    """The least B over the ball/cylinder/slab candidates at A = alpha (see module docstring)."""
    return _least_radial_b(alpha, epsilon, box, boundary, radial_minimum)


def beta_upper(alpha: float, epsilon: float, box, boundary: str) -> float:
    """An upper bound of ``beta_min`` in closed form (no NLP): the least B of the same candidates'
    tanh profiles (``radial_competitor``), each feasible for its radial problem."""
    return _least_radial_b(alpha, epsilon, box, boundary, radial_competitor)


def _bounding_box_data(alpha: float, volume: float, box):
    """(alpha, |box|, box) of the same enclosed volume in the square box [-R, R]^2 x [z0, z1] around the
    cylinder of an axisymmetric scene's meridian box [[0, R], [z0, z1]] (``mesh.axisymmetric``): the
    box's bound allows every field of the cylinder (extended by phi = -1) and the corner pieces the
    cylinder cannot hold, so it is at most the cylinder's; a necessary condition, never a false refusal."""
    R, (z0, z1) = box[0][1], box[1]
    box3 = ((-R, R), (-R, R), (z0, z1))
    volume3 = 4 * R * R * (z1 - z0)
    return alpha + volume - volume3, volume3, box3


def check_feasible(alpha: float, beta: float, scene, disc=None) -> float:
    """Refuse infeasible (alpha, beta) with a one-line InfeasibleError; warn near the bound. Returns
    the bound beta was checked against: ``beta_upper`` when beta is at least (1 + WARN) times it
    (then beta >= (1 + WARN) beta_min, so neither refusal nor warning can follow, and the three
    small NLPs of ``beta_min`` with CasADi's import, 0.13-0.29 s of a CLI run, are skipped),
    else ``beta_min`` (NaN: not computable, warned)."""
    volume = scene.domain.volume if disc is None else disc.volume
    if not -volume < alpha < volume:
        raise InfeasibleError("constraints.alpha",
                              f"alpha = {alpha:.6g} must lie in (-|Omega|, |Omega|) = ({-volume:.6g}, {volume:.6g})")
    if not beta > 0:
        raise InfeasibleError("constraints.beta", f"beta = {beta:.6g} must be > 0")
    box = scene.domain.box if disc is None else disc.box  # a mesh file brings its own bounding box
    if scene.domain.axisymmetric:  # the meridian half-plane: bound the cylinder by its bounding box
        alpha, volume, box = _bounding_box_data(alpha, volume, box)
    # mirror grids (mesh.cosine): alpha, beta are the full symmetric field's, 2^d times the box's own,
    # whose natural-boundary problem the box's bound covers
    cells = max(1, round(volume / math.prod(b - a for a, b in box)))
    upper = cells * beta_upper(alpha / cells, scene.model.epsilon, box, scene.domain.boundary)
    if beta >= upper * (1 + WARN):  # evidently feasible (docstring)
        return upper
    bound = cells * beta_min(alpha / cells, scene.model.epsilon, box, scene.domain.boundary)
    if math.isnan(bound):
        warnings.warn("the phase-field feasibility bound could not be computed for these data; "
                      "(alpha, beta) were not checked against it", stacklevel=2)
        return bound
    if beta < bound:
        raise InfeasibleError("constraints.beta",
                              f"infeasible: beta = {beta:.6g} is below the least area functional "
                              f"beta_min(alpha = {alpha:.6g}, eps = {scene.model.epsilon:g}) = {bound:.6g}")
    if beta < bound * (1 + WARN):
        warnings.warn(f"beta = {beta:.6g} is within {100 * (beta / bound - 1):.2g}% of beta_min = "
                      f"{bound:.6g}: the minimiser is nearly a sphere and the multipliers are ill-conditioned",
                      stacklevel=2)
    return bound
