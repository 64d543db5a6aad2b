"""The vesicle problem of a diagram: the correctors of ``branch.corrector`` (IPOPT),
``branch.nk_corrector`` (Newton-Krylov) and ``branch.bordered`` (p free) behind ``branch.tree``'s
interface (``branch.problem``), the rows of ``branch.store``.

Per point (``row``): the certificate, the second-order verdict and its least few eigenvalues, the
envelope identity's ``dE_dp`` and ``envelope_residual`` (``branch.run`` docstring). For the tree:

* ``solve(p, phi0, lam0)``: the certified point at fixed p, warm (the location of a branch point,
  the fixed-p switch); ``free``: the point with p free on a hyperplane (IPOPT with lumped mass:
  ``branch.bordered``; Newton-Krylov: ``branch.nk_free``, which also makes every fixed-p point there);
* ``mode(point, m)``: the m-th eigenvector of the reduced Hessian at a point (``verify.lobpcg``'s
  matrix-free spectrum with its vectors; the check's own least mode for m = 0 elsewhere);
* ``align(phi, ref)``: on periodic grids the image of phi under translations (the peak of the FFT
  cross-correlation) and, on square 2D grids, the square's rotations and reflections nearest ref; on
  mirror grids the exchanges of axes of equal extent and spacing (the octant's x <-> y);
* ``deflate(p, phi0, known)``: ``branch.deflation`` on the bordered Newton system at fixed p,
  its root certified by the fixed-p IPOPT solve.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Callable

import numpy as np

from vesicle_opt.api import solve
from vesicle_opt.backends import choose_backend, supports
from vesicle_opt.branch import arclength as arc
from vesicle_opt.branch.bordered import Affine, BorderedCorrector
from vesicle_opt.branch.corrector import IpoptCorrector, least_squares_multipliers
from vesicle_opt.branch.deflation import deflated_vesicle
from vesicle_opt.branch.events import Point, sign
from vesicle_opt.branch.nk_corrector import NewtonKrylovCorrector
from vesicle_opt.branch.nk_free import CERTIFY_MAX_ITER, VesicleKKT, free_newton
from vesicle_opt.branch.nk_free import tangent as nk_tangent
from vesicle_opt.branch.params import Parameter, explicit_derivative
from vesicle_opt.branch.problem import TreeProblem, split
from vesicle_opt.branch.store import Store
from vesicle_opt.branch.symmetry import align as symmetric_image
from vesicle_opt.branch.symmetry import align_mirror
from vesicle_opt.errors import InputError
from vesicle_opt.mesh import discretize
from vesicle_opt.mesh.cosine import KIND as MIRROR
from vesicle_opt.model.problem import initial_guess
from vesicle_opt.nk.setup import prepare
from vesicle_opt.scene.schema import Scene
from vesicle_opt.verify import lobpcg
from vesicle_opt.verify import verdict as V
from vesicle_opt.verify.failure import tol_to_certify


def _least_sign(mu, errors) -> int:
    """The certified sign (``events.sign``) of a row's least eigenvalue, its bound the first of
    ``errors`` (a tuple, or the CSV's ';'-joined text); a row without bounds: 0 (as the assembled
    check's ~1e-11 would give)."""
    first = split(errors)[:1] if isinstance(errors, str) or errors is None else tuple(errors)[:1]
    return sign(mu, first[0] if first else 0.0)


class VesicleProblem(TreeProblem):
    """The branches of one scene: the correctors, the rows, the store (module docstring)."""

    def __init__(self, scene, par: Parameter, settings, store: Store, backend, options, reference, progress):
        self.scene, self.par, self.s, self.store = scene, par, settings, store
        self.backend, self.options, self.reference, self.progress = backend, options, reference, progress
        self.weights = discretize(scene).weights
        # on IPOPT the NLP, its solver and the check's operators are built once (branch.corrector);
        # on Newton-Krylov (numpy arrays) the setup, warm from point to point (branch.nk_corrector)
        chosen = choose_backend(scene, backend)
        self.ipopt = IpoptCorrector(scene, options) if chosen == "ipopt" else None
        self.nk = NewtonKrylovCorrector(scene, options) if chosen == "newton-krylov" and \
            scene.solver.array != "jax" else None
        self._bordered = None  # branch.bordered, built when the walk first nears a fold (IPOPT, lumped)
        self._kkt = None  # branch.nk_free's model, built when first needed (Newton-Krylov)
        self.start, self.param = par.start, par.name
        self.disc = self.ipopt.disc if self.ipopt is not None else discretize(scene)

    def free_corrector(self, branch: int) -> Callable | None:
        """The corrector with p free (``branch.bordered``, then the fixed-p IPOPT solve at the p
        found, which certifies the point); None where it does not apply (Newton-Krylov backend,
        consistent mass): the walk then uses its scalar iteration (``branch.arclength``). On
        Newton-Krylov (numpy arrays): ``branch.nk_free``, then the fixed-p Newton-Krylov solve at
        the p found, which certifies the point."""
        if self.nk is not None:
            return self.nk_free_corrector(branch)
        if self.ipopt is None or self.ipopt.disc.consistent:
            return None

        def free(phi_pred, p_pred, t_phi, t_p, theta):
            t0 = time.perf_counter()
            lam = None if branch is None else self.multipliers(branch, p_pred)
            if lam is None:
                lam = least_squares_multipliers(self.scene, self.ipopt.disc, phi_pred)
            nw = self.bordered().solve(phi_pred, p_pred, lam, t_phi, t_p, theta)
            if not nw.converged or (self.par.name == "reduced_volume" and not 0 < nw.p <= 1):
                why = nw.message or f"reduced_volume {nw.p:.6g} outside (0, 1]"
                return arc.Attempt(nw.p, phi_pred, False, nw.iterations,
                                   (None, f"bordered Newton: {why}", time.perf_counter() - t0, None))
            res = self.ipopt.solve(self.par.scene_at(self.scene, nw.p), nw.phi, nw.lam, feasibility=False)
            # the step control reads the larger of the two counts, not their sum: IPOPT's certifying solve
            # from a converged Newton point takes a count of its own that the step does not change (at eps
            # 0.04: 6 in all at the steady step, which the sum held at the target, and the walk crept to
            # the cup's fold in 82 points, against 36 with the larger count)
            return arc.Attempt(nw.p, res.phi, res.converged, nw.iterations + res.iterations,
                               (res, None, time.perf_counter() - t0, False),
                               control=max(nw.iterations, res.iterations))
        return free

    def kkt(self) -> VesicleKKT:
        """The Newton-Krylov bordered model of the branch (``branch.nk_free``), built once."""
        if self._kkt is None:
            a, b, c = self.par.affine(self.scene)
            self._kkt = VesicleKKT(self.nk.setup(self.scene), self.nk.scene, Affine(a, b, c))
        return self._kkt

    def nk_free_corrector(self, branch: int | None) -> Callable:
        """p free on Newton-Krylov (``branch.nk_free``): the bordered Newton-GMRES point, then
        ``NewtonKrylovCorrector.solve`` at its own p from it (the certificate, the check); the
        iterations are Newton steps of both, the GMRES counts in the Result's extra."""
        def free(phi_pred, p_pred, t_phi, t_p, theta, start=None):
            t0 = time.perf_counter()
            lam = None if branch is None else self.multipliers(branch, p_pred)
            return self.nk_newton_point(branch, phi_pred, p_pred, lam, t_phi, t_p, theta, t0, start)
        return free

    def nk_newton_point(self, branch, phi0, p0, lam, t_phi, t_p, theta, t0, start=None) -> arc.Attempt:
        """The bordered Newton-Krylov point from (phi0, p0, lam) on the hyperplane, certified at its p
        (Newton from ``start`` where given: ``arclength.Settings.predict``)."""
        if lam is None:
            lam = least_squares_multipliers(self.par.scene_at(self.scene, p0), self.disc, phi0)
        nw = free_newton(self.kkt(), phi0, lam, p0, t_phi, t_p, theta, self.nk.options.tol, start=start)
        if not nw.converged or (self.par.name == "reduced_volume" and not 0 < nw.p <= 1):
            why = nw.message or f"reduced_volume {nw.p:.6g} outside (0, 1]"
            return arc.Attempt(nw.p, phi0, False, nw.iterations,
                               (None, f"bordered Newton-Krylov: {why}", time.perf_counter() - t0, None))
        try:
            sc = self.par.scene_at(self.scene, nw.p)
            if getattr(self.disc, "axisymmetric", False):  # the pin held: certified as it stands (``nk_free``)
                res = self.nk.certify(sc, nw.phi, nw.lam, -1 if branch is None else branch)
            else:
                res = self.nk.solve(sc, nw.phi, nw.lam, -1 if branch is None else branch, max_iter=CERTIFY_MAX_ITER)
        except InputError as exc:  # infeasible targets at the p found: a failed attempt
            return arc.Attempt(nw.p, phi0, False, nw.iterations, (None, str(exc), time.perf_counter() - t0, None))
        res = dataclasses.replace(res, extra={**res.extra, "bordered_newton": nw.iterations,
                                              "krylov_iterations": ";".join(map(str, nw.krylov))})
        return arc.Attempt(nw.p, res.phi, res.converged, nw.iterations + res.iterations,
                           (res, None, time.perf_counter() - t0, False))

    def nk_fixed(self, branch, sc: Scene, p: float, phi0, lam0, t0):
        """(result, restarted) at fixed p on Newton-Krylov: Newton on the KKT system from the prediction
        (``nk_free`` with t_phi = 0, t_p = 1), certified at p, which converges on saddles too; if it
        fails, the fixed-p solve (a minimiser) from the prediction (``restarted`` true), the
        iterations added."""
        nw = self.nk_newton_point(branch, phi0, p, lam0, np.zeros_like(phi0), 1.0, 0.0, t0)
        if nw.converged:  # its iterations: the Newton steps of both (the step control's count)
            return dataclasses.replace(nw.payload[0], iterations=nw.iterations), False
        res = self.nk.solve(sc, phi0, lam0, -1 if branch is None else branch)
        return dataclasses.replace(res, iterations=nw.iterations + res.iterations), True

    def multipliers(self, branch: int, p: float) -> tuple[float, float] | None:
        """(lambda_volume, lambda_area) predicted at p: linear in p through the branch's last two
        accepted points (the last one's with one; None before), read from the rows, so that a
        resumed run starts each solve where the uninterrupted one did."""
        acc = [r for r in self.store.rows() if r["accepted"] and r["branch"] == branch and r["lambda_volume"] is not None]
        if not acc:
            return None
        b = acc[-1]
        lam_b = np.array([b["lambda_volume"], b["lambda_area"]], float)
        if len(acc) == 1 or acc[-2]["target"] == b["target"]:
            return tuple(lam_b)
        a = acc[-2]
        lam_a = np.array([a["lambda_volume"], a["lambda_area"]], float)
        return tuple(lam_b + (p - b["target"]) / (b["target"] - a["target"]) * (lam_b - lam_a))

    def bordered(self) -> BorderedCorrector:
        if self._bordered is None:
            a, b, c = self.par.affine(self.scene)
            self._bordered = BorderedCorrector(self.ipopt.scene, self.ipopt.disc, Affine(a, b, c))
        return self._bordered

    def ipopt_point(self, branch: int | None, sc: Scene, p: float, phi0: np.ndarray, lam0=None):
        """(result, restarted) at fixed p on IPOPT: warm from the prediction; if that fails (lumped
        mass), Newton at fixed p from the prediction (``BorderedCorrector.fixed``) and IPOPT warm
        from Newton's point, which certifies it (0 iterations where Newton converged); the
        iterations add up. (Measured, 128^2 elastica: warm IPOPT failed once, at nu = 0.576, and took
        2-3 iterations at the next eight points from the secant; a Newton-first rule after a
        fallback cost 4-8 s a point there.) The data are checked at the start and the end
        (``branch``); a point between whose targets were infeasible fails: a failed row."""
        if branch is not None:
            lam0 = self.multipliers(branch, p)
        elif lam0 is None:
            lam0 = least_squares_multipliers(sc, self.ipopt.disc, phi0)
        res = self.ipopt.solve(sc, phi0, lam0, feasibility=False)
        if res.converged or self.ipopt.disc.consistent:
            return res, False
        lam_n = lam0 if lam0 is not None else least_squares_multipliers(sc, self.ipopt.disc, phi0)
        nw = self.bordered().fixed(phi0, p, lam_n)
        if not nw.converged:
            return res, True
        polish = self.ipopt.solve(sc, nw.phi, nw.lam, feasibility=False)
        return dataclasses.replace(polish, iterations=res.iterations + nw.iterations + polish.iterations), True

    def correct(self, branch: int) -> Callable:
        return self.corrector(None, branch)

    def free_attempt(self, branch: int) -> Callable | None:
        return self.free_corrector(branch)

    def tangent(self, branch: int) -> Callable | None:
        """On Newton-Krylov (numpy arrays) the start's dphi/dp (``branch.nk_free.tangent``, at the
        start's multipliers): the first step along it with p free (``arclength._first_tangent``),
        where a natural one failed near a fold. None on IPOPT, where the natural first step's warm
        solve falls back to the sparse fixed-p Newton (``ipopt_point``); a tangent from the sparse
        bordered system would serve there too (from the eps 0.03 seedless saddle cup the natural
        first step failed down to dv = 1.25e-4, measured): not built."""
        if self.nk is None:
            return None
        found: dict = {}  # the walk asks again at the same start after each refused first step: one solve

        def tangent(p, phi):
            if p not in found:
                lam = self.multipliers(branch, p)
                if lam is None:
                    lam = least_squares_multipliers(self.par.scene_at(self.scene, p), self.disc, phi)
                found[p] = nk_tangent(self.kkt(), phi, lam, p)
            return found[p]
        return tangent

    def corrector(self, seed: np.ndarray | None, branch: int = 0) -> Callable:
        def correct(p, phi_start):
            t0 = time.perf_counter()
            start = phi_start is None and seed is None
            if start:
                sc = self.scene  # the start: the scene as given
            else:
                phi_start = seed if phi_start is None else phi_start
                if self.par.name == "reduced_volume" and not 0 < p <= 1:
                    return arc.Attempt(p, phi_start, False, 0, (None, f"reduced_volume {p:.6g} outside (0, 1]", 0.0, None))
                sc = self.par.scene_at(self.scene, p)
            restarted = None
            try:
                if self.nk is not None and start and getattr(self.disc, "axisymmetric", False):
                    # a meridian mesh: Newton with the axial pin from the scene's start (the fixed-p solve
                    # slides: from the eps 0.1 stomatocyte at v 0.7038 it ran 336 Newton steps to another state)
                    res, restarted = self.nk_fixed(branch, sc, p, initial_guess(sc, self.disc), None, t0)
                elif self.nk is not None and start:  # the scene's own start (nested iteration, least squares)
                    res = self.nk.solve(sc, phi_start, None, branch)
                elif self.nk is not None:
                    res, restarted = self.nk_fixed(branch, sc, p, phi_start, self.multipliers(branch, p), t0)
                elif self.ipopt is None:
                    res = solve(sc, backend=self.backend, method="exact", x0=phi_start, options=self.options)
                elif start:
                    res = self.ipopt.solve(sc, self.ipopt.nlp.split(self.ipopt.nlp.x0)[0])  # cold
                else:
                    res, restarted = self.ipopt_point(branch, sc, p, phi_start)
            except InputError as exc:  # infeasible data beyond the range of a start: a failed point
                if start:
                    raise
                return arc.Attempt(p, phi_start, False, 0, (None, str(exc), time.perf_counter() - t0, None))
            return arc.Attempt(p, res.phi, res.converged, res.iterations,
                               (res, None, time.perf_counter() - t0, restarted))
        return correct

    def row(self, branch: int, st: arc.Step) -> tuple[dict, object]:
        a = st.attempt
        res, message, wall, restarted = a.payload  # (Result or None, why not, seconds, restarted)
        rows = self.store.rows()
        point = len(rows)
        sc = self.scene
        row = {"point": point, "branch": branch, "param": self.par.name, "target": a.p,
               "accepted": st.accepted, "converged": bool(a.converged), "iterations": a.iterations,
               "solves": st.solves, "corrector": st.corrector, "arc_step": st.arc_step,
               "arc_theta": st.theta, "arc_condition": st.arc_condition, "deviation": st.deviation, "wall_time_s": wall,
               "epsilon": sc.model.epsilon, "n": sc.mesh.n[0],
               "c0": a.p if self.par.name == "c0" else sc.model.c0, "restarted": restarted}
        if res is None:
            row.update({"outcome": "not_solved", "status": message, "reason": message})
            return row, None
        ex = res.extra
        row.update({k: ex.get(k) for k in ("reason", "shape", "shape_volume_gap", "bulk_volume_share",
                                          "reduced_volume", "reduced_energy", "second_order",
                                          "second_order_min_eigenvalue", "second_order_excluded",
                                          "rotation_rayleigh", "topology", "components",
                                          "h", "alpha", "beta", "volume", "area", "f", "c0_reduced",
                                          "krylov_iterations")})
        row["wraps"] = None if ex.get("wraps") is None else "".join("xyz"[i] for i in ex["wraps"]) or "none"
        row["certifiable_tol"] = tol_to_certify(res)  # a round-off floor: the tol that can be certified
        row.update({"energy": res.energy, "lambda_volume": res.lambda_volume, "lambda_area": res.lambda_area,
                    "kkt_residual": res.kkt_residual, "outcome": str(res.outcome), "status": res.status})
        point_scene = self.par.scene_at(sc, a.p)
        row["dE_dp"] = (res.lambda_volume * self.par.dalpha() + res.lambda_area * self.par.dbeta()
                        + explicit_derivative(self.par.name, res, point_scene))
        if a.converged and not st.accepted:
            row["event"] = (f"rejected: {st.deviation:.3g} ds from the prediction (another branch)"
                            if st.deviation is not None else "rejected")
        prev = [r for r in rows if r["accepted"] and r["branch"] == branch]
        if st.accepted and prev:
            q = prev[-1]
            g, dp = (q["dE_dp"] + row["dE_dp"]) / 2, a.p - q["target"]
            row["envelope_residual"] = abs(res.energy - q["energy"] - g * dp) / abs(g * dp) if g * dp else None
            # the verdict's signs only (``events.sign``: negative below -TOL_REL, its "saddle"; positive
            # beyond its error bound, its "minimum"): a flat mode's +-1e-8 (the rotation on a Fourier
            # grid, "marginal") or an undecided one is no change; the last signed point is the
            # reference, so minimum -> marginal -> saddle is still seen where the sign flips
            last = next((s for s in (_least_sign(r["second_order_min_eigenvalue"], r.get("second_order_errors"))
                                     for r in reversed(prev)) if s), 0)
            s1 = _least_sign(row["second_order_min_eigenvalue"], (res.extra or {}).get("second_order_errors"))
            if last and s1 and last != s1:
                row["event"] = "stability change"
        if self.reference is not None:
            row["sharp_reduced_energy"] = self.reference(self.par.name, a.p, sc.dim)
        return row, res

    # -- the tree's interface (``branch.tree``) ------------------------------------------------
    def _point(self, res, p: float) -> Point | None:
        if res is None or not res.converged:
            return None
        ex = res.extra
        eig = ex.get("second_order_eigenvalues") or (() if ex.get("second_order_min_eigenvalue") is None
                                                    else (ex["second_order_min_eigenvalue"],))
        return Point(float(p), np.asarray(res.phi, float), res.energy, tuple(eig),
                     tuple(ex.get("second_order_errors") or ()), (res.lambda_volume, res.lambda_area), res)

    def solve(self, p: float, phi0: np.ndarray, lam0=None) -> Point | None:
        """The certified point at fixed p from (phi0, lam0), not recorded (None: not converged)."""
        if self.par.name == "reduced_volume" and not 0 < p <= 1:
            return None
        sc = self.par.scene_at(self.scene, p)
        try:
            if self.nk is not None:
                res, _ = self.nk_fixed(None, sc, p, phi0, lam0, time.perf_counter())
            elif self.ipopt is None:
                res = solve(sc, backend=self.backend, method="exact", x0=phi0, options=self.options)
            else:
                res, _ = self.ipopt_point(None, sc, p, phi0, lam0)
        except InputError:
            return None
        return self._point(res, p)

    @property
    def free(self) -> Callable | None:
        f = self.free_corrector(None)
        if f is None:
            return None

        def free_point(phi_pred, p_pred, t_phi, t_p, theta):
            a = f(phi_pred, p_pred, t_phi, t_p, theta)
            return self._point(a.payload[0], a.p) if a.converged else None
        return free_point

    def mode(self, point: Point, m: int) -> np.ndarray | None:
        """The m-th eigenvector (M-normalised) of the reduced Hessian at a certified point."""
        res = point.payload
        if m == 0 and res.history.get("second_order_mode") is not None:
            return np.asarray(res.history["second_order_mode"], float)
        sc = self.par.scene_at(self.scene, point.p)
        if not supports(sc, "newton-krylov"):  # the assembled check keeps its least mode only
            return None
        setup = self.nk.setup(sc) if self.nk is not None else prepare(sc, self.ipopt.fourier if self.ipopt else None)
        _, _, vec = lobpcg.reduced_hessian_eigenvalues(sc, res, setup, k=max(lobpcg.K, m + 2),
                                                       rotations=V.excludes_rotations(sc), vectors=True)
        return np.asarray(vec[:, m], float)

    def align(self, phi: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """phi's image nearest ref under the grid's symmetries (module docstring)."""
        disc = self.ipopt.disc if self.ipopt is not None else discretize(self.scene)
        if disc.grid_shape is None:
            return phi
        if self.scene.domain.boundary == "periodic":
            return symmetric_image(phi, ref, disc.grid_shape, disc.box)
        if disc.kind == MIRROR:  # the octant: exchanges of equal axes only (``branch.symmetry``)
            return align_mirror(phi, ref, disc.grid_shape, disc.box)
        return phi

    def point_row(self, k: int, point: Point, corrector: str) -> tuple[dict, object]:
        res = point.payload
        st = arc.Step(arc.Attempt(point.p, point.phi, True, res.iterations, (res, None, 0.0, None)), True,
                      corrector, 1, abs(self.s.step), None)
        row, res = self.row(k, st)
        row.update({"envelope_residual": None, "event": None})
        return row, res

    def deflate(self, p: float, phi0: np.ndarray, known: list[np.ndarray]) -> Point | None:
        return deflated_vesicle(self, p, phi0, known)
