"""The fixed-parameter corrector of a branch on Newton-Krylov (large 3D grids), warm along the branch.

Every point of a branch is the exact-constraint problem (6)-(8) of the same mesh with other targets
(alpha, beta) or another C = sqrt(2) c0. ``NewtonKrylovCorrector`` runs each point as the front door
does on ``backend="newton-krylov"`` (``nk.solve`` with method ``exact``, the common certificate of
``verify.certify``, the matrix-free second-order check of ``verify.lobpcg`` with the rotations
excluded on Fourier grids, the topology, the FFT library of ``solver.fft``), with what the previous
point of the same branch knows:

* the backend's setup (``nk.setup.prepare``: operators, preconditioner, translations) built once
  (again only where C changes: the parameter c0);
* the solve starts from the predictor with the predicted multipliers (``branch.run``: linear in p
  through the last two accepted points) and the previous point's dual model (W, rho) of the
  augmented Lagrangian's dual Newton step (``nk.solve``'s ``warm``), so that the two W solves
  (two CG solves of H_rho^{-1} [dA, dB]) are not redone unless |c| stops falling;
* the second-order check's coarsest level starts from the previous point's eigenvectors on that
  level (``verify.lobpcg`` ``warm``) instead of the random-mixed interface block, the finer levels
  from the interpolated coarser ones as in the cold check. Measured (prolate, 108 x 48 x 48, eps =
  0.14, v = 0.6955, load ~2): cold coarsest level 44 x 20 x 20 300 iterations (1.1 s, its cap:
  the nearly degenerate least pair settles slowly from a random start), warm 26 (0.1 s); check
  2.7 s cold, 1.4-1.8 s warm, mu_min the same to 1e-8 (error bound 3.5e-3). Starting the fine
  level from the previous point's fine eigenvectors instead took 29 iterations (3.1 s) against 6
  from the interpolated coarse ones: the eigenvectors move more between points than the coarse
  level's discretisation error.

Measured per warm point (solve + check, median of 5 points, CPU seconds; two runs each, before
(the front door per point) and after interleaved, load 3-5 on 2 cores; script: the branch of the
study's cases with the corrector wrapped): prolate 108 x 48 x 48 (eps = 0.14, ~64^3 nodes) 8.6,
8.8 -> 6.8, 7.0 s (check wall 3.4, 2.9 -> 2.2, 2.0 s; the CG count per solve about the same,
218-329 against 220-368: most of the solve is the Newton-CG work itself); oblate 72 x 72 x 36
(eps = 0.14) 3.6, 3.6 -> 2.4, 2.4 s (CG 116-218 -> 77-178); prolate 90 x 36 x 36 (eps = 0.2) 2.7,
2.6 -> 2.1, 1.95 s. Tried and dropped: a looser first inner tolerance (1e-2: 9 Newton steps and
260 CG against 7 and 215; 1e-3: no change), restoring the constraints of the prediction first
(11 Newton steps against 10); the dual model's CG solves to 1e-2 instead of 1e-4 (cold point 29 ->
25 Newton steps, 717 -> 456 CG, but warm points 8-10 Newton steps against 6-9 and no faster: the
median warm point 6.0 against 5.7 s); W corrected by a symmetric secant (Broyden) update from each
outer step and moved with rho (as many W refreshes, 4 in 4 points, CG 417/226/215/142 against
308/218/251/329: the last outer steps' (dlam, dc) are inner-solve noise). Not wasted: the 2-3 CG
Newton step after a multiplier update (it cuts the dual residual ~700x, 4.9e-3 -> 7.3e-6).

A warm check is kept only where its verdict is decided and equals the previous point's; else the
point is checked again cold (``second_order_warm`` in extra says which was reported): every
stability change is found by the cold check, as it would be without the warm start. A warm start
cannot bring in a mode that is absent from the previous block (the cold start mixes random columns
for that, ``verify.lobpcg``); a mode falling below the least one from outside the block without a
verdict change goes unseen until a cold check, which ``COLD_EVERY`` bounds.

Step control: ``branch.run`` gives the walk ``TARGET_ITERATIONS`` as its target where the corrector
is Newton-Krylov; the count is Newton steps, of which a warm point needs ~6 at any step size.
Measured (prolate 108 x 48 x 48, eps = 0.14, v 0.75 -> 0.575, the study's step 0.025): 20 -> 16
points (steady step in v 0.0075-0.008 -> 0.010-0.011; every point a certified minimum, the last
one's reduced energy the same to 6e-9), the warm point's cost unchanged (median 5.64 against 5.66 s
over 9 points, interleaved, load ~1-1.5); prolate 90 x 36 x 36 (eps = 0.2): 10 -> 9 points.

A resumed branch (``branch.store``) starts its first point after the resume without the dual model
and with a cold check: the same point to the certificate's tolerance, other iteration counts.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from vesicle_opt import resources
from vesicle_opt.api import with_reports
from vesicle_opt.branch.corrector import axial_slide, slide_modulo
from vesicle_opt.branch.events import spectrum_extra
from vesicle_opt.errors import NotSupported
from vesicle_opt.mesh.spectral import fft_library, resolve_fft
from vesicle_opt.model.feasibility import check_feasible
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.nk import solve as nk_solve
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.nk.setup import discretization_path, prepare
from vesicle_opt.nk.solve import l2_floor
from vesicle_opt.result import Result
from vesicle_opt.scene.schema import Scene
from vesicle_opt.verify import lobpcg, verdict
from vesicle_opt.verify.certify import build_result

TARGET_ITERATIONS = 8  # the Newton steps a point's step control aims at on this corrector (``branch.run``;
# IPOPT's 6 is ``arclength.Settings``): the median of the converged warm points of the ~64^3 prolate
# (108 x 48 x 48, eps = 0.14: 12, 8, 8, 9, 7). A warm point takes >= 6 whatever the step (the exact
# loop's 3-4 outer iterations of 1-2 steps: the oblate 72 x 72 x 36 at a fixed step 6, 6, 6, 6), so on
# IPOPT's target the prolate's step in v fell from 0.025 to 0.0075-0.008 (module docstring)
COLD_EVERY = 8  # every 8th check of a branch is cold even where the warm one agrees: a mode from
# outside the warm block is found within 8 points (module docstring); the rest cost ~0.6x a cold one


@dataclass
class _Warm:
    """What one branch's last converged point leaves for the next."""

    dual_model: tuple | None = None  # (W, rho) of nk.solve's last dual Newton step
    levels: dict | None = None  # {coarse shape: eigenvector rows} of its second-order check
    verdict: str | None = None
    since_cold: int = 0  # warm checks since the last cold one


