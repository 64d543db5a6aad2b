"""The matrix-free Newton-Krylov backend (``solver.backend = 'newton-krylov'``).

Methods (``solver.method``):

* ``exact``: an augmented Lagrangian around ``nk.newton_cg.newton_minimize``. After each inner solve the
  multipliers take a Newton step on the dual function, lam <- lam - W^{-1} c with
  W = G^T H_rho^{-1} G (G = [dA, dB], two extra CG solves), which is the Newton-KKT step in the
  multipliers (and lam - rho c, the classical update, when rho is large); rho grows 10x when |c|
  falls by less than 4x. Stops when the constraints hold to 0.1 tol (|A-alpha| <= tol |Omega|,
  |B-beta| <= tol beta is the IPOPT backend's test) and the relative dual KKT residual <= tol.
* ``penalty``: the same inner solver with lam = 0, rho = (M, M) fixed: the paper's E_{M,h} (11) with
  rigidity on E only. The multipliers are the penalty's, lam = -M c (exact at its stationary point).
* ``continuation``: penalty solves at M_k = M0 r^k (``solver.M0``, ``M_factor``, ``M_max``: the
  schedule of the IPOPT path, ``model.penalty.schedule``), each warm-started from the last, stopped
  where the next stage's floor would reach tol (``model.penalty.next_stage``); the result is the last
  stage's, every stage in ``history['stages']``, with the Richardson extrapolation in 1/M and the
  augmented polish beside it (``nk.stages``, as on IPOPT).
* ``augmented``: stage k minimises E_{M,h} - mu_k . c; mu moves by Broyden's secant method on c(mu) = 0
  from the first-order step mu - M c (``model.penalty.DualSecant``), M only where its floor stays below
  tol (``model.penalty.raise_M``), at most ``solver.max_outer`` stages; certified with the exact
  constraints.

Translations d_i phi are projected out of every step on Fourier grids (exact null modes of the
spectral problem up to aliasing). On coarse grids (h ~ eps) several KKT points are close: from the
symmetric torus start both backends end at the axisymmetric one; so does the P1 tensor mesh (whose
lumped operator equals FD) with a preconditioner that keeps the mesh symmetries, while three plain
pyamg V-cycles, which break them at ~3e-5, led to a lower, slightly non-axisymmetric one (330.02 vs
330.53 at 16^3, 406.41 vs 407.21 at 24^3; see ``precond``). Neither backend certifies a minimiser;
``verify.lobpcg.check`` (the front door's second-order report) checks one.

Nested iteration (``NewtonKrylovOptions.nested``, the default on Fourier grids): coarser grids first, each
level started from the trigonometric interpolant of the last; see ``coarse_levels``.

Reported multipliers of ``exact`` are the least-squares ones of the final phi in the dual metric
(independent of the iteration), with rigidity * grad E_h = lam_A grad A + lam_B grad B. The solver
stops on the quantity the certificate decides on (issue 25, one quantity): the KKT residual in the
natural norm (``model.metric``) relative to the norms of its five elementary terms
(``verify.kkt.terms_scale``; ``extra['kkt_dual_solver']``, which ``verify.certify.build_result``
recomputes independently as ``kkt_dual``, with its floor ~ eps_mach h^-2, ``kkt_dual_floor``). Until
then it stopped on the same residual relative to the net terms (reported as ``kkt_dual_net``; never
below ``kkt_dual``): at tol 1e-10 the 256^2 circles and the 48^3/64^3 sphere, whose net terms cancel
40 ... 2800x, could not meet it and ended ``roundoff_stall`` after extra Newton steps. Where even the
certificate's quotient cannot be met (tol at or below its floor) the inner solves stall and the run
still ends ``roundoff_stall`` (``outer_verdict``), judged by the certificate. The L2 residual
(``kkt_residual``, floor ~ eps_mach k_max^4 on Fourier grids: ``l2_floor``, ``extra['kkt_floor']``)
is reported beside them: ``converged`` is the one certificate of every backend.
"""

from __future__ import annotations

import math
import time

import numpy as np
from threadpoolctl import threadpool_limits

