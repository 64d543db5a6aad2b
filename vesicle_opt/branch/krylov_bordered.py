"""Newton with the parameter free on a bordered system, each step solved matrix-free by GMRES.

The continuation of a KKT point of (6)-(8) in a parameter p is a square system in
z = (phi, lambda, p, mu) (``branch.bordered`` for the equations: stationarity, the constraints, the
arclength hyperplane, the phase conditions). Its Jacobian is the Hessian of the Lagrangian H
(N x N, applied matrix-free) bordered by k = n_c + 1 + d columns and rows:

    J = [ H    B ]     B = [-G, r_p, -T],   C = [G^T; theta^2 t_phi^T W; T^T],
        [ C    D ]     D = [[0, c_p, 0], [0, t_p, 0], [0, 0, 0]]   (k x k),

G the constraint gradients (dA, dB), r_p the stationarity's derivative in p, c_p the constraints'
(- d alpha/dp, - d beta/dp), T the phase conditions' vectors (weighted translations). J is
indefinite (a saddle-point matrix, and H itself indefinite past a fold or on a saddle branch) and,
through the hyperplane row, not symmetric: GMRES (``nk.gmres``), not CG or MINRES.

Preconditioner: the same border around the Newton-Krylov model P of H (``nk.precond``, SPD: the
constant-coefficient model cE/eps S M_L^{-1} S + cB S, floored), inverted exactly by the Schur
complement (bordering): with U = P^{-1} B (k applications of P^{-1}, once per Newton step) and
S = D - C U (k x k),

    K^{-1} [f; g] = [P^{-1} f - U y;  y],   y = S^{-1} (g - C P^{-1} f),

one P^{-1} a Krylov iteration, as in the fixed-p Newton-CG. K^{-1} is applied on the left: GMRES
minimises |K^{-1}(b - J x)|_2, whose phi block is the residual in P's dual norm, the norm the
Newton-Krylov solver measures stationarity in (``nk.newton_cg``). K and J differ in the H block
only, K^{-1} J = I + K^{-1} [H - P, 0; 0, 0], so K^{-1} J clusters where P^{-1} H does (what keeps
the fixed-p CG counts at 10-300 a Newton step). Measured GMRES counts a Newton step: 2-25 (2D FD
and spectral 48^2), 3-57 (3D octant 20-31 k nodes), 8-28 (3D periodic spectral 90 x 36 x 36).

Newton: inexact, forcing term eta = min(ETA_MAX, max(sqrt(error), OVERSOLVE tol / error))
(Eisenstat-Walker, as the fixed-p steps, without oversolving the last step: ``forcing``), a step
capped at STEP_CAP in any nodal value, halved while the error grows more than
``GROWTH`` (a safeguard, not a line search on a merit function: J's solution is a saddle).
``model.at(phi, lam, p)`` gives what one step needs (``Linearization``); where the model has
``advance(phi, dphi)``, that is the iterate after the step dphi (a step taken in another coordinate,
equal to phi + dphi to first order: ``model.profile.step`` on the vesicle walks), else phi + dphi;
``model`` knows nothing of the walk. Nothing here knows about vesicles:
``tests/branch/test_krylov_bordered.py`` runs it on a closed-form fold, checks the linear solve
against dense LU and the ``advance`` hook on a residual that is linear in atanh.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from vesicle_opt.nk.gmres import gmres

MAX_NEWTON = 25
ETA_MAX = 0.01  # GMRES relative tolerance cap per Newton step (as ``nk.newton_cg.ETA_MAX``)
MAX_KRYLOV = 400  # GMRES iterations per Newton step (2x the fixed-p CG cap: GMRES on a saddle point)
RESTART = 200  # Krylov vectors held (memory: RESTART x N floats)
STEP_CAP = 1.0  # no step changes a nodal value by more than 1 (phi lives in [-1, 1]; ``nk.newton_cg``)
GROWTH = 10.0  # a step that multiplies the error by more than this is halved (at most HALVINGS times)
HALVINGS = 6
OVERSOLVE = 0.1  # no GMRES solve is asked for more than 0.1 tol / error: the step that ends Newton only
# has to bring the error below tol (Eisenstat-Walker's sqrt(error) asked 2.8e-5 of the last step at
# error 8e-10, tol 5e-10: 54 GMRES iterations on the 3D octant, 65 k nodes, for a reduction of 0.6)


@dataclass
class Linearization:
    """The system at one z: residuals, the Jacobian's parts and the error the Newton stop reads."""

    r: np.ndarray  # stationarity residual (N)
    c: np.ndarray  # constraint residuals (n_c)
    hvp: Callable  # v -> H v
    pinv: Callable  # r -> P^{-1} r (SPD model of H)
    G: list  # constraint gradients (n_c arrays of N)
    r_p: np.ndarray | None  # d r / d p (None: zero)
    c_p: np.ndarray  # d c / d p (n_c)
    error: Callable  # (r, c) -> relative error, <= tol ends Newton (with the hyperplane held)


