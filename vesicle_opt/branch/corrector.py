"""The fixed-parameter corrector of a branch on IPOPT, built once per branch.

Every point of a branch is the exact-constraint problem (6)-(8) of the same mesh with other targets
(alpha, beta) or another C = sqrt(2) c0. ``IpoptCorrector`` builds what does not change once:

* one parametric CasADi NLP (``nlp.exact.build_exact(parametric=True)``: p = (alpha, beta, C,
  f_scale), the scaling contract of ``nlp.exact`` evaluated at each point's targets, so each solve
  is the NLP the front door would build for that point) and one IPOPT solver on it;
* the Fourier-grid operators of the matrix-free second-order check (``verify.lobpcg``).

Per point: IPOPT warm-started at the predicted field with the predicted multipliers
(``ipopt.warm_start_init_point``; the start, with no prediction, cold as the front door); on 2D FD
grids the warm solves hold the orientation of the prediction by one linear row (``pinned``,
``rotation_row``): below nu ~ 0.66 the grid-aligned 128^2 elastica is a saddle of the discrete
problem along the grid-broken rotation (Rayleigh quotient -2e-4 ... -6e-4 mu_ref), and IPOPT, a
minimiser, then wandered at a few points (measured nu 0.58 - 0.51: 6-60 iterations without
convergence, warm or cold, from the prediction or the last point; pinned: 2-3 iterations at all of
them). The row's multiplier vanishes at shapes symmetric under the axis reflections, and the
certificate recomputes stationarity without it (``rotation_multiplier`` in extra). On meridian
meshes every solve (warm and cold) holds the axial pin instead (``branch.bordered.axial_pin``: the
inside's centre of mass at the prediction's, the front door's pin row of ``nlp.reuse``;
``translation_multiplier`` in extra): unpinned, the stomatocyte's warm solves stalled along the
near-null slide and its branch did not leave its start (measured, ``tests/branch/test_stomatocyte_fold.py``). Then the
common certificate (``verify.certify``, inside
``nlp.solve.solve_exact``), then the second-order check and the topology, reported exactly as the
front door reports them (``api.with_reports``).

Second-order check: the matrix-free check wherever it applies (lumped mass and nodal quadrature):
on FD grids it excludes the translations *and the rotation* (the infinitesimal rotation
(x - x_c) d_y phi - (y - y_c) d_x phi, spectral derivatives; about any centre x_c, since the
translations are excluded too), the rule of the front door's matrix-free path. The FD grid breaks
the rotation symmetry only weakly: kept, its soft mode (~2e-3 mu_ref) is the least eigenvalue of
the assembled check and changes sign along the 2D elastica branch near nu ~ 0.70 (a grid effect,
not a fold). Elsewhere (consistent mass, Gauss quadrature) the assembled check of the front door
(translations only). Meridian meshes (``mesh.kind = "axisymmetric"``) take the assembled check too,
with the IPOPT solver's own Hessian and Jacobian (``nlp.reuse.derivatives``) and the axial slide
excluded (``slide_row``: T held M-orthogonal to d_z phi; the front door keeps it and names it). The
slide is a near-null mode (+-1e-5 mu_ref) whose sign needs resolving, which the matrix-free check's
LOBPCG did not resolve within its cap on the stomatocyte walks' 8.9-17 k-node meshes ("not checked"
at every walked point, the seed's front-door check "minimum"); the shift-invert Lanczos resolves it
to ~1e-9 mu_ref at any size. Measured at 128^2 (FD, eps = 0.2): assembled 2.5 s, matrix-free 0.17 s per point,
the same eigenvalues to 1e-9 mu_ref (``tests/branch/test_corrector.py`` ties them).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from vesicle_opt.api import with_reports
from vesicle_opt.backends import supports
from vesicle_opt.branch.bordered import axial_pin
from vesicle_opt.branch.events import spectrum_extra
from vesicle_opt.mesh import discretize
from vesicle_opt.mesh.spectral import FourierGrid, fft_library
from vesicle_opt.model import functionals as F
from vesicle_opt.model.feasibility import check_feasible
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.nk.setup import on_fourier_grid, prepare
from vesicle_opt.nlp import IpoptOptions, build_nlp
from vesicle_opt.nlp.exact import at_point, build_exact, parameter_values
from vesicle_opt.nlp.ipopt import make_solver
from vesicle_opt.nlp.reuse import derivatives
from vesicle_opt.nlp.solve import solve_exact
from vesicle_opt.result import Result
from vesicle_opt.scene.schema import Scene
from vesicle_opt.verify import lobpcg, second_order
from vesicle_opt.verify import verdict as V
from vesicle_opt.verify.verdict import SecondOrder

WARM = (("ipopt.warm_start_init_point", "yes"),)  # IPOPT takes the given multipliers (cold, it would
# replace them by its least-squares estimate); no bounds, no inequalities: nothing else to warm
WARM_MAX_ITER = 6  # a warm-started point takes 2-4 IPOPT iterations (measured, 128^2 elastica); one
# that needs more is cut here and handed to the Newton fallback (``branch.run``)


def least_squares_multipliers(scene: Scene, disc, phi: np.ndarray) -> tuple[float, float]:
    """argmin |rigidity dE - lambda_A dA - lambda_B dB| at phi (hand gradients, ``functionals``): the
    estimate IPOPT starts from when cold (``constr_mult_init``), for starts with no prediction."""
    dE, dA, dB = F.gradients(disc, np.asarray(phi, float), scene.model.epsilon, scene.model.C)
    lam, *_ = np.linalg.lstsq(np.column_stack([dA, dB]), scene.model.rigidity * dE, rcond=None)
    return float(lam[0]), float(lam[1])


def rotation_row(disc, phi: np.ndarray) -> np.ndarray:
    """c with c . phi = <r, phi>_w / sqrt|Omega|, r the infinitesimal rotation about the centroid of
    {phi > 0}, (x - x_c) d_y phi - (y - y_c) d_x phi (spectral derivatives), normalised |r|_w = 1:
    the row c . (phi - phi0) = 0 of the warm solves holds the shape's orientation at the
    prediction's (a relative change, so IPOPT's constraint tolerance means the same at any size)."""
    dx, dy = FourierGrid(disc.box, disc.grid_shape).derivatives(phi)
    w = disc.weights
    inside = w * (1 + phi) / 2
    xc = (inside @ disc.nodes) / inside.sum()
    r = (disc.nodes[:, 0] - xc[0]) * dy - (disc.nodes[:, 1] - xc[1]) * dx
    return w * r / np.sqrt(w @ (r * r)) / np.sqrt(disc.volume)


def pinned(nlp):
    """The parametric NLP with one more linear row c . x - d = 0, (c, d) appended to its parameters
    (``rotation_row``). At a shape symmetric under the reflections of the axes its multiplier is
    zero (the Lagrangian's gradient is even, the rotation odd): the point is a KKT point of the
    unpinned problem, and the certificate, which recomputes stationarity without that row, says so
    (a nonzero multiplier would show as kkt_residual, and the point would not be certified)."""
    import casadi as ca  # third-party, lazy: only the IPOPT path builds graphs (0.25 s at import)
    n = nlp.disc.n_nodes
    c, d = ca.MX.sym("rotation", n), ca.MX.sym("rotation_at", 1)
    return dataclasses.replace(nlp, g=ca.vertcat(nlp.g, ca.dot(c, nlp.x[:n]) - d), p=ca.vertcat(nlp.p, c, d),
                               lbg=np.zeros(nlp.lbg.size + 1), ubg=np.zeros(nlp.ubg.size + 1))


class IpoptCorrector:
    """The exact-constraint solve of any point of a branch of ``scene`` (module docstring)."""

    def __init__(self, scene: Scene, options: IpoptOptions | None = None):
        self.scene = scene.replace(solver=dataclasses.replace(scene.solver, method="exact"))
        self.disc = discretize(self.scene)
        self.nlp = build_exact(self.scene, self.disc, check=False, parametric=True)
        self.cold_options = options or IpoptOptions.from_scene(self.scene)
        self.options = dataclasses.replace(self.cold_options, max_iter=min(WARM_MAX_ITER, self.cold_options.max_iter),
                                           extra=WARM + tuple(self.cold_options.extra))
        # FD grids: the warm solves hold the rotation (``rotation_row``); meridian meshes the axial slide
        # (``axial_pin``); elsewhere none is near-null
        self.slide = bool(getattr(self.disc, "axisymmetric", False))
        self.pin = self.slide or (self.disc.kind == "fd" and self.disc.grid_shape is not None and self.disc.dim == 2
                                  and not self.disc.consistent)
        self.warm_nlp = pinned(self.nlp) if self.pin else self.nlp
        self.solver = make_solver(self.warm_nlp, self.options)
        self._cold = None  # the cold solver (the scene's max_iter, IPOPT's own multipliers): on demand
        self.matrix_free = supports(self.scene, "newton-krylov")
        self.fourier = on_fourier_grid(self.disc) if self.matrix_free else None

    def solve(self, scene: Scene, phi0: np.ndarray, lam0: tuple[float, float] | None = None,
              feasibility: bool = True) -> Result:
        """The certified, second-order checked point of ``scene`` (a point scene of the branch:
        same mesh, other constraints or c0) from the field ``phi0`` and multipliers ``lam0``
        (physical): warm, at most ``WARM_MAX_ITER`` iterations; ``lam0`` None: cold, with IPOPT's
        own multipliers and the scene's max_iter, as the front door starts. ``feasibility``: refuse
        infeasible targets (InputError) first."""
        scene = scene.replace(solver=dataclasses.replace(scene.solver, method="exact"))
        alpha, beta = constraint_data(scene, self.disc)
        if feasibility:
            check_feasible(alpha, beta, scene, self.disc)
        nlp = at_point(self.nlp, scene, alpha, beta)
        p = parameter_values(scene, self.disc, alpha, beta)
        if lam0 is None:  # no prediction (the start): cold, as the front door starts
            return self.reports(scene, nlp, self._cold_solve(nlp, phi0, p))
        phi0 = np.asarray(phi0, float)
        if self.pin:  # the rotation row or the axial pin: its multiplier starts at 0 (module docstring)
            nlp = at_point(self.warm_nlp, scene, alpha, beta)
            p = self._pinned(p, phi0)
        lam_g0 = -np.asarray(lam0, float) * nlp.g_scale / nlp.f_scale  # inverse of NLP.multipliers
        if nlp.lbg.size > 2:  # the consistent-mass rows M w + K phi = 0 or the rotation row: start at 0
            lam_g0 = np.concatenate([lam_g0, np.zeros(nlp.lbg.size - 2)])
        res = solve_exact(nlp, x0=nlp.from_phi(phi0), lam_g0=lam_g0, solver=self.solver,
                          options=self.options, p=p)
        return self.reports(scene, nlp, self._unpinned(res) if self.pin else res)

    def _pinned(self, p: np.ndarray, phi0: np.ndarray) -> np.ndarray:
        """The pinned NLP's parameters: the point's ``p``, then the row c (the axial pin on a meridian
        mesh, else the rotation row at ``phi0``) and its value c . phi0 (held at the start's)."""
        c = axial_pin(self.disc) if self.slide else rotation_row(self.disc, phi0)
        return np.concatenate([p, c, [c @ phi0]])

    def _unpinned(self, res: Result) -> Result:
        """A pinned solve's result in the unpinned NLP's layout, as the front door's; the row's
        multiplier (IPOPT's scaled units) in extra, for the record."""
        key = "translation_multiplier" if self.slide else "rotation_multiplier"
        return dataclasses.replace(res, lam_g=res.lam_g[:-1], extra={**res.extra, key: float(res.lam_g[-1])})

    def _cold_solve(self, nlp, phi0, p) -> Result:
        """The cold solve; on a meridian mesh pinned as the warm ones (``axial_pin``, at the start's
        centre of mass): unpinned, the stomatocyte's cold start from the sharp shape's tanh profile at
        eps 0.1 (uniform, h = eps / 2) ran to 500 IPOPT iterations, sliding (measured)."""
        phi0 = np.asarray(phi0, float)
        if self._cold is None:
            self._cold = make_solver(self.warm_nlp if self.slide else self.nlp, self.cold_options)
        if not self.slide:
            return solve_exact(nlp, x0=nlp.from_phi(phi0), solver=self._cold, options=self.cold_options, p=p)
        nlp = at_point(self.warm_nlp, nlp.scene, nlp.alpha, nlp.beta)
        return self._unpinned(solve_exact(nlp, x0=nlp.from_phi(phi0), solver=self._cold,
                                          options=self.cold_options, p=self._pinned(p, phi0)))

    def reports(self, scene: Scene, nlp, res: Result) -> Result:
        """``res`` with the second-order and topology reports of the front door (module docstring)."""
        so, t0 = None, time.perf_counter()
        if scene.solver.second_order and res.converged:
            if getattr(self.disc, "axisymmetric", False):  # the assembled check with the solver's own derivatives
                p = parameter_values(scene, self.disc, nlp.alpha, nlp.beta)
                if self.slide or (self._cold is None and self.pin):  # the pinned solver's parameters: the row (linear) enters
                    p = np.concatenate([p, np.zeros(self.disc.n_nodes + 1)])  # neither H nor dA, dB
                so = second_order.check(nlp, res, derivatives=derivatives(nlp, self._cold or self.solver, p),
                                        pin=slide_row(self.disc, res.phi))
                so = dataclasses.replace(so, reason=so.reason.replace(V.PINNED, SLIDE_EXCLUDED))
            elif self.matrix_free:  # with the FFTs the front door's check uses (solver.fft)
                with fft_library(scene.solver.fft):
                    setup = prepare(scene, self.fourier)
                    so = rotation_modulo(lobpcg.check(scene, res, setup, rotations=V.excludes_rotations(scene)),
                                         scene.dim)
            else:  # the front door's assembled check on the point's own (constant) NLP
                so = second_order.check(build_nlp(scene, self.disc, check=False), res)
        res = with_reports(res, so, seconds=time.perf_counter() - t0, scene=scene)
        if so is not None:  # the least few, for the branch's index (``branch.events``)
            res = dataclasses.replace(res, extra={**res.extra, **spectrum_extra(so)})
        if so is not None and so.excluded == V.TRANSLATIONS_ROTATIONS:
            res = dataclasses.replace(res, extra={**res.extra, "rotation_rayleigh": min(so.excluded_rayleigh[scene.dim:])})
        return res


SLIDE_EXCLUDED = ("axial slide excluded (T held M-orthogonal to d_z phi: the slide between the natural end "
                  "walls is near-null, +-1e-5 mu_ref, and its sign flips along a branch are no stability change)")


def slide_row(disc, phi) -> np.ndarray:
    """The row M d_z phi (lumped weights) whose kernel is T's part M-orthogonal to the axial slide: the
    assembled check's ``pin`` on a meridian mesh, so that a branch's verdict excludes the slide as
    ``slide_modulo`` does on the matrix-free path (the walks' sign flips of the near-null slide were
    read as stability changes: ``tests/branch/test_meridian_slide.py``)."""
    from vesicle_opt.mesh.axisymmetric import axial_translation  # scikit-fem: meridian meshes only
    return np.asarray(disc.weights, float) * axial_translation(disc, phi)


def axial_slide(disc):
    """The ``translations`` of ``nk.setup.prepare`` for a meridian mesh's check: the axial slide
    d_z phi (``mesh.axisymmetric.axial_translation``) as the one excluded mode (``slide_modulo``)."""
    from vesicle_opt.mesh.axisymmetric import axial_translation  # scikit-fem: meridian meshes only

    def slide(phi, scale: float = 1.0, coordinates: bool = False):
        return None if coordinates else (scale * axial_translation(disc, phi))[:, None]
    return slide


def slide_modulo(so: SecondOrder) -> SecondOrder:
    """A branch's verdict on a meridian mesh with the axial slide excluded (d_z phi projected out of
    the check, ``axial_slide``), as the front door's refined solve excludes it by its pin
    (``nlp.reuse``): between the natural end walls the slide is near-null (+-1e-5 mu_ref), and kept
    it is the least eigenvalue of every point, whose sign flips along a branch are no stability
    change (measured: the eps = 0.03 oblate, v 0.62 -> 0.59, +6.6e-5 -> -6.5e-5 mu_ref); the
    shape's own least mode is then the branch's critical one (by interlacing between the kept
    check's first and second eigenvalues; ``tests/branch/test_meridian_slide.py``). The verdict is
    classified without the projected direction's Rayleigh quotient (O(1): the averaged nodal d_z phi
    is close to, not exactly, the discrete slide), which stays as ``axial_rayleigh``."""
    if not so.errors or len(so.excluded_rayleigh) != 1:
        return so
    verdict, reason = V.classify(so.relative_min_eigenvalue, so.errors[0], ())
    note = f"axial slide excluded (d_z phi projected out, its Rayleigh quotient {so.excluded_rayleigh[0]:.3g} mu_ref)"
    return dataclasses.replace(so, verdict=verdict, reason="; ".join(x for x in (reason, note) if x),
                               axial_rayleigh=float(so.excluded_rayleigh[0]))


def rotation_modulo(so: SecondOrder, dim: int) -> SecondOrder:
    """The verdict with the rotations removed as the translations are: from the least eigenvalue
    on T minus all symmetry modes and the translations' Rayleigh quotients, not the rotations'
    (``verdict.classify`` counts every excluded mode's; on a grid the rotation's quotient is a
    soft +-2e-3 mu_ref whose sign is a grid effect, module docstring). The rotations' quotients
    stay in ``excluded_rayleigh`` (the branch's column ``rotation_rayleigh``)."""
    if so.excluded != V.TRANSLATIONS_ROTATIONS or not so.errors:
        return so
    verdict, reason = V.classify(so.relative_min_eigenvalue, so.errors[0], so.excluded_rayleigh[:dim])
    return dataclasses.replace(so, verdict=verdict, reason=reason)