from vesicle_opt.io import progress
from vesicle_opt.mesh.cosine import KIND as MIRROR_KIND
from vesicle_opt.mesh.spectral import fourier_grid
from vesicle_opt.model.band_coarse import Lagged
from vesicle_opt.model.feasibility import check_feasible
from vesicle_opt.model.penalty import extrapolation
from vesicle_opt.model.problem import constraint_data, initial_guess
from vesicle_opt.nk.newton_cg import Counters, Objective, hessian_solves, newton_minimize
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.nk.setup import coarse_levels, discretization_path, prepare, resample
from vesicle_opt.nk.stages import Stage, penalty_stages, timed_stage  # noqa: F401 (nk_jax imports them here)
from vesicle_opt.result import Result, combine_stages, polish_keys, stage_record
from vesicle_opt.scene.shapes import phase_field
from vesicle_opt.verify.certify import build_result, dual_floor_of


SOLVE_LAG_G = 1.2  # a solve's coarse space is remade where eps |g' - g'_held| > 1.2 (eps g' = 1 - 3 phi^2 spans 3):
# octant prolate eps 0.05 (205 k nodes), cold: 14 spaces made, 14.5 CPU s; at 0.6, 21 made, 14.7 s
SOLVE_LAG_CB = 0.1  # ... and re-factored (the space kept) where -mu_B moves by more than 10 %
ROUNDOFF_STALL = "roundoff_stall"  # 'exact': the constraints held, the inner solves stalled at round-off


def _least_squares_multipliers(prec, rig, dE, dA, dB) -> np.ndarray:
    """argmin_lam |rig dE - lam_A dA - lam_B dB|_* in the dual metric of the model P0."""
    pinv = prec.inverse(1.0)
    G = [dA, dB]
    PG = [pinv(v) for v in G]
    N = np.array([[G[i] @ PG[j] for j in range(2)] for i in range(2)])
    rhs = np.array([rig * (dE @ PG[i]) for i in range(2)])
    return np.linalg.solve(N, rhs)


def _dual_hessian(obj: Objective, pt, w_tol: float) -> np.ndarray | None:
    """W = G^T H_rho^{-1} G (2 x 2) by two CG solves; None when CG meets negative curvature."""
    sols = hessian_solves(obj, pt, (pt.dA, pt.dB), w_tol)
    if not all(s.status == "converged" for s in sols):
        return None
    W = np.array([[pt.dA @ sols[j].x, pt.dB @ sols[j].x] for j in range(2)])
    return 0.5 * (W + W.T)


def dual_model_at(W: np.ndarray, rho: np.ndarray, rho_new: np.ndarray) -> np.ndarray:
    """W = G^T (H + G diag(rho) G^T)^{-1} G moved to rho_new: W^{-1} = (G^T H^{-1} G)^{-1} + diag(rho)
    (push-through identity), so W_new^{-1} = W^{-1} + diag(rho_new - rho)."""
    return np.linalg.inv(np.linalg.inv(W) + np.diag(np.asarray(rho_new, float) - np.asarray(rho, float)))


