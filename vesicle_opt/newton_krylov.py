"""The matrix-free Newton-Krylov backend (``solver.backend = 'newton-krylov'``).

Methods (``solver.method``):

* ``exact``: an augmented Lagrangian around ``newton.newton_minimize``. After each inner solve the
  multipliers take a Newton step on the dual function, lam <- lam - W^{-1} c with
  W = G^T H_rho^{-1} G (G = [dA, dB], two extra CG solves), which is the Newton-KKT step in the
  multipliers (and lam - rho c, the classical update, when rho is large); rho grows 10x when |c|
  falls by less than 4x. Stops when the constraints hold to 0.1 tol (|A-alpha| <= tol |Omega|,
  |B-beta| <= tol beta is the IPOPT backend's test) and the relative dual KKT residual <= tol.
* ``penalty``: the same inner solver with lam = 0, rho = (M, M) fixed: the paper's E_{M,h} (11) with
  rigidity on E only. The multipliers are the penalty's, lam = -M c (exact at its stationary point).
* ``continuation``: penalty solves at M/100, M/10, M, each warm-started from the last (starting
  lower lost the ellipse-2d shape at M/1000 = 1: E 6.2 against 2.75).

Translations d_i phi are projected out of every step on Fourier grids (exact null modes of the
spectral problem up to aliasing). On coarse grids (h ~ eps) several KKT points are close: from the
symmetric torus start both backends end at the axisymmetric one; so does the P1 tensor mesh (whose
lumped operator equals FD) with a preconditioner that keeps the mesh symmetries, while three plain
pyamg V-cycles, which break them at ~3e-5, led to a lower, slightly non-axisymmetric one (330.02 vs
330.53 at 16^3, 406.41 vs 407.21 at 24^3; see ``precond``). Neither backend certifies a minimiser;
``second_order_lobpcg.reduced_hessian_eigenvalues`` checks one on Fourier grids.

Nested iteration (``solve(nested=True)``, the default on Fourier grids): coarser grids first, each
level started from the trigonometric interpolant of the last; see ``coarse_levels``.

Reported multipliers of ``exact`` are the least-squares ones of the final phi in the dual metric
(independent of the iteration), with rigidity * grad E_h = lam_A grad A + lam_B grad B. The result
records both the dual-norm KKT residual (``extra['kkt_dual']``, the stopping test) and the L2 one
from ``kkt.kkt_residual`` (``kkt_residual``), which has a round-off floor ~ eps_mach k_max^4;
``converged`` requires the dual test, the constraints, and the L2 residual below
``KKT_FACTOR * tol`` or below ``ROUNDOFF_FACTOR`` times its measured floor (``extra``).
"""

from __future__ import annotations

import math
import time

import numpy as np

from . import functionals as F
from .discretization import discretize
from .errors import InputError
from .feasibility import check_feasible
from .kkt import kkt_residual
from .matfree import LumpedOperators, PhaseField
from .newton import Counters, Objective, hessian_solve, newton_minimize
from .precond import FourierPreconditioner, SparsePreconditioner
from .result import Result
from .spectral import fourier_grid

KKT_FACTOR = 100.0  # as the IPOPT backend (solve.KKT_FACTOR): L2 vs scaled-test ratio allowance
ROUNDOFF_FACTOR = 10.0  # the L2 residual may sit at 10x its round-off floor (see _l2_floor)
RHO_HAT = 10.0  # initial rho_i = RHO_HAT / (G_i^T P^{-1} G_i): the penalty dominates the model
MAX_OUTER = 30
COARSE_MIN_N = 16  # nested iteration: coarsest grid side
COARSE_TOL = 1e-5  # coarse levels only make a start; their error is far below the fine step's reach
CONSTRAINT_MARGIN = 0.1  # outer stop at |c| <= 0.1 tol (scaled as IPOPT's test): the energy error lam . c
# then stays below the 1e-8 agreement with IPOPT (measured 7e-8 on a P1 ellipse with margin 1)
W_REFRESH = 0.1  # a reused dual Hessian must cut |c| 10x per outer iteration, else it is recomputed
W_TOL = 1e-4  # CG tolerance of the two solves H^{-1} dA, H^{-1} dB of the dual Newton step: its error
# only slows the (otherwise quadratic) multiplier convergence by a factor ~1e-4 per outer iteration