@dataclass
class Counts:
    newton: int = 0
    krylov: list = field(default_factory=list)  # GMRES iterations per Newton step
    errors: list = field(default_factory=list)


@dataclass(frozen=True)
class Free:
    """What the bordered Newton-Krylov iteration found (``converged`` false: diverged or stalled)."""

    phi: np.ndarray
    p: float
    lam: tuple
    converged: bool
    iterations: int
    krylov: tuple = ()  # GMRES iterations of each Newton step
    message: str = ""
    mu: tuple = ()  # the phase conditions' multipliers (0 at a solution up to symmetry breaking)
    best: tuple = ()  # not converged: (error, phi, lam) of the iterate with the least error


def bordered_solve(hvp, pinv, cols, rows, corner, f, g, eta: float, max_iter: int = MAX_KRYLOV):
    """[H B; C D] [x; y] = [f; g] by left-preconditioned GMRES (module docstring). ``cols``, ``rows``:
    the k columns of B and rows of C as N-arrays; ``corner``: D (k x k). Returns (x, y, iterations,
    converged)."""
    n, k = f.size, len(cols)
    # P^{-1} is linear: a zero column (r_p where p is a constraint target) maps to zero without an application
    U = [pinv(b) if np.any(b) else np.zeros(n) for b in cols]
    S = np.asarray(corner, float) - np.array([[float(rw @ u) for u in U] for rw in rows]).reshape(k, k)
    S_inv = np.linalg.inv(S) if k else np.zeros((0, 0))

    def precond(f_, g_):
        x = pinv(f_)
        y = S_inv @ (np.asarray(g_, float) - np.array([float(rw @ x) for rw in rows]))
        for u, yi in zip(U, y):
            x -= yi * u
        return np.concatenate([x, y])

    def matvec(z):
        z = np.asarray(z, float).ravel()
        x, y = z[:n], z[n:]
        top = hvp(x)
        for b, yi in zip(cols, y):
            top = top + yi * b
        bottom = np.array([float(rw @ x) for rw in rows]) + _corner_product(corner, y)
        return precond(top, bottom)

    out = gmres(matvec, precond(f, g), eta, max_iter, RESTART)
    return out.x[:n], out.x[n:], out.iterations, out.converged


def border(lin: Linearization, T: list, arc_row: np.ndarray, t_p: float) -> tuple[list, list, np.ndarray]:
    """The border of J at ``lin`` (module docstring): B's columns [-G, r_p, -T], C's rows [G^T, arc_row,
    T^T] and the corner D, for ``bordered_solve``; the unknowns ordered (phi; lambda, p, mu)."""
    nc = len(lin.G)
    cols = [-g for g in lin.G] + [lin.r_p if lin.r_p is not None else np.zeros_like(lin.r)] + [-t for t in T]
    rows = list(lin.G) + [arc_row] + list(T)
    kk = nc + 1 + len(T)
    D = np.zeros((kk, kk))
    D[:nc, nc] = lin.c_p
    D[nc, nc] = t_p
    return cols, rows, D


def forcing(err: float, tol: float) -> float:
    """GMRES's relative tolerance at a Newton step of error ``err``: Eisenstat-Walker's sqrt(err)
    (superlinear), capped at ``ETA_MAX``, never below ``OVERSOLVE`` tol / err (no more accuracy than
    the end of the iteration needs)."""
    err = max(float(err), np.finfo(float).tiny)
    return min(ETA_MAX, max(np.sqrt(err), OVERSOLVE * tol / err))


def _corner_product(corner, y):
    return np.asarray(corner, float) @ y if len(y) else np.zeros(0)