def _exact(obj: Objective, pt0_phi, tol, opts: NewtonKrylovOptions, volume, beta, log, dual_model=None,
           lam0=None, nearby=False):
    """Augmented Lagrangian with dual Newton steps. dual_model = (W, rho, ...) of a coarser level: with
    the same rho, W = dc/dlam is a mesh-independent quantity, so it carries over to discretisation
    accuracy and the finer level needs no W solves unless its |c| stops falling. ``nearby``: it is
    a nearby solution's (a branch's last point): rho starts afresh (carried, it grew 10x a point
    along a 3D branch) and W is moved to it (``dual_model_at``). lam0: the start multipliers
    (physical), e.g. a branch's prediction; None: least squares at the start field."""
    prec, rig = obj.prec, obj.rig
    pt = obj.point(pt0_phi)
    obj.lam = _least_squares_multipliers(prec, rig, pt.dE, pt.dA, pt.dB) if lam0 is None else \
        np.array(lam0, float)
    W = None
    if dual_model is not None and not nearby:
        W, obj.rho = dual_model[:2]
    else:
        pinv = prec.inverse(rig)
        obj.rho = np.array([opts.rho_hat / float(g @ pinv(g)) for g in (pt.dA, pt.dB)])
        if dual_model is not None:
            try:
                W = dual_model_at(dual_model[0], dual_model[2], obj.rho)
            except np.linalg.LinAlgError:  # a singular W: computed afresh
                W = None
    w_rho = obj.rho.copy()  # the rho at which W was computed (dual_update may grow rho after)
    cscale = np.array([volume, abs(beta)])
    prev_c = np.inf
    status = "max_iter"
    stalled_before = False
    for outer in range(1, opts.exact_max_outer + 1):
        crel = float(np.max(np.abs(pt.c) / cscale))
        inner_tol = max(0.1 * tol, min(1e-3, crel))
        budget = opts.max_iter - obj.cnt.newton
        pt, inner = newton_minimize(obj, pt.phi, inner_tol, budget, opts.max_cg)
        crel = float(np.max(np.abs(pt.c) / cscale))
        lam_ls = _least_squares_multipliers(prec, rig, pt.dE, pt.dA, pt.dB)
        dual = obj.kkt_at(pt, lam_ls)  # the certificate's quotient (verify.kkt.terms_scale)
        log.append({"outer": outer, "inner": inner, "newton": obj.cnt.newton, "c_rel": crel,
                    "dual": dual, "rho": obj.rho.tolist(), "lam": lam_ls.tolist()})
        verdict, stalled_before = outer_verdict(inner, crel, dual, tol, opts, stalled_before,
                                                obj.cnt.newton >= opts.max_iter)
        if verdict is not None:
            status = verdict
            break
        # Newton step on the dual: lam <- lam - W^{-1} c, W = G^T H_rho^{-1} G; a reused W is
        # refreshed when |c| fell by less than w_refresh over the last outer iteration
        if W is None or crel > opts.w_refresh * prev_c:
            W, w_rho = _dual_hessian(obj, pt, opts.w_tol), obj.rho.copy()
        W = dual_update(obj, W, pt.c, crel, prev_c)
        prev_c = crel
    # (W, the rho reached, the rho W belongs to): a finer level takes the first two, ``nearby`` the third
    return pt, status, lam_ls, dual, (None if W is None else (W, obj.rho.copy(), w_rho))


def outer_verdict(inner: str, crel: float, dual: float, tol: float, opts: NewtonKrylovOptions,
                  stalled_before: bool, budget_spent: bool) -> tuple[str | None, bool]:
    """The exact-constraint loop's decision after an inner solve ended with status ``inner`` at
    relative constraint residual ``crel`` and dual KKT residual ``dual``: (status, stalled_before),
    status None to go on with a multiplier update. Shared by the numpy loop and ``nk_jax.solver``.

    The outer test comes first: an inner solve that stalls at round-off on a point that meets it (a
    start at a solution, e.g. an earlier solve's file) has converged.
    [Issue 12] An inner solve that stalls (steps below the round-off of phi) has done what double
    precision permits at these multipliers; it used to end the run ("inner_stalled", exit 1) even
    where the outer iteration could still move the multipliers, or where the point already met
    everything but a dual test below its own round-off (ellipse 128^2 spectral at tol 1e-12, FD
    1024^2 at tol 1e-9). Now the outer loop goes on; two stalls in a row with the constraints
    held end it as ROUNDOFF_STALL, which the certificate judges like a success: it passes only
    if the independent ``kkt_dual`` meets 100 tol and its floor is below tol (else outcome
    roundoff_floor, with the tolerance that can be certified). ``dual`` is that same quotient
    (``Objective.kkt_at``), so a stall here means the certificate's own test was out of reach. ``budget_spent``: the Newton budget
    is used up (max_iter, or ROUNDOFF_STALL when this last inner solve stalled with them held)."""
    held = crel <= opts.constraint_margin * tol
    if held and dual <= tol:
        return "converged", stalled_before
    if inner == "stalled":
        if held and stalled_before:
            return ROUNDOFF_STALL, True
        stalled_before = held
    elif inner not in ("converged", "max_iter"):
        return f"inner_{inner}", stalled_before
    else:
        stalled_before = False
    if budget_spent:
        return (ROUNDOFF_STALL if inner == "stalled" and held else "max_iter"), stalled_before
    return None, stalled_before