class NewtonKrylovCorrector:
    """The certified, second-order checked point of any p of a branch of ``scene`` (module docstring)."""

    def __init__(self, scene: Scene, options: NewtonKrylovOptions | None = None):
        if options is not None and not isinstance(options, NewtonKrylovOptions):  # as the front door
            raise NotSupported("options", f"the newton-krylov backend takes NewtonKrylovOptions, got "
                               f"{type(options).__name__}")
        self.scene = scene.replace(solver=dataclasses.replace(scene.solver, method="exact"))
        self.options = options or NewtonKrylovOptions.from_scene(self.scene)
        resources.check(self.scene, "newton-krylov")  # the memory estimate, once: the mesh is the branch's
        self.rotations = verdict.excludes_rotations(self.scene)  # as the front door
        self._setup: tuple[float | None, object] = (None, None)  # (C, nk.setup.prepare of it)
        self.warm: dict[int, _Warm] = {}  # branch id -> its last converged point's data

    def setup(self, scene: Scene):
        C, setup = self._setup
        if setup is None or C != scene.model.C:  # PhaseField holds C: rebuilt where c0 moves
            setup = prepare(scene, tensor_fft=self.options.tensor_fft)
            self._setup = (scene.model.C, setup)
        return setup

    def solve(self, scene: Scene, phi0: np.ndarray | None, lam0: tuple[float, float] | None = None,
              branch: int = 0, max_iter: int | None = None) -> Result:
        """The point of ``scene`` (a point scene of the branch) from the field ``phi0`` (None: the
        scene's own start, nested iteration, as the front door) and the predicted multipliers
        ``lam0`` (physical; None: least squares at ``phi0``), with the previous point of ``branch``
        as the warm start. Infeasible targets raise InputError before any solve. ``max_iter``: a
        Newton budget below the options' (the certification of a point already converged,
        ``branch.nk_free``)."""
        scene = scene.replace(solver=dataclasses.replace(scene.solver, method="exact"))
        setup = self.setup(scene)
        disc = setup[0]
        check_feasible(*constraint_data(scene, disc), scene, disc)
        prev = self.warm.setdefault(branch, _Warm())
        warm = None if phi0 is None else (lam0, prev.dual_model)
        with fft_library(scene.solver.fft):
            opts = self.options if max_iter is None else dataclasses.replace(self.options, max_iter=max_iter)
            res = nk_solve.solve(scene, x0=phi0, options=opts, setup=setup, check=False, warm=warm)
        if res.converged and res.history.get("dual_model") is not None:
            prev.dual_model = res.history["dual_model"]
        return self.reported(scene, res, setup, prev)

    def certify(self, scene: Scene, phi: np.ndarray, lam, branch: int = 0, iterations: int = 0) -> Result:
        """The common certificate (``verify.certify.build_result``), the second-order check and the
        reports of a point a p-free Newton converged to (``branch.nk_free``), without a fixed-p solve:
        on a meridian mesh, where that Newton held the axial pin (``branch.bordered.axial_pin``) and the
        fixed-p solve, which cannot hold it, slides (module docstring of ``branch.nk_free``). The
        certificate recomputes stationarity without the pin, as the IPOPT corrector's does."""
        scene = scene.replace(solver=dataclasses.replace(scene.solver, method="exact"))
        setup = self.setup(scene)
        disc, pf = setup[0], setup[1]
        alpha, beta = constraint_data(scene, disc)
        phi = np.asarray(phi, float)
        st = pf.state(phi)
        grads = pf.gradients(st)
        lam = tuple(float(v) for v in lam)
        rig, eps = scene.model.rigidity, scene.model.epsilon
        res = build_result(scene=scene, disc=disc, alpha=alpha, beta=beta, phi=phi, tol=self.options.tol,
                           solver_status="converged", solver_success=True, method="exact", lam=lam,
                           exact_constraints=True, floor=l2_floor(disc, rig, eps, grads, lam), iterations=iterations,
                           extra={"backend": "newton-krylov", "mesh_kind": disc.kind,
                                  "discretization_path": discretization_path(scene, disc, setup[2])})
        return self.reported(scene, res, setup, self.warm.setdefault(branch, _Warm()))

    def reported(self, scene: Scene, res: Result, setup, prev: _Warm) -> Result:
        """``res`` with the second-order check (``check``, warm from ``prev``), the topology and the
        branch's spectrum keys, as ``solve`` reports a point."""
        so, used, t0 = None, None, time.perf_counter()
        if scene.solver.second_order and res.converged:
            with fft_library(scene.solver.fft):
                so, used = self.check(scene, res, setup, prev)
        res = with_reports(res, so, seconds=time.perf_counter() - t0, scene=scene)
        extra = {**res.extra, "fft_library": resolve_fft(scene.solver.fft)}
        if used is not None:
            extra["second_order_warm"] = used
        if so is not None:
            extra.update(spectrum_extra(so))
        return dataclasses.replace(res, extra=extra)

    def check(self, scene: Scene, res: Result, setup, prev: _Warm):
        """(SecondOrder, warm used): warm from ``prev`` where that applies and agrees (module
        docstring), else cold; ``prev`` then holds this point's levels and verdict. On a meridian mesh
        the axial slide is excluded (``branch.corrector.slide_modulo``)."""
        slide = getattr(setup[0], "axisymmetric", False)
        if slide:
            setup = (*setup[:3], axial_slide(setup[0]))
        so, used = self._check(scene, res, setup, prev)
        return (slide_modulo(so) if slide else so), used

    def _check(self, scene: Scene, res: Result, setup, prev: _Warm):
        if prev.levels and prev.verdict not in (None, "not checked") and prev.since_cold + 1 < COLD_EVERY:
            so, levels = lobpcg.check_levels(scene, res, setup, self.rotations, warm=prev.levels)
            if so.verdict == prev.verdict:
                prev.levels, prev.since_cold = levels, prev.since_cold + 1
                return so, True
        so, levels = lobpcg.check_levels(scene, res, setup, self.rotations)
        prev.levels, prev.verdict, prev.since_cold = levels, so.verdict, 0
        return so, False
