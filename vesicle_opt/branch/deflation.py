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
bordered Newton of ``branch.bordered`` (sparse LU) and the matrix-free bordered GMRES Newton of
``branch.krylov_bordered`` (Newton-Krylov) take it as their ``deflation`` hook). A root found this way is
only a root of F: the vesicle's is then certified by the fixed-p solve like every point of a branch
(IPOPT, or Newton-Krylov with the one certificate, ``verify.certify``, at its parameter), and refused
when it is an image of a known one under the grid's symmetries (``branch.symmetry``; a translated copy
of a known root is a root of F too).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from vesicle_opt.backends import choose_backend
from vesicle_opt.branch.corrector import least_squares_multipliers
from vesicle_opt.branch.nk_free import STOP, free_newton
from vesicle_opt.mesh import discretize
from vesicle_opt.model.problem import initial_guess

POWER = 2.0  # q: Farrell et al.'s choice; M ~ |phi - r|^-2 near a known root
SHIFT = 1.0  # sigma: M -> 1 + ... far from the known roots, so Newton far away is Newton
NEWTON_STEPS = 60
SAME = 1e-3  # a root within this fraction of |phi|_w of a known one (after alignment) is that one
HANDOFF = 1e-6  # Newton-Krylov: the deflated Newton's root handed to the certifying solve at this relative
# error (there quadratic: measured 3e-6 -> 7e-9 -> a step that grew the error, 48^2 spectral circle,
# where a near-null mode spoils the last GMRES step; the undeflated fixed-p solve finishes it)
RETRIES = 3  # roots refused from one start (deflated in turn) before the next start
NEAR_ROOT = 1e-2  # Newton-Krylov: a deflated Newton that did not converge hands its best iterate to the
# certifying solve where its relative error came below this. On the 48^2 spectral circle (nu = 0.95) it came
# to 2.2e-3 - 3.1e-3 and wandered off again (the rotation's near-null mode, which no phase condition holds),
# the outcome depending on the BLAS kernel's round-off (it converged under OpenBLAS Sandybridge only: measured)


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


def multiplier(phi: np.ndarray, known: list[np.ndarray], weights, align: Callable | None = None) -> float:
    """M(phi) = prod_i (1 / |phi - r_i|_w^q + sigma) (module docstring): the deflated residual's weight,
    the merit of the bordered Newton's line search (``branch.bordered``)."""
    m = 1.0
    for r in known:
        e = phi - (align(r, phi) if align is not None else r)
        n = math.sqrt(float(np.dot(weights, e * e)))
        m *= (n ** -POWER if n > 0 else math.inf) + SHIFT
    return m


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


def supported(scene, backend) -> str | None:
    """Why ``deflated_vesicle`` cannot run for this scene and backend, or None where it can: the
    deflated Newton needs the bordered fixed-p Newton of IPOPT with lumped mass (``branch.bordered``,
    sparse LU) or of Newton-Krylov with numpy arrays (``branch.krylov_bordered``, GMRES), the two
    correctors ``branch.vesicle`` builds."""
    chosen = choose_backend(scene, backend)
    if chosen == "newton-krylov" and scene.solver.array != "jax":
        return None
    if chosen == "ipopt" and not discretize(scene).consistent:
        return None
    if chosen == "ipopt":
        return "deflation needs lumped mass on IPOPT (this scene's mass is consistent)"
    return f"deflation needs IPOPT with lumped mass or Newton-Krylov with numpy arrays (here: {chosen}, array {scene.solver.array})"


def _fixed_newton(problem, p: float) -> Callable:
    """(start, lam, hook) -> (converged, phi, lam): the bordered Newton at fixed p, its steps rescaled
    by ``hook(phi, dphi)``: sparse LU on IPOPT (``branch.bordered``), matrix-free GMRES with the
    Schur-complement preconditioner on Newton-Krylov (``branch.nk_free``; Farrell et al.'s Sec. 3: the
    deflated step is the undeflated Krylov step rescaled, no other solve)."""
    if problem.nk is not None:
        def nk(start, lam, hook):
            tol = max(problem.nk.options.tol, HANDOFF) / STOP  # free_newton stops at STOP x tol
            nw = free_newton(problem.kkt(), start, lam, p, np.zeros_like(start), 1.0, 0.0, tol,
                             deflation=hook, max_newton=NEWTON_STEPS)
            if not nw.converged and nw.best and nw.best[0] <= NEAR_ROOT:  # in a root's basin: the certifying
                return True, nw.best[1], nw.best[2]  # solve finishes it (``deflated_vesicle``)
            return nw.converged, nw.phi, nw.lam
        return nk

    def ipopt(start, lam, hook, merit=None):
        nw = problem.bordered().fixed(start, p, lam, hook, merit)
        return nw.converged, nw.phi, nw.lam
    return ipopt


def deflated_vesicle(problem, p: float, phi0: np.ndarray, known: list[np.ndarray]):
    """Another certified point of the vesicle problem at p (``branch.vesicle``): the bordered Newton
    at fixed p deflated by ``known``, from the scene's own start field and from phi0 pushed both
    ways along its least eigenvector, each root handed to the fixed-p solve at p, which certifies it
    (IPOPT; on Newton-Krylov ``VesicleProblem.solve``: Newton from the root, 0 steps, and the one
    certificate with its second-order check). A root of another topology than phi0's (a vesicle
    diagram is one membrane: two far components are a KKT point too, measured at nu = 0.95, 48^2)
    or an image of a known one is deflated as well and the start retried (``RETRIES``). None when
    every start fails; ``supported`` says where it cannot run (``branch.run`` refuses ``--deflate``
    there before any work)."""
    if problem.nk is None and (problem.ipopt is None or problem.ipopt.disc.consistent):
        return None  # ``supported``: refused by ``branch.run`` before any work
    sc = problem.par.scene_at(problem.scene, p)
    w = problem.weights
    scale = math.sqrt(float(np.dot(w, phi0 * phi0)))
    ip = problem.ipopt
    starts = [ip.nlp.split(ip.nlp.x0)[0] if ip is not None else initial_guess(sc, problem.disc)]
    base = problem.solve(p, phi0, None)
    mode = None if base is None else problem.mode(base, 0)
    if mode is not None:
        starts += [phi0 + 0.2 * scale * mode, phi0 - 0.2 * scale * mode]
    shape = None if base is None else base.payload.extra.get("topology")
    newton_at_p = _fixed_newton(problem, p)
    deflated = list(known)
    for start in starts:
        for _ in range(RETRIES):
            lam = least_squares_multipliers(sc, problem.disc, start)
            hook = lambda phi, d: factor(phi, d, deflated, w, problem.align)  # noqa: E731
            if problem.nk is None:  # IPOPT's bordered Newton: steps line-searched on |M F| (``bordered``)
                ok, phi, lam = newton_at_p(start, lam, hook, lambda phi: multiplier(phi, deflated, w, problem.align))
            else:
                ok, phi, lam = newton_at_p(start, lam, hook)
            if not ok:
                break
            pt = problem.solve(p, phi, lam)
            if pt is None:
                break
            new = all(math.sqrt(float(np.dot(w, (problem.align(r, pt.phi) - pt.phi) ** 2))) > SAME * scale
                      for r in known)
            if new and (shape is None or pt.payload.extra.get("topology") == shape):
                return pt
            deflated.append(pt.phi)  # another topology (e.g. two far components) or a known image: deflated too
    return None