def dual_update(obj, W, c, crel: float, prev_c: float):
    """The multiplier step of the exact-constraint loop, on ``obj.lam`` and ``obj.rho`` in place:
    Newton on the dual, lam <- lam - W^{-1} c, or the first-order lam <- lam - rho c when W is
    singular (then W is dropped: returned None); rho x 10 when |c| fell by less than 4x. Shared by
    the numpy loop and ``nk_jax.solver``."""
    try:
        obj.lam = obj.lam - np.linalg.solve(W, c)
    except (np.linalg.LinAlgError, ValueError):
        W = None
        obj.lam = obj.lam - obj.rho * c
    if crel > 0.25 * prev_c:
        obj.rho = obj.rho * 10.0
    return W


def band_coarse_of(pf, opts: NewtonKrylovOptions):
    """The Newton-CG preconditioner's coarse space on mirror grids (``opts.band_coarse``), else None.
    Reused while eps |g' - g'_held| <= ``SOLVE_LAG_G`` (re-factored where only -mu_B moves by more than
    ``SOLVE_LAG_CB``): a solve moves the state far more than a branch point's corrector does."""
    grid = pf.ops.fourier
    if not opts.band_coarse or grid is None or getattr(grid, "kind", None) != MIRROR_KIND:
        return None
    return Lagged(pf.eps, SOLVE_LAG_G, SOLVE_LAG_CB)


def _run_level(scene, disc, phi, cnt, log, tol, opts, W=None, setup=None, lam0=None, nearby=False):
    disc, pf, prec, translations = setup or prepare(scene, disc)
    alpha, beta = constraint_data(scene, disc)
    method = scene.solver.method
    obj = Objective(pf, prec, translations, scene.model.rigidity, alpha, beta, np.zeros(2), np.zeros(2), cnt,
                    coordinates=opts.fourier_coordinates, coarse=band_coarse_of(pf, opts))
    if method == "exact":
        (pt, status, lam, dual, W), n, wall, deriv = timed_stage(
            obj, lambda: _exact(obj, phi, tol, opts, disc.volume, beta, log, W, lam0, nearby))
        stages = [Stage(pt, status, None, (0.0, 0.0), lam, dual, n, wall, deriv)]
    else:
        eps, C, rig = scene.model.epsilon, scene.model.C, scene.model.rigidity

        def floor(pt, M):
            return dual_floor_of(disc, pt.phi, eps, C, rig, tuple(pt.mu), (M, M), (pt.dE, pt.dA, pt.dB))
        stages = penalty_stages(obj, phi, tol, opts, method, scene.solver, disc.volume, beta, floor=floor)
    return disc, stages, alpha, beta, W


def l2_floor(disc, rig, eps, grads, lam) -> float:
    """Round-off floor of the relative L2 KKT residual on Fourier grids. dE contains
    eps Delta_h^T (m eps Delta_h phi)/eps and dB contains eps Delta_h phi: the round-off of phi
    (eps_mach per node, independent from node to node: white noise of L2 norm eps_mach |Omega|^{1/2})
    is amplified mode by mode by sigma^2 (resp. sigma), sigma = |symbol|, so

        |delta r|_L2 ~ eps_mach eps (rig rms(sigma^2) + |lam_B| rms(sigma)) |Omega|^{1/2},

    made relative with the residual's own scale rig |dE|_* + |lam_A| |dA|_* + |lam_B| |dB|_*
    (``verify.kkt``). [Issue 12, two changes: (1) the scale was |dE|_* alone, which overstates the
    floor where the terms cancel (a sphere at its own targets: rig dE ~ lam_A dA + lam_B dB, each
    large); (2) sigma_max^2 bounded the worst case of an error concentrated in the highest mode, while
    round-off spreads over all modes, so its amplification is the rms, ~7x (3D) and ~6x (2D) below
    the max. The sphere of R = 1.5 at its own targets (32^3 ... 64^3) was refused with floors
    3.4e-8 ... 5.7e-7 although its kkt_residual, 2.4e-9 ... 3.7e-8, sits at the rms floor.]"""
    fourier = getattr(disc, "fourier", None)
    if fourier is None:
        return 0.0
    dE, dA, dB = grads
    sigma = np.abs(np.asarray(fourier.symbol, float)).ravel()
    rms2, rms1 = math.sqrt(float(np.mean(sigma**4))), math.sqrt(float(np.mean(sigma**2)))
    scale = rig * disc.dual_norm(dE) + abs(lam[0]) * disc.dual_norm(dA) + abs(lam[1]) * disc.dual_norm(dB)
    noise = np.finfo(float).eps * eps * (rig * rms2 + abs(lam[1]) * rms1) * math.sqrt(disc.volume)
    return noise / max(scale, np.finfo(float).tiny)


