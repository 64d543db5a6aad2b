"""The Newton-Krylov backend on JAX (``solver.array = 'jax'``): ``nk.solve`` for ``exact`` and
``penalty`` on periodic grids (spectral, FD by FFT), with the fields on one or several devices.

* ``exact``: the augmented Lagrangian with dual Newton steps lam <- lam - W^{-1} c,
  W = G^T H_rho^{-1} G, of ``nk.solve._exact`` (the same rho start, refresh and growth rules and
  the same outer test |c| <= margin tol, dual KKT <= tol (the certificate's quotient,
  ``verify.kkt.terms_scale``), and the same decision after each inner
  solve, ``nk.solve.outer_verdict``, with its ``roundoff_stall`` exit), least-squares multipliers in
  the dual metric of P0;
* ``penalty``, ``continuation``, ``augmented``: ``nk.solve.penalty_stages`` itself, the stage
  loop of the numpy path (one M, re-solved at the certifiable M; the schedule M0 ... M_max stopped
  where the next stage's floor would reach tol, then the augmented polish; the warm ramp and the
  secant multiplier updates at the floor-capped M), with this package's Newton-CG as its inner
  solver and the floors (``verify.certify.dual_floor_of``) computed on the host from the fields
  brought back; every stage is certified and the stages combined as on numpy (``result.combine_stages``).

Nested iteration (coarse grids first, ``nk.setup.coarse_levels``; the interpolant by
``nk.setup.resample`` on the host) as on numpy. The result is the one certified ``Result`` of
every backend: the returned field is brought back to the host and ``verify.certify.build_result``
recomputes E_h, A, B, the multipliers' KKT residual and the round-off floor in numpy on the numpy
discretisation, so the certificate, the summary and the front door's second-order check
(``verify.lobpcg``, numpy) are those of the numpy path.
"""

from __future__ import annotations

import math
import time

import jax
import jax.numpy as jnp
import numpy as np

from vesicle_opt.errors import InputError
from vesicle_opt.mesh import discretize
from vesicle_opt.mesh.spectral import fourier_grid
from vesicle_opt.model.feasibility import check_feasible
from vesicle_opt.model.problem import constraint_data, initial_guess
from vesicle_opt.nk.newton_cg import Counters
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.nk.setup import coarse_levels, discretization_path, on_fourier_grid, resample
from vesicle_opt.nk.solve import (ROUNDOFF_STALL, Stage, dual_update, l2_floor, outer_verdict, pack_run,
                                  penalty_stages, timed_stage)
from vesicle_opt.nk_jax.layout import GridLayout
from vesicle_opt.nk_jax.newton import DeviceObjective, newton_minimize
from vesicle_opt.nk_jax.ops import GridOps
from vesicle_opt.result import Result
from vesicle_opt.scene.shapes import phase_field
from vesicle_opt.verify.certify import build_result, dual_floor_of
from vesicle_opt.verify.kkt import terms_scale

METHODS = ("exact", "penalty", "continuation", "augmented")


def _ls_kernel(ops, rig):
    """(N, rhs) of argmin_lam |rig dE - lam_A dA - lam_B dB|_* (``nk.solve._least_squares_multipliers``)."""
    def kernel(dE, dA, dB):
        G = (dA, dB)
        PG = [ops._apply_inverse(v, 1.0, 0.0, 0.0) for v in G]
        dot = ops.layout.dot
        N = jnp.array([[dot(G[i], PG[j]) for j in range(2)] for i in range(2)])
        rhs = jnp.array([rig * dot(dE, PG[i]) for i in range(2)])
        return N, rhs
    return jax.jit(kernel)


def _residual_norm_kernel(ops, rig):
    """|rig dE - lam_A dA - lam_B dB|_* (the numerator of ``nk.newton_cg.Objective.kkt_at``)."""
    def kernel(dE, dA, dB, lam0, lam1):
        return ops._dual_norm(rig * dE - lam0 * dA - lam1 * dB)
    return jax.jit(kernel)