def prepare(scene, disc=None):
    """(disc, PhaseField, preconditioner, translations) for a scene; FD grids go to FFT."""
    disc = disc or discretize(scene)
    if disc.kind == "fd" and getattr(disc, "fourier", None) is None:
        disc = fourier_grid(disc.box, disc.grid_shape, "fd")  # equal to the sparse FD to round-off
    ops = LumpedOperators(disc)
    pf = PhaseField(ops, scene.model.epsilon, scene.model.C)
    fourier = getattr(disc, "fourier", None)
    if fourier is not None:
        prec = FourierPreconditioner(fourier, disc.weights[0], scene.model.epsilon)
    else:
        prec = SparsePreconditioner(disc.K, disc.weights, scene.model.epsilon, disc.dim)
    # translations are null modes only where the discrete problem is translation invariant (grid
    # shifts of Fourier grids); a tetrahedral mesh breaks the symmetry, so its gradient has parts
    # along d_i phi that a projection would freeze (measured: a stall at kkt_dual 3e-6)
    deriv = fourier

    def translations(phi):
        if deriv is None:
            return None
        return np.column_stack(deriv.derivatives(phi))

    return disc, pf, prec, translations


def _least_squares_multipliers(prec, rig, dE, dA, dB) -> np.ndarray:
    """argmin_lam |rig dE - lam_A dA - lam_B dB|_* in the dual metric of the model P0."""
    pinv = prec.inverse(1.0)
    G = [dA, dB]
    PG = [pinv(v) for v in G]
    N = np.array([[G[i] @ PG[j] for j in range(2)] for i in range(2)])
    rhs = np.array([rig * (dE @ PG[i]) for i in range(2)])
    return np.linalg.solve(N, rhs)


def _dual_kkt(prec, rig, dE, dA, dB, lam) -> float:
    dn = prec.dual_norm
    res = rig * dE - lam[0] * dA - lam[1] * dB
    scale = rig * dn(dE) + abs(lam[0]) * dn(dA) + abs(lam[1]) * dn(dB)
    return dn(res) / max(scale, np.finfo(float).tiny)


def _l2_floor(disc, rig, dE, eps) -> float:
    """Round-off floor of the relative L2 KKT residual: eps_mach * |symbol|_max^2 * eps scale of dE.

    dE contains eps Delta_h^T (m eps Delta_h phi)/eps; round-off in phi (eps_mach) is amplified by
    the largest |symbol|^2, so |delta dE|_L2 ~ eps_mach eps sigma_max^2 |Omega|^{1/2}.
    """
    fourier = getattr(disc, "fourier", None)
    if fourier is None:
        return 0.0
    smax = float(np.max(-fourier.symbol))
    dn = math.sqrt(max(dE @ (dE / disc.weights), np.finfo(float).tiny))
    return np.finfo(float).eps * eps * smax**2 * math.sqrt(disc.volume) / dn


def _dual_hessian(obj: Objective, pt) -> np.ndarray | None:
    """W = G^T H_rho^{-1} G (2 x 2) by two CG solves; None when CG meets negative curvature."""
    sols = [hessian_solve(obj, pt, g, W_TOL) for g in (pt.dA, pt.dB)]
    if not all(s.status == "converged" for s in sols):
        return None
    W = np.array([[pt.dA @ sols[j].x, pt.dB @ sols[j].x] for j in range(2)])
    return 0.5 * (W + W.T)


def _exact(obj: Objective, pt0_phi, tol, max_iter, volume, beta, log, dual_model=None):
    """Augmented Lagrangian with dual Newton steps. dual_model = (W, rho) of a coarser level: with
    the same rho, W = dc/dlam is a mesh-independent quantity, so it carries over to discretisation
    accuracy and the finer level needs no W solves unless its |c| stops falling."""
    prec, rig = obj.prec, obj.rig
    pt = obj.point(pt0_phi)
    obj.lam = _least_squares_multipliers(prec, rig, pt.dE, pt.dA, pt.dB)
    W = None
    if dual_model is not None:
        W, obj.rho = dual_model
    else:
        pinv = prec.inverse(rig)
        obj.rho = np.array([RHO_HAT / float(g @ pinv(g)) for g in (pt.dA, pt.dB)])
    cscale = np.array([volume, abs(beta)])
    prev_c = np.inf
    status = "max_iter"
    for outer in range(1, MAX_OUTER + 1):
        crel = float(np.max(np.abs(pt.c) / cscale))
        inner_tol = max(0.1 * tol, min(1e-3, crel))
        budget = max_iter - obj.cnt.newton
        pt, inner = newton_minimize(obj, pt.phi, inner_tol, budget)
        crel = float(np.max(np.abs(pt.c) / cscale))
        lam_ls = _least_squares_multipliers(prec, rig, pt.dE, pt.dA, pt.dB)
        dual = _dual_kkt(prec, rig, pt.dE, pt.dA, pt.dB, lam_ls)
        log.append({"outer": outer, "inner": inner, "newton": obj.cnt.newton, "c_rel": crel,
                    "dual": dual, "rho": obj.rho.tolist(), "lam": lam_ls.tolist()})
        if inner not in ("converged", "max_iter"):
            status = f"inner_{inner}"
            break
        if crel <= CONSTRAINT_MARGIN * tol and dual <= tol:
            status = "converged"
            break
        if obj.cnt.newton >= max_iter:
            break
        # Newton step on the dual: lam <- lam - W^{-1} c, W = G^T H_rho^{-1} G; a reused W is
        # refreshed when |c| fell by less than W_REFRESH over the last outer iteration
        if W is None or crel > W_REFRESH * prev_c:
            W = _dual_hessian(obj, pt)
        try:
            obj.lam = obj.lam - np.linalg.solve(W, pt.c)
        except (np.linalg.LinAlgError, ValueError):
            W = None
            obj.lam = obj.lam - obj.rho * pt.c
        if crel > 0.25 * prev_c:
            obj.rho = obj.rho * 10.0
        prev_c = crel
    return pt, status, lam_ls, dual, (None if W is None else (W, obj.rho.copy()))