def pack_run(pack, stages: list[Stage], method: str, cnt, log: list, level_log: list, cpu: float,
             wall: float) -> Result:
    """The Result of a run from its stages (numpy and ``nk_jax`` alike): ``pack(stage, iterations,
    wall_s, deriv_s, history=None, extra=None)`` certifies one stage; the run's totals and history
    go on the last; continuation and augmented combine every stage (``result.combine_stages``)."""
    hist = dict(cnt.history)
    hist["outer"] = log
    hist["levels"] = level_log
    totals = {"cpu_time_s": cpu, "newton_iterations": cnt.newton, "cg_iterations": cnt.cg, "hvp_count": cnt.hvp,
              "outer_iterations": len(log) if method == "exact" else len(stages),
              "levels": " ".join("x".join(map(str, lv["n"])) for lv in level_log),
              "fine_newton_iterations": level_log[-1]["newton"]}
    if method not in ("continuation", "augmented"):  # one stage: the run's totals are its counts
        if len(stages) > 1:  # a penalty re-solved at the certifiable M (model.penalty.penalty_retry)
            totals["M_requested"] = stages[0].M[0]
        return pack(stages[-1], cnt.newton, wall, cnt.deriv_time, hist, totals)
    polish = [st for st in stages if st.polish]
    stages = [st for st in stages if not st.polish]
    records = [pack(st, st.newton, st.wall_s, st.deriv_s) for st in stages[:-1]]
    st = stages[-1]
    records.append(pack(st, st.newton, st.wall_s, st.deriv_s, hist, totals))
    failed = sum(not r.success for r in records)
    info = {"failed_stages": failed}
    if method == "continuation":
        info.update(extrapolation([stage_record(r) for r in records]))
    if polish:  # its last stage, with every polish stage's Newton steps
        info.update(polish_keys(pack(polish[-1], polish[-1].newton, polish[-1].wall_s, polish[-1].deriv_s)),
                    polish_iterations=sum(st.newton for st in polish))
    return combine_stages(records[-1], records, method, wall, info,
                          iterations=cnt.newton, derivative_time_s=cnt.deriv_time)


def solve(scene, disc=None, *, x0=None, options: NewtonKrylovOptions | None = None,
          check: bool = True, setup=None, warm=None) -> Result:
    """``_solve`` (below) with one BLAS thread: its dense work is dot products and N x few
    products, where a second OpenBLAS thread only spin-waits on a busy machine (measured, 48^3
    torus, fresh processes interleaved, load average ~25 on 2 cores: 98.6 s median with the
    default two threads against 27.0 s with one; the issue's quiet-machine figure: <= 4% slower).
    The FFTs are scipy's, one worker (``mesh.fftlib.WORKERS``)."""
    with threadpool_limits(limits=1, user_api="blas"):
        return _solve(scene, disc, x0=x0, options=options, check=check, setup=setup, warm=warm)


