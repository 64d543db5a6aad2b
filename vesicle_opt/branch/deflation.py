"""Deflation: other KKT points at the same parameter, given the known ones (Farrell, Birkisson &
Funke, SIAM J. Sci. Comput. 37 (2015) A2026).

With known roots r_1, ..., r_k of the KKT residual F (stationarity of (6) with the constraints (7),
(8), the multipliers unknowns beside phi) the deflated residual

    G(u) = M(u) F(u),   M(u) = prod_i (1 / |phi - r_i|_w^q + sigma)

(q = ``POWER``, sigma = ``SHIFT``; the norm on the field only, the multipliers following it) has the
roots of F except the r_i: near r_i, M blows up and G does not vanish. Newton on G needs no new
linear solve: with d = -J^{-1} F the undeflated step, Sherman-Morrison gives the deflated step

    d_G = d / (1 - <grad log M, d>),   grad log M = sum_i -q W (phi - r_i) / (|phi - r_i|^{q+2} (|phi - r_i|^{-q} + sigma))

(Farrell et al., Sec. 3), so any Newton iteration deflates by rescaling its steps (``factor``; the
bordered Newton of ``branch.bordered`` takes it as its ``deflation`` hook). A root found this way is
only a root of F: the vesicle's is then certified by the fixed-p IPOPT solve like every point of a
branch, and refused when it is an image of a known one under the grid's symmetries
(``branch.symmetry``; a translated copy of a known root is a root of F too).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from vesicle_opt.branch.corrector import least_squares_multipliers

POWER = 2.0  # q: Farrell et al.'s choice; M ~ |phi - r|^-2 near a known root
SHIFT = 1.0  # sigma: M -> 1 + ... far from the known roots, so Newton far away is Newton
NEWTON_STEPS = 60
SAME = 1e-3  # a root within this fraction of |phi|_w of a known one (after alignment) is that one
RETRIES = 3  # roots refused from one start (deflated in turn) before the next start


def factor(phi: np.ndarray, dphi: np.ndarray, known: list[np.ndarray], weights, align: Callable | None = None) -> float:
    """The rescaling 1 / (1 - <grad log M, d>) of a Newton step d (module docstring)."""
    s = 0.0
    for r in known:
        if align is not None:
            r = align(r, phi)
        e = phi - r
        n = math.sqrt(float(np.dot(weights, e * e)))
        if n == 0:
            return 1.0
        s += -POWER * float(np.dot(weights, e * dphi)) / (n ** (POWER + 2) * (n ** -POWER + SHIFT))
    den = 1.0 - s
    return 1.0 / den if den != 0 else 1.0


def newton(residual: Callable, jacobian: Callable, u0: np.ndarray, known: list[np.ndarray], weights,
           n_phi: int | None = None, tol: float = 1e-12, max_steps: int = NEWTON_STEPS) -> tuple[np.ndarray, bool, int]:
    """Deflated Newton on a dense residual F(u) (u[:n_phi] the field; all of u by default): (u,
    converged, steps). Converged: |F| <= tol (F's own residual, not G's)."""
    u = np.asarray(u0, float).copy()
    n = len(u) if n_phi is None else n_phi
    for k in range(1, max_steps + 1):
        F = residual(u)
        if np.linalg.norm(F) <= tol:
            return u, True, k - 1
        d = -np.linalg.solve(jacobian(u), F)
        u = u + factor(u[:n], d[:n], known, weights) * d
        if not np.all(np.isfinite(u)):
            return u, False, k
    return u, bool(np.linalg.norm(residual(u)) <= tol), max_steps


def deflated_vesicle(problem, p: float, phi0: np.ndarray, known: list[np.ndarray]):
    """Another certified point of the vesicle problem at p (``branch.vesicle``): the bordered Newton
    at fixed p deflated by ``known``, from the scene's own start field and from phi0 pushed both
    ways along its least eigenvector, each root handed to IPOPT, which certifies it. A root of
    another topology than phi0's (a vesicle diagram is one membrane: two far components are a KKT
    point too, measured at nu = 0.95, 48^2) or an image of a known one is deflated as well and the
    start retried (``RETRIES``). None when every start fails (IPOPT with lumped mass only: elsewhere
    None)."""
    ip = problem.ipopt
    if ip is None or ip.disc.consistent:
        return None
    sc = problem.par.scene_at(problem.scene, p)
    w = problem.weights
    scale = math.sqrt(float(np.dot(w, phi0 * phi0)))
    starts = [ip.nlp.split(ip.nlp.x0)[0]]
    base = problem.solve(p, phi0, None)
    mode = None if base is None else problem.mode(base, 0)
    if mode is not None:
        starts += [phi0 + 0.2 * scale * mode, phi0 - 0.2 * scale * mode]
    shape = None if base is None else base.payload.extra.get("topology")
    deflated = list(known)
    for start in starts:
        for _ in range(RETRIES):
            lam = least_squares_multipliers(sc, ip.disc, start)
            nw = problem.bordered().fixed(start, p, lam, lambda phi, d: factor(phi, d, deflated, w, problem.align))
            if not nw.converged:
                break
            pt = problem.solve(p, nw.phi, nw.lam)
            if pt is None:
                break
            new = all(math.sqrt(float(np.dot(w, (problem.align(r, pt.phi) - pt.phi) ** 2))) > SAME * scale
                      for r in known)
            if new and (shape is None or pt.payload.extra.get("topology") == shape):
                return pt
            deflated.append(pt.phi)  # another topology (e.g. two far components) or a known image: deflated too
    return None