def _penalty(obj: Objective, phi, tol, max_iter, Ms):
    status, pt = "max_iter", None
    for M in Ms:
        obj.lam, obj.rho = np.zeros(2), np.array([M, M], float)
        pt, status = newton_minimize(obj, phi, tol, max_iter - obj.cnt.newton)
        phi = pt.phi
        if status != "converged":
            break
    return pt, status


def coarse_levels(disc, epsilon: float) -> list[tuple[int, ...]]:
    """Grid shapes of the nested-iteration start, coarse to fine, excluding disc's own.

    Halve n while every side stays even and >= COARSE_MIN_N and the coarse spacing still resolves
    the interface (h <= eps); only on Fourier grids (spectral or FD), where the Fourier interpolant
    carries a coarse solution to the fine grid.
    """
    if getattr(disc, "fourier", None) is None:
        return []
    shapes, n = [], tuple(disc.grid_shape)
    lengths = disc.fourier.lengths
    while all(k % 2 == 0 and k // 2 >= COARSE_MIN_N for k in n) and max(lengths / (np.array(n) // 2)) <= epsilon:
        n = tuple(k // 2 for k in n)
        shapes.append(n)
    return shapes[::-1]


def resample(phi: np.ndarray, shape_from, shape_to) -> np.ndarray:
    """The trigonometric interpolant of a periodic grid field on another grid (same box)."""
    from scipy.signal import resample as fourier_resample
    v = phi.reshape(shape_from)
    for axis, n in enumerate(shape_to):
        v = fourier_resample(v, n, axis=axis)
    return np.ascontiguousarray(v).ravel()


def _run_level(scene, disc, phi, cnt, log, tol, max_iter, check, W=None):
    from .nlp import constraint_data  # the core's (alpha, beta), target shapes evaluated on this mesh
    disc, pf, prec, translations = prepare(scene, disc)
    alpha, beta = constraint_data(scene, disc)
    if check:
        check_feasible(alpha, beta, scene, disc)
    method, M = scene.solver.method, scene.solver.M
    obj = Objective(pf, prec, translations, scene.model.rigidity, alpha, beta, np.zeros(2), np.zeros(2), cnt)
    if method == "exact":
        pt, status, lam, dual, W = _exact(obj, phi, tol, max_iter, disc.volume, beta, log, W)
    elif method in ("penalty", "continuation"):
        Ms = [M] if method == "penalty" else [M / 100, M / 10, M]
        pt, status = _penalty(obj, phi, tol, max_iter, Ms)
        lam = -M * pt.c  # rig dE + M c . dc = 0 at the penalty's stationary point
        dual = pt.rel
    else:
        raise InputError("solver.method", f"{method!r}: allowed exact, penalty, continuation")
    return disc, pt, status, lam, dual, alpha, beta, W


def solve(scene, disc=None, phi0=None, throw: bool = False, check: bool = True,
          nested: bool = True) -> Result:
    """Solve a scene with the Newton-Krylov backend; the same Result as ``solve.solve``.

    ``nested``: on Fourier grids first solve on the ``coarse_levels`` (to COARSE_TOL) from the same
    initial shape and start each finer level from the Fourier interpolant (nested iteration; the
    reported wall time and counts include the coarse levels).
    """
    from .shapes import phase_field
    t0, cpu0 = time.perf_counter(), time.process_time()
    disc = disc or discretize(scene)
    if disc.kind == "fd" and getattr(disc, "fourier", None) is None:
        disc = fourier_grid(disc.box, disc.grid_shape, "fd")  # equal to the sparse FD to round-off
    rig, eps, tol = scene.model.rigidity, scene.model.epsilon, scene.solver.tol
    method, M = scene.solver.method, scene.solver.M
    levels = coarse_levels(disc, eps) if (nested and phi0 is None) else []
    cnt = Counters()
    log: list = []
    level_log = []
    phi = W = prev_shape = None
    for shape in levels:
        cdisc = fourier_grid(disc.box, shape, disc.kind)
        start = phase_field(scene.initial, cdisc.nodes, cdisc.box, eps) if phi is None else \
            resample(phi, prev_shape, shape)
        n0, c0, tl = cnt.newton, cnt.cg, time.perf_counter()
        _, cpt, cstatus, *_, W = _run_level(scene, cdisc, start, cnt, log, max(tol, COARSE_TOL),
                                            scene.solver.max_iter, check=False, W=W)
        level_log.append({"n": list(shape), "status": cstatus, "newton": cnt.newton - n0,
                          "cg": cnt.cg - c0, "wall_s": time.perf_counter() - tl})
        phi, prev_shape = cpt.phi, shape
    if phi is None:
        phi = phase_field(scene.initial, disc.nodes, disc.box, eps) if phi0 is None else np.array(phi0, float)
    else:
        phi = resample(phi, prev_shape, disc.grid_shape)
    n0, c0, tl = cnt.newton, cnt.cg, time.perf_counter()
    disc, pt, status, lam, dual, alpha, beta, _ = _run_level(scene, disc, phi, cnt, log, tol,
                                                             scene.solver.max_iter, check, W)
    level_log.append({"n": list(disc.grid_shape or [disc.n_nodes]), "status": status,
                      "newton": cnt.newton - n0, "cg": cnt.cg - c0, "wall_s": time.perf_counter() - tl})
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    phi = pt.phi
    vals = F.evaluate(disc, phi, eps, scene.model.C)  # independent re-evaluation (functionals.py)
    res_A, res_B = vals["A"] - alpha, vals["B"] - beta
    kkt = kkt_residual(disc, phi, eps, scene.model.C, rig, float(lam[0]), float(lam[1]))
    floor = _l2_floor(disc, rig, pt.dE, eps)
    finite = bool(np.all(np.isfinite(phi)))
    success = status == "converged" and finite
    feasible = abs(res_A) <= tol * disc.volume and abs(res_B) <= tol * abs(beta)
    l2_ok = kkt <= max(KKT_FACTOR * tol, ROUNDOFF_FACTOR * floor)
    converged = success and l2_ok and (feasible or method != "exact")
    penalized = None
    if method != "exact":
        penalized = rig * vals["E"] + M / 2 * (res_A**2 + res_B**2)
    hist = dict(cnt.history)
    hist["outer"] = log
    hist["levels"] = level_log
    result = Result(
        phi=phi, w=None, energy=rig * vals["E"], volume_residual=res_A, area_residual=res_B,
        lambda_volume=float(lam[0]), lambda_area=float(lam[1]), kkt_residual=kkt,
        status=status, success=success, converged=converged, iterations=cnt.newton,
        wall_time_s=wall, derivative_time_s=cnt.deriv_time, other_time_s=wall - cnt.deriv_time,
        n_nodes=disc.n_nodes, hessian_nnz_per_row=float("nan"), method=method,
        M=None if method == "exact" else M, penalized_energy=penalized, history=hist,
        extra={"alpha": alpha, "beta": beta, "epsilon": eps, "h": disc.h, "backend": "newton-krylov",
               "mesh_kind": disc.kind, "kkt_dual": float(dual), "kkt_l2_floor": floor,
               "cpu_time_s": cpu, "newton_iterations": cnt.newton, "cg_iterations": cnt.cg, "hvp_count": cnt.hvp,
               "outer_iterations": len(log), "levels": " ".join("x".join(map(str, lv["n"])) for lv in level_log),
               "fine_newton_iterations": level_log[-1]["newton"]})
    if throw and not converged:
        from .errors import SolverError
        raise SolverError(f"not converged: status {status}, kkt_dual {dual:.3g}, kkt_residual {kkt:.3g}, "
                          f"A-alpha {res_A:.3g}, B-beta {res_B:.3g}", result)
    return result