class Level:
    """One grid: its operators, objective and the exact method's helper kernels."""

    def __init__(self, scene, disc, alpha, beta, cnt, devices):
        self.disc = disc
        self.layout = GridLayout(disc.grid_shape, devices)
        self.ops = GridOps(disc.fourier, scene.model.epsilon, scene.model.C, self.layout)
        rig = scene.model.rigidity
        self.obj = DeviceObjective(self.ops, rig, alpha, beta, np.zeros(2), np.zeros(2), cnt)
        self._ls = _ls_kernel(self.ops, rig)
        self._residual = _residual_norm_kernel(self.ops, rig)
        self._gpg = jax.jit(lambda g, cE: self.layout.dot(g, self.ops._apply_inverse(g, cE, 0.0, 0.0)))

    def multipliers(self, pt) -> np.ndarray:
        N, rhs = jax.device_get(self._ls(pt.dE, self.obj.ones, pt.dB))
        return np.linalg.solve(np.asarray(N), np.asarray(rhs))

    def dual_kkt(self, pt, lam) -> float:
        """The certificate's quotient at pt with multipliers lam (``nk.newton_cg.Objective.kkt_at``)."""
        scale = terms_scale(self.obj.rig, lam[0], lam[1], self.obj.term_norms(pt))
        return float(self._residual(pt.dE, self.obj.ones, pt.dB, lam[0], lam[1])) / max(scale, np.finfo(float).tiny)


def _dual_hessian(level: Level, pt, w_tol: float, max_cg: int):
    obj = level.obj
    sols = [obj.pcg(pt, g, w_tol, max_cg)[0] for g in (obj.ones, pt.dB)]
    if not all(s.status == "converged" for s in sols):
        return None
    W = np.array([[float(obj._dot(obj.ones, s.x)), float(obj._dot(pt.dB, s.x))] for s in sols])
    return 0.5 * (W + W.T)


def _exact(level: Level, phi, tol, opts: NewtonKrylovOptions, volume, beta, log, dual_model=None):
    """``nk.solve._exact`` on the device (see there)."""
    obj, rig = level.obj, level.obj.rig
    pt = obj.point(phi)
    obj.lam = level.multipliers(pt)
    W = None
    if dual_model is not None:
        W, obj.rho = dual_model
    else:
        obj.rho = np.array([opts.rho_hat / float(level._gpg(g, rig)) for g in (obj.ones, pt.dB)])
    cscale = np.array([volume, abs(beta)])
    prev_c = np.inf
    status = "max_iter"
    stalled_before = False
    lam_ls, dual = obj.lam, math.inf
    for outer in range(1, opts.exact_max_outer + 1):
        crel = float(np.max(np.abs(pt.c) / cscale))
        inner_tol = max(0.1 * tol, min(1e-3, crel))
        budget = opts.max_iter - obj.cnt.newton
        pt, inner = newton_minimize(obj, pt.phi, inner_tol, budget, opts.max_cg)
        crel = float(np.max(np.abs(pt.c) / cscale))
        lam_ls = level.multipliers(pt)
        dual = level.dual_kkt(pt, lam_ls)
        log.append({"outer": outer, "inner": inner, "newton": obj.cnt.newton, "c_rel": crel,
                    "dual": dual, "rho": obj.rho.tolist(), "lam": lam_ls.tolist()})
        verdict, stalled_before = outer_verdict(inner, crel, dual, tol, opts, stalled_before,
                                                obj.cnt.newton >= opts.max_iter)
        if verdict is not None:
            status = verdict
            break
        if W is None or crel > opts.w_refresh * prev_c:
            W = _dual_hessian(level, pt, opts.w_tol, opts.max_cg)
        W = dual_update(obj, W, pt.c, crel, prev_c)
        prev_c = crel
    return pt, status, lam_ls, dual, (None if W is None else (W, obj.rho.copy()))


def _run_level(scene, level: Level, phi_host, log, tol, opts, W=None):
    """One level from a host start; returns (stages, W) as ``nk.solve._run_level``."""
    s, obj = scene.solver, level.obj
    phi = level.layout.put(phi_host)
    if s.method == "exact":
        (pt, status, lam, dual, W), n, wall, deriv = timed_stage(
            obj, lambda: _exact(level, phi, tol, opts, level.disc.volume, obj.target[1], log, W))
        return [Stage(pt, status, None, (0.0, 0.0), lam, dual, n, wall, deriv)], W
    m, get = scene.model, level.layout.get
    dA = get(obj.ones)

    def floor(pt, M):  # the certificate's floor on the host, as ``nk.solve._run_level``'s
        return dual_floor_of(level.disc, get(pt.phi), m.epsilon, m.C, m.rigidity, tuple(pt.mu), (M, M),
                             (get(pt.dE), dA, get(pt.dB)))
    stages = penalty_stages(obj, phi, tol, opts, s.method, s, level.disc.volume, obj.target[1],
                            minimize=newton_minimize, floor=floor)
    return stages, W