def _solve(scene, disc=None, *, x0=None, options: NewtonKrylovOptions | None = None,
           check: bool = True, setup=None, warm=None) -> Result:
    """Solve a scene with the Newton-Krylov backend; the same certified Result as the IPOPT path.

    ``x0``: a start phi (nodal values) instead of the scene's initial field (its shape, or the
    ``initial.file`` of an earlier solve: ``model.problem.initial_guess``). With ``options.nested``
    and a shape start, Fourier grids are first solved on the ``coarse_levels`` (to ``coarse_tol``)
    from the same shape, each finer level started from the Fourier interpolant (the reported wall
    time and counts include the coarse levels). ``check``: refuse infeasible (alpha, beta) before
    any solve. ``setup``: the fine level's ``nk.setup.prepare(scene, disc)``, when the caller
    reuses it (the second-order check). ``warm``: (lam0, dual_model or None) of a nearby solution
    for ``exact`` (``branch.nk_corrector``): the fine level's start multipliers and the dual model
    as an earlier Result's ``history["dual_model"]`` holds it (W, rho, rho of W; ``_exact``).
    """
    opts = options or NewtonKrylovOptions.from_scene(scene)
    t0, cpu0 = time.perf_counter(), time.process_time()
    if setup is None:  # the fine level's operators, built once (a P1 tensor box goes to FFT: nk.setup)
        setup = prepare(scene, disc, tensor_fft=opts.tensor_fft)
    disc = setup[0]
    rig, eps, tol = scene.model.rigidity, scene.model.epsilon, opts.tol
    if check:  # the fine level's data, before any (coarse) solve
        check_feasible(*constraint_data(scene, disc), scene, disc)
    shape_start = x0 is None and scene.initial.shape != "file"
    levels = coarse_levels(disc, eps, opts.coarse_min_n) if (opts.nested and shape_start) else []
    bar = progress.bar(f"Newton-Krylov {scene.solver.method}", unit="Newton steps")

    def on_step(rel: float) -> None:
        bar.set_postfix_str(f"kkt_dual {rel:.1e} (tol {tol:.0e})", refresh=False)
        bar.update(1)

    cnt = Counters(on_step=on_step)
    log: list = []
    level_log = []
    phi = W = prev_shape = None
    for shape in levels:
        cdisc = fourier_grid(disc.box, shape, disc.kind)
        start = phase_field(scene.initial, *cdisc.scene_points(), eps) if phi is None else \
            resample(phi, prev_shape, shape, disc.kind)
        n0, c0, tl = cnt.newton, cnt.cg, time.perf_counter()
        _, cstages, *_, W = _run_level(scene, cdisc, start, cnt, log, max(tol, opts.coarse_tol), opts, W=W)
        level_log.append({"n": list(shape), "status": cstages[-1].status, "newton": cnt.newton - n0,
                          "cg": cnt.cg - c0, "wall_s": time.perf_counter() - tl})
        phi, prev_shape = cstages[-1].pt.phi, shape
    if phi is None:
        phi = initial_guess(scene, disc) if x0 is None else np.array(x0, float)
    else:
        phi = resample(phi, prev_shape, disc.grid_shape, disc.kind)
    n0, c0, tl = cnt.newton, cnt.cg, time.perf_counter()
    lam0, nearby = (None, False) if warm is None else (warm[0], warm[1] is not None)
    if nearby:
        W = warm[1]
    disc, stages, alpha, beta, W = _run_level(scene, disc, phi, cnt, log, tol, opts, W, setup, lam0, nearby)
    level_log.append({"n": list(disc.grid_shape or [disc.n_nodes]), "status": stages[-1].status,
                      "newton": cnt.newton - n0, "cg": cnt.cg - c0, "wall_s": time.perf_counter() - tl})
    bar.close()
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    method = scene.solver.method
    path = discretization_path(scene, disc, setup[2])

    def pack(st: Stage, iterations: int, wall_s: float, deriv_s: float, history=None, extra=None) -> Result:
        penalty = st.M is not None
        lam = st.mu - np.asarray(st.M) * st.pt.c if penalty else st.lam  # as build_result computes them
        floor = l2_floor(disc, rig, eps, (st.pt.dE, st.pt.dA, st.pt.dB), lam)
        return build_result(
            scene=scene, disc=disc, alpha=alpha, beta=beta, phi=st.pt.phi, tol=tol,
            solver_status=st.status, solver_success=st.status in ("converged", ROUNDOFF_STALL), method=method,
            lam=None if penalty else tuple(st.lam), M=st.M, mu=st.mu,
            exact_constraints=method in ("exact", "augmented") or st.polish, floor=floor,
            iterations=iterations, wall_time_s=wall_s, derivative_time_s=deriv_s, history=history,
            extra={"backend": "newton-krylov", "mesh_kind": disc.kind, "discretization_path": path,
                   "kkt_dual_solver": float(st.dual),  # its stopping test, kkt_dual's quotient (build_result recomputes it)
                   "kkt_l2_floor": floor, **(extra or {})})

    cnt.history["dual_model"] = W  # (W, rho, rho of W) of the last dual Newton step ('exact'; None: none)
    return pack_run(pack, stages, method, cnt, log, level_log, cpu, wall)
