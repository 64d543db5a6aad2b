"""The front door: ``solve(scene_or_problem, *, backend=None, method=None, x0=None, throw=False)``.

This is the only dispatcher of an equilibrium solve: the CLI, the studies, the tests and the README
call it. The backend (``backends.choose_backend``) and the method are chosen here, once; both
backends return the same certified :class:`~vesicle_opt.result.Result` (``verify.certify``), with
the same reports added here:

* ``second_order``: ``minimum`` / ``saddle`` / ``not checked`` for converged solves that promise
  exact constraints (methods ``exact`` and ``augmented``: the augmented Lagrangian's final point is
  certified with A = alpha, B = beta to tol, and on the tangent space T its Hessian is that of the
  exact Lagrangian with lambda = mu - M c, the penalty's M grad c grad c^T vanishing on T) with
  ``solver.second_order`` (IPOPT: ``verify.second_order``, assembled; Newton-Krylov:
  ``verify.lobpcg``, matrix-free), with ``second_order_min_eigenvalue``; its eigenvector (the
  M-normalised phi direction of the least eigenvalue) is ``history["second_order_mode"]``; the
  error bound of that eigenvalue ``second_order_error_bound`` (mu_ref units, ``verify.verdict``), the
  check's iterations (matrix-free) and its wall seconds ``second_order_time_s`` (beside the
  solve's ``wall_time_s``);
* ``topology`` and its counts (``verify.topology.report``);
* ``shape`` (``verify.shape``): the phi = 0 surface's volume, corrected by the tanh profile's
  O(eps^2) curvature term, against (|Omega| + A) / 2 (4), the bulk's offset from -1 and the volume
  it carries, merged periodic images: ``ok``, ``bulk_offset`` (a warning line, ``shape_reason``)
  or ``wrong_shape`` (outcome ``wrong_shape``, not converged, the line its ``reason``; with
  ``solver.shape_check = false`` a warning line only, the result converged).

``solver.array = 'jax'`` runs the newton-krylov backend's arrays on JAX devices (``nk_jax``); its
field comes back to the host and is certified, and second-order checked, by the numpy code.

Warm starts: ``x0`` is a field phi (nodal values), a full NLP vector, a path to a ``phi.npz``, or an
earlier ``Result`` (on IPOPT its primal-dual point is reused when the NLP matches, else its phi), on
either backend; a file or Result of another periodic grid of the same box is Fourier-resampled
(``model.warm_start``; ``flow(scene, x0=...)`` takes the same argument).
``throw=True`` raises :class:`~vesicle_opt.errors.SolverError` (carrying the result) instead of
returning a result that is not converged.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np

from threadpoolctl import threadpool_limits

from vesicle_opt import nk_jax, resources
from vesicle_opt.backends import METHODS, choose_backend, reason
from vesicle_opt.errors import InputError, NotSupported, SolverError
from vesicle_opt.mesh import band_start
from vesicle_opt.mesh.spectral import fft_library, resolve_fft
from vesicle_opt.model.feasibility import check_feasible
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.model.warm_start import start_field
from vesicle_opt.nk import solve as nk_solve
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.nk.setup import prepare
from vesicle_opt.nlp import NLP, IpoptOptions, PenaltyNLP, build_nlp, reuse, solve_nlp
from vesicle_opt.nlp.solve import solve_exact
from vesicle_opt.result import Result
from vesicle_opt.scene import Scene
from vesicle_opt.scene.ranges import resolution_warning
from vesicle_opt.verify import band, lobpcg, second_order, shape, topology, verdict


# the methods whose converged result promises A = alpha, B = beta to tol: second-order checked
EXACT_METHODS = ("exact", "augmented")

log = logging.getLogger(__name__)  # one INFO line per phase of a solve (the CLI shows them; -q hides them)
REFINED_BLAS_THREADS = 1  # numpy's BLAS threads in a refined mesh's IPOPT solve and certificate (vector
# products: a second OpenBLAS thread only spin-waits on a busy machine; measured, 20.3 k-node meridian
# points, OMP_NUM_THREADS=2, load ~13: 1.06 -> 0.87 s CPU, 2.5 -> 2.1 s wall a point); None: no limit


def _log_start(scene, chosen: str, backend: str | None, n_nodes: int) -> None:
    """The INFO line of a solve's start: scene, method, backend and why (``backends.reason``), after
    every refusal; before it, a warning where eps / h is below the recommended resolution
    (``scene.ranges.resolution_warning``)."""
    if (coarse := resolution_warning(scene)) is not None:
        log.warning("%s", coarse)
    log.info("%s: method %s on %s (%s), %d nodes", scene.name, scene.solver.method, chosen,
             reason(scene, chosen, backend), n_nodes)


def _replace_extra(result: Result, **items) -> Result:
    return dataclasses.replace(result, extra={**result.extra, **items})


def _ipopt_start(nlp: NLP, x0) -> dict:
    """x0, lam_x0, lam_g0 for IPOPT from any accepted warm start (module docstring)."""
    if x0 is None:
        return {}
    if isinstance(x0, Result):
        if x0.x is not None and x0.x.size == nlp.x0.size and x0.lam_g is not None \
                and x0.lam_g.size == nlp.lbg.size:
            return {"x0": x0.x, "lam_x0": x0.lam_x, "lam_g0": x0.lam_g}
    x0 = start_field(x0, nlp.disc)  # a path or a Result of another periodic grid: resampled
    if x0.size == nlp.x0.size:
        return {"x0": x0}
    if x0.size == nlp.disc.n_nodes:
        return {"x0": nlp.from_phi(x0)}
    raise InputError("x0", f"a warm start needs {nlp.disc.n_nodes} nodal values (or the NLP's "
                     f"{nlp.x0.size}), got {x0.size}")


def _phi_start(x0, disc) -> np.ndarray | None:
    """phi for the matrix-free backend from any accepted warm start: a Result, a field, or an IPOPT
    vector of a lumped NLP (phi, or phi with the penalty's two lifted unknowns)."""
    if x0 is None:
        return None
    phi = start_field(x0, disc)  # a path or a Result of another periodic grid: resampled
    n_nodes = disc.n_nodes
    if phi.size not in (n_nodes, n_nodes + 2):
        raise InputError("x0", f"a warm start needs {n_nodes} nodal values (or a lifted NLP vector of "
                         f"{n_nodes + 2}), got {phi.size}")
    return phi[:n_nodes]


def _exact_point(nlp: NLP, result: Result) -> tuple[NLP, Result]:
    """The exact-constraint NLP and the result's point on it, for the assembled second-order check:
    a lifted penalty NLP (method augmented, ``nlp.lifted``) has the exact NLP's rows shifted by its
    unknowns u, and its penalty depends on u alone, so on (phi [, w]) its Lagrangian Hessian is the
    exact NLP's at the same lam_g; the u entries are dropped."""
    if isinstance(nlp, PenaltyNLP):
        return nlp.exact, dataclasses.replace(result, x=np.asarray(result.x, float)[: nlp.n_base])
    return nlp, result


def _check_options(options, kind, backend: str):
    if options is not None and not isinstance(options, kind):
        raise NotSupported("options", f"the {backend} backend takes {kind.__name__}, got {type(options).__name__}")


def _second_order(result: Result, so, seconds: float = 0.0) -> Result:
    """The second-order keys of ``extra``, the same on both backends (``so`` None: not checked)."""
    if so is None:
        return _replace_extra(result, second_order="not checked", second_order_min_eigenvalue=None,
                              second_order_excluded=None)
    extra = {"second_order_reason": so.reason} if so.reason else {}
    extra["second_order_time_s"] = seconds
    extra["second_order_error_bound"] = so.errors[0] if so.errors else so.residual
    if so.iterations is not None:
        extra["second_order_iterations"] = so.iterations
    rot = [q for q in so.rotation_rayleigh if np.isfinite(q)]
    if rot:  # the rotations stay in the check; their least Rayleigh quotient on T beside it (mu_ref)
        extra["rotation_rayleigh"] = float(min(rot))
    if np.isfinite(getattr(so, "axial_rayleigh", float("nan"))):  # meridian mesh: the slide's quotient (mu_ref)
        extra["axial_rayleigh"] = float(so.axial_rayleigh)
    result = _replace_extra(result, second_order=so.verdict, second_order_min_eigenvalue=so.relative_min_eigenvalue,
                            second_order_excluded=so.excluded, **extra)
    if so.lowest_mode is None:
        return result
    # the critical eigenvector (M-normalised phi direction), for branch switching (vesicle_opt.branch)
    return dataclasses.replace(result, history={**result.history, "second_order_mode": so.lowest_mode})


def with_reports(result: Result, so, seconds: float = 0.0, scene: Scene | None = None) -> Result:
    """The second-order keys (``so``: a ``verdict.SecondOrder`` or None: not checked; ``seconds``: the
    check's wall time) and the topology keys every front-door result carries; for callers that run a
    backend's pieces themselves (``vesicle_opt.branch`` reuses one IPOPT solver along a branch) and
    report the same way. ``scene``: its ``solver.shape_check`` (default true) makes a wrong shape
    not converged (``verify.shape.apply``)."""
    result = _second_order(result, so, seconds)
    result = _replace_extra(result, **topology.report(result.disc, result.phi))
    result = band.apply(result)  # an interface-refined mesh: the interface still in its fine band
    # the physical shape against the targets (verify.shape)
    return shape.apply(result, enforce=True if scene is None else scene.solver.shape_check)


def solve(problem: Scene | NLP, *, backend: str | None = None, method: str | None = None, x0: np.ndarray | str | Path | Result | None = None,
          options: IpoptOptions | NewtonKrylovOptions | None = None, throw: bool = False) -> Result:
    """Minimise rigidity * E_h subject to A = alpha, B = beta (or its penalty form); see the module
    docstring. ``backend`` and ``method`` override the scene's ``solver.backend`` / ``solver.method``;
    ``options`` replaces the scene's solver settings (``IpoptOptions`` or ``NewtonKrylovOptions``).
    ``mesh.refine = "interface"``: the band is built about the start (``mesh.band_start``), and a
    result whose interface left it, or whose axial pin held a force, is solved again on a band about it
    (``band_start.REMESH_ROUNDS``)."""
    result = _solve(problem, backend, method, x0, options)
    for _ in range(band_start.REMESH_ROUNDS if isinstance(problem, Scene) else 0):
        if band_start.left_band(result):
            log.info("%s: the interface left the refined band (%.3g eps from the coarse cells): re-meshed "
                     "about it", result.scene.name, result.extra["band_margin"])
        elif band_start.held(result):
            log.info("%s: the axial pin held a force (multiplier %.3g): re-meshed about the result",
                     result.scene.name, result.extra["translation_multiplier"])
        else:
            break
        result = _solve(problem, backend, method, result, options, remesh=True)
    if throw and not result.converged:
        raise SolverError(f"not converged ({result.reason}): status {result.status}, kkt_residual "
                          f"{result.kkt_residual:.3g}, A-alpha {result.volume_residual:.3g}, "
                          f"B-beta {result.area_residual:.3g}", result)
    return result


def _solve(problem, backend, method, x0, options, remesh: bool = False) -> Result:
    """One solve of ``solve`` (its docstring), on the band about the start for a refined scene."""
    disc = None
    if isinstance(problem, NLP):
        nlp, scene = problem, problem.scene
        if backend not in (None, "ipopt"):
            raise NotSupported("solver.backend", "an NLP of build_nlp runs on 'ipopt'; pass the Scene "
                               f"for {backend!r}")
        if method not in (None, scene.solver.method):
            raise NotSupported("solver.method", f"this NLP was built for {scene.solver.method!r}; "
                               f"build it again for {method!r}")
        chosen = "ipopt"
    elif isinstance(problem, Scene):
        nlp, scene = None, problem
        if method is not None:
            if method not in METHODS:
                raise NotSupported("solver.method", f"must be one of {', '.join(METHODS)}, got {method!r}")
            scene = scene.replace(solver=dataclasses.replace(scene.solver, method=method))
        chosen = choose_backend(scene, backend)
        resources.check(scene, chosen)  # the memory estimate, before anything is built
        if band_start.refined(scene):
            disc, x0 = band_start.start(scene, x0, remesh)
    else:
        raise InputError("problem", f"solve takes a Scene (vesicle_opt.load_scene) or an NLP of build_nlp, "
                         f"got {type(problem).__name__}")
    check_second_order = scene.solver.method in EXACT_METHODS and scene.solver.second_order
    if chosen == "ipopt":
        _check_options(options, IpoptOptions, chosen)
        derivs = pin = None
        if disc is not None and scene.solver.method == "exact":  # a refined mesh: one graph and solver per mesh
            check_feasible(*constraint_data(scene, disc), scene, disc)  # before anything is logged
            opts = options or IpoptOptions.from_scene(scene)
            nlp, solver, p, start = reuse.point(scene, disc, opts, x0)
            _log_start(scene, chosen, backend, disc.n_nodes)
            with threadpool_limits(limits=REFINED_BLAS_THREADS, user_api="blas"):
                result = reuse.unpinned(solve_exact(nlp, solver=solver, options=opts, p=p, **start), nlp, opts.tol)
            derivs = reuse.derivatives(nlp, solver, p)
            pin = reuse.pin_of(p, disc.n_nodes)  # the check's T: the solve's rows, the pin's included
        else:
            nlp = nlp or build_nlp(scene, disc)  # refuses infeasible data (one line, before anything is logged)
            _log_start(scene, chosen, backend, nlp.disc.n_nodes)
            result = solve_nlp(nlp, options=options, **_ipopt_start(nlp, x0))
        # the assembled check (verify.second_order): translations excluded on periodic grids
        if check_second_order and result.converged:
            log.info("%s: second-order check (shift-invert Lanczos on the KKT matrix)", scene.name)
        t0 = time.perf_counter()
        so = (second_order.check(*_exact_point(nlp, result), derivatives=derivs, pin=pin)
              if check_second_order and result.converged else None)
    else:
        _check_options(options, NewtonKrylovOptions, chosen)
        # built once: the solve and its second-order check (lumped P1 on a periodic tensor box goes
        # to the FFT path it equals unless options.tensor_fft is False: nk.setup.fft_equivalent)
        setup = prepare(scene, disc, tensor_fft=(options or NewtonKrylovOptions.from_scene(scene)).tensor_fft)
        disc = setup[0]
        check_feasible(*constraint_data(scene, disc), scene, disc)  # before anything is logged
        _log_start(scene, chosen, backend, disc.n_nodes)
        # solver.array: the same method with numpy arrays or on JAX devices (nk_jax), same Result
        run = nk_jax.solve if scene.solver.array == "jax" else nk_solve.solve
        # solver.fft: the real FFTs of the solve and its check (scipy.fft or pyFFTW)
        with fft_library(scene.solver.fft):
            result = run(scene, x0=_phi_start(x0, disc), options=options, setup=setup, check=False)
            # the matrix-free check (verify.lobpcg), rotations excluded on grids (verdict.excludes_rotations)
            rotations = verdict.excludes_rotations(scene)
            if check_second_order and result.converged:
                log.info("%s: second-order check (matrix-free LOBPCG)", scene.name)
            t0 = time.perf_counter()
            so = (lobpcg.check(scene, result, setup, rotations=rotations)
                  if check_second_order and result.converged else None)
    result = with_reports(result, so, seconds=time.perf_counter() - t0, scene=scene)
    if result.extra.get("shape") == "bulk_offset" or (result.extra.get("shape") == "wrong_shape" and result.converged):
        log.warning("%s: %s", scene.name, result.extra["shape_reason"])
    if chosen != "ipopt" and getattr(result.disc, "fourier", None) is not None:  # which FFTs the solve ran
        lib = "jax" if scene.solver.array == "jax" else resolve_fft(scene.solver.fft)
        result = _replace_extra(result, fft_library=lib)
    return dataclasses.replace(result, scene=scene)  # for vo.write_result (its name, scene.resolved.toml)