def solve(scene, disc=None, *, x0=None, options: NewtonKrylovOptions | None = None,
          check: bool = True, setup=None, devices=None) -> Result:
    """``nk.solve.solve`` with the arrays in JAX (module docstring); ``devices``: the devices to
    split the grid over (default all of ``jax.devices()``, the largest count dividing n_0)."""
    if scene.solver.method not in METHODS:
        raise InputError("solver.array", f"'jax' runs solver.method {', '.join(METHODS)}, got "
                         f"{scene.solver.method!r}")
    opts = options or NewtonKrylovOptions.from_scene(scene)
    t0, cpu0 = time.perf_counter(), time.process_time()
    disc = setup[0] if setup is not None else on_fourier_grid(disc or discretize(scene))
    rig, eps, tol = scene.model.rigidity, scene.model.epsilon, opts.tol
    alpha, beta = constraint_data(scene, disc)
    if check:
        check_feasible(alpha, beta, scene, disc)
    shape_start = x0 is None and scene.initial.shape != "file"
    levels = coarse_levels(disc, eps, opts.coarse_min_n) if (opts.nested and shape_start) else []
    cnt = Counters()
    log: list = []
    level_log = []
    phi = W = prev_shape = None
    for shape in levels:
        cdisc = fourier_grid(disc.box, shape, disc.kind)
        start = phase_field(scene.initial, cdisc.nodes, cdisc.box, eps) if phi is None else \
            resample(phi, prev_shape, shape)
        ca, cb = constraint_data(scene, cdisc)
        n0, c0, tl = cnt.newton, cnt.cg, time.perf_counter()
        level = Level(scene, cdisc, ca, cb, cnt, devices)
        cstages, W = _run_level(scene, level, start, log, max(tol, opts.coarse_tol), opts, W)
        level_log.append({"n": list(shape), "status": cstages[-1].status, "newton": cnt.newton - n0,
                          "cg": cnt.cg - c0, "wall_s": time.perf_counter() - tl})
        phi, prev_shape = level.layout.get(cstages[-1].pt.phi), shape
    if phi is None:
        phi = initial_guess(scene, disc) if x0 is None else np.array(x0, float)
    else:
        phi = resample(phi, prev_shape, disc.grid_shape)
    n0, c0, tl = cnt.newton, cnt.cg, time.perf_counter()
    level = Level(scene, disc, alpha, beta, cnt, devices)
    stages, _ = _run_level(scene, level, phi, log, tol, opts, W)
    level_log.append({"n": list(disc.grid_shape), "status": stages[-1].status, "newton": cnt.newton - n0,
                      "cg": cnt.cg - c0, "wall_s": time.perf_counter() - tl})
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    method = scene.solver.method
    dA = level.layout.get(level.obj.ones)
    path = discretization_path(scene, disc, None)

    def pack(st: Stage, iterations: int, wall_s: float, deriv_s: float, history=None, extra=None) -> Result:
        """``nk.solve.solve``'s pack, the fields brought to the host first."""
        penalty = st.M is not None
        lam = np.asarray(st.mu) - np.asarray(st.M) * st.pt.c if penalty else st.lam  # as build_result does
        dE, dB = level.layout.get(st.pt.dE), level.layout.get(st.pt.dB)
        floor = l2_floor(disc, rig, eps, (dE, dA, dB), lam)
        return build_result(
            scene=scene, disc=disc, alpha=alpha, beta=beta, phi=level.layout.get(st.pt.phi), tol=tol,
            solver_status=st.status, solver_success=st.status in ("converged", ROUNDOFF_STALL), method=method,
            lam=None if penalty else tuple(st.lam), M=st.M, mu=st.mu,
            exact_constraints=method in ("exact", "augmented") or st.polish, floor=floor,
            iterations=iterations, wall_time_s=wall_s, derivative_time_s=deriv_s, history=history,
            extra={"backend": "newton-krylov", "array": "jax", "devices": level.layout.count,
                   "platform": level.layout.devices[0].platform, "mesh_kind": disc.kind,
                   "kkt_dual_solver": float(st.dual), "kkt_l2_floor": floor, "discretization_path": path,
                   **(extra or {})})

    return pack_run(pack, stages, method, cnt, log, level_log, cpu, wall)