def newton(model, phi_pred, lam_pred, p_pred: float, t_phi, t_p: float, theta: float, weights,
           tol: float, phase=(), max_newton: int = MAX_NEWTON, arc_tol: float = 1e-10, deflation=None,
           start=None) -> Free:
    """Newton from the prediction onto the hyperplane theta^2 <phi - phi_pred, t_phi>_w +
    (p - p_pred) t_p = 0 (t_phi = 0, t_p = 1: Newton at fixed p), with the phase conditions
    <T_i, phi - phi_pred> = 0 for the vectors ``phase`` (multipliers mu_i on -T_i in the
    stationarity). Stops where ``error`` <= tol and the hyperplane and phase rows hold to
    ``arc_tol`` (relative). ``deflation(phi, dphi)``: the factor of each step (``branch.deflation``:
    Sherman-Morrison on the undeflated GMRES step, the deflated step is that step rescaled; None: 1).
    ``start``: another candidate first iterate; Newton starts from whichever of it and phi_pred has
    the smaller error (one residual more; the hyperplane and the phase rows stay anchored at phi_pred:
    being linear, one step puts the iterate on them)."""
    w = np.asarray(weights, float)
    phi = np.array(phi_pred, float)
    lam, p = np.array(lam_pred, float), float(p_pred)
    T = [np.asarray(t, float) for t in phase]
    mu = np.zeros(len(T))
    arc_row = theta**2 * w * np.asarray(t_phi, float)
    cnt = Counts()
    scale = max(1.0, float(np.sqrt(w @ (phi * phi))))

    def evaluate(phi, lam, p, mu):
        """The linearisation at z, the residual rows (stationarity, hyperplane, phases) and the error."""
        lin = model.at(phi, lam, p)
        r = lin.r.copy()
        for m, t in zip(mu, T):
            r -= m * t
        N = float(arc_row @ (phi - phi_pred)) + (p - p_pred) * t_p
        ph = np.array([float(t @ (phi - phi_pred)) for t in T])
        return lin, r, N, ph, lin.error(r, lin.c)

    advance = getattr(model, "advance", None) or (lambda x, dx: x + dx)
    lin, r, N, ph, err = evaluate(phi, lam, p, mu)
    if start is not None:  # the candidate start (``model.profile.interface_secant`` on the vesicle walks)
        phi_s = np.array(start, float)
        at_start = evaluate(phi_s, lam, p, mu)
        if np.isfinite(at_start[-1]) and at_start[-1] < err:
            phi, (lin, r, N, ph, err) = phi_s, at_start
    best: tuple = ()
    for k in range(1, max_newton + 1):
        cnt.errors.append(err)
        if np.isfinite(err) and err <= min(cnt.errors):
            best = (err, phi, lam)
        if not np.isfinite(err):
            return Free(phi, p, tuple(lam), False, k - 1, tuple(cnt.krylov), "non-finite residual", tuple(mu))
        held = abs(N) <= arc_tol * scale and all(abs(v) <= arc_tol * scale for v in ph)
        if err <= tol and held:
            return Free(phi, p, tuple(lam), True, k - 1, tuple(cnt.krylov), "", tuple(mu))
        nc = len(lin.G)
        cols, rows, D = border(lin, T, arc_row, t_p)
        g_rhs = -np.concatenate([lin.c, [N], ph])
        eta = forcing(err, tol)
        dx, dy, its, _ = bordered_solve(lin.hvp, lin.pinv, cols, rows, D, -r, g_rhs, eta)
        cnt.krylov.append(its)
        if deflation is not None:  # the deflated Newton step: the same direction, rescaled
            f = deflation(phi, dx)
            dx, dy = f * dx, f * dy
        if not (np.all(np.isfinite(dx)) and np.all(np.isfinite(dy))):
            return Free(phi, p, tuple(lam), False, k, tuple(cnt.krylov), "non-finite step", tuple(mu))
        s = min(1.0, STEP_CAP / max(float(np.max(np.abs(dx))), np.finfo(float).tiny))
        for _ in range(HALVINGS + 1):
            phi_t, lam_t = advance(phi, s * dx), lam + s * dy[:nc]
            p_t, mu_t = p + s * dy[nc], mu + s * dy[nc + 1:]
            lin_t, r_t, N_t, ph_t, err_t = evaluate(phi_t, lam_t, p_t, mu_t)
            if np.isfinite(err_t) and err_t <= GROWTH * err:
                break
            s *= 0.5
        else:
            return Free(phi, p, tuple(lam), False, k, tuple(cnt.krylov), "the error grew at every step length",
                        tuple(mu))
        phi, lam, p, mu, lin, r, N, ph, err = phi_t, lam_t, p_t, mu_t, lin_t, r_t, N_t, ph_t, err_t
    return Free(phi, p, tuple(lam), False, max_newton, tuple(cnt.krylov),
                f"no convergence in {max_newton} Newton steps (error {err:.2e})", tuple(mu), best)
