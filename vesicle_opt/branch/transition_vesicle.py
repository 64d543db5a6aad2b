"""``transition_line(scene_a, scene_b, second="c0", values=...)``: the energy crossing of two vesicle
branches in the reduced volume, continued in c0 (``branch.transition``), e.g. the prolate/oblate
line D(c0) on the meridian half-plane (``mesh.kind = "axisymmetric"``: a 2D solve per 3D point).

    import vesicle_opt as vo
    from vesicle_opt.branch.transition_vesicle import transition_line
    a = vo.load_scene("prolate.toml")                     # reduced_volume near the crossing
    b = a.replace(initial=...)                            # the same scene, the other branch's start
    line = transition_line(a, b, values=[0.05, 0.1, -0.05, -0.1], step=-0.01, to=0.6, out="out/D")
    for r in line.rows: print(r["c0_reduced"], r["target"], r["f"], r["converged"])

The two scenes differ in ``initial`` only (the mesh, box, model and constraints are one problem).
Every point is the branch corrector's IPOPT solve (``branch.corrector``: one parametric NLP per
branch, (alpha, beta, C) its parameters): warm from the nearest sample's field with the multipliers
interpolated, at most ``WARM_MAX_ITER`` iterations, then, if that fails, IPOPT from the same field
with the scene's iteration limit; certified and second-order checked as the front door reports
(``second_order`` columns). dE/dv = lambda_V dalpha/dv and dE/dc0 = rigidity dE_h/dc0 at fixed phi
(the envelope identity, ``branch.params``) give the line's first tangent and each Newton step on
the energy difference. Columns: ``branch.transition_store``; the figure: ``branch.phase_figure``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from vesicle_opt.branch.corrector import IpoptCorrector, least_squares_multipliers
from vesicle_opt.branch.refined_corrector import RefinedCorrector
from vesicle_opt.branch.fold_continuation import fold_line as continue_fold
from vesicle_opt.branch.params import check_end, check_range, explicit_derivative, parameter
from vesicle_opt.branch.transition import Sample, continue_line
from vesicle_opt.branch.transition_store import LineStore
from vesicle_opt.errors import InputError
from vesicle_opt.mesh import band_start
from vesicle_opt.nlp import IpoptOptions
from vesicle_opt.scene import resolved
from vesicle_opt.scene.argument import require_scene
from vesicle_opt.scene.schema import Scene
from vesicle_opt.verify import updown
from vesicle_opt.verify.failure import tol_to_certify

REFINED_WARM_MAX_ITER = 30  # a warm refined point takes 5-6 IPOPT iterations (docs/guide/axisymmetric.md); one
# that needs more than this is solved again with IPOPT's own multipliers (a full solve)
REPORT = ("reduced_energy", "f", "c0_reduced", "reduced_volume", "second_order", "second_order_min_eigenvalue",
          "second_order_excluded", "shape", "topology", "reason")


@dataclasses.dataclass(frozen=True)
class Line:
    """The rows of a transition line (``branch.transition_store.COLUMNS``, parsed) and where."""

    second: str
    rows: tuple[dict, ...]
    out: Path | None = None

    def points(self) -> list[dict]:
        """The certified crossings, ordered by the second parameter."""
        return sorted((r for r in self.rows if r["converged"]), key=lambda r: r["value"])

    @property
    def converged(self) -> bool:
        return bool(self.rows) and all(r["converged"] for r in self.rows)


class VesicleCrossing:
    """The branches' point solves at (p, q) (module docstring): ``param`` p and ``second`` q, one of
    them the reduced volume and the other c0 (a crossing: p = v; a fold line in c0: p = c0)."""

    def __init__(self, scene_a: Scene, scene_b: Scene | None = None, options=None, param: str = "reduced_volume",
                 second: str = "c0", starts: dict | None = None):
        self.base = {"a": scene_a, "b": scene_b if scene_b is not None else scene_a}
        self.starts = starts or {}  # x -> (mesh or None, field): the cold start's field instead of initial
        self.param, self.second = param, second
        self.vpar = parameter(scene_a, "reduced_volume")
        self.qpar = parameter(scene_a, "c0")
        self.options, self._corr = options, {}
        self.refined = band_start.refined(scene_a)
        self.disc = self.corr("a").disc

    def corr(self, x: str):
        if x not in self._corr:  # built on first use: a fold line uses one
            # an interface-refined meridian mesh: the band follows each point (branch.refined_corrector)
            self._corr[x] = (RefinedCorrector if self.refined else IpoptCorrector)(self.base[x], self.options)
        return self._corr[x]

    def mesh_of(self, nodes, triangles):
        """The discretisation of a point's own refined mesh from its nodes and triangles (a resume)."""
        from vesicle_opt.mesh import axisymmetric, refine  # scikit-fem: refined meshes only
        import skfem

        sc = self.base["a"]
        mesh = skfem.MeshTri(np.ascontiguousarray(np.asarray(nodes, float).T), np.ascontiguousarray(triangles))
        h_fine = refine.square_side(sc.domain.box, sc.mesh.n) / 2**sc.mesh.levels
        return axisymmetric.assemble(mesh, sc.domain.box, sc.mesh.mass, sc.mesh.quadrature, h_fine=h_fine,
                                     band=sc.mesh.band)

    def scene_at(self, p: float, q: float) -> Scene:
        val = {self.param: p, self.second: q}  # c0 first: its scene_at resets the constraints
        return self.vpar.scene_at(self.qpar.scene_at(self.base["a"], val["c0"]), val["reduced_volume"])

    def solve(self, x: str, p: float, q: float, phi0, lam0, disc0=None) -> Sample:
        """The certified point of branch x at (p, q) from phi0 (on ``disc0``: a refined point's own
        mesh; None: cold from the branch's initial shape) and the multipliers lam0."""
        t0 = time.perf_counter()
        corr, sc = self.corr(x), self.scene_at(p, q)
        try:
            if phi0 is None and x in self.starts:  # the start from a given field, IPOPT's own multipliers
                disc0, phi0 = self.starts[x]
                res = corr.solve(sc, phi0, None, disc0) if self.refined else corr.solve(sc, phi0, None)
            elif self.refined:
                res = self._refined(corr, sc, phi0, lam0, disc0)
            elif phi0 is None:  # the start: cold from the branch's own initial shape
                res = corr.solve(sc, corr.nlp.split(corr.nlp.x0)[0], None, feasibility=True)
            else:
                lam = lam0 if lam0 is not None else least_squares_multipliers(sc, corr.disc, phi0)
                res = corr.solve(sc, phi0, lam, feasibility=False)
                if not res.converged:  # warm IPOPT cut at WARM_MAX_ITER: the full solve from the same field
                    cold = corr.solve(sc, phi0, None, feasibility=False)
                    res = dataclasses.replace(cold, iterations=res.iterations + cold.iterations)
        except InputError as exc:  # infeasible targets at this p: a failed point
            return Sample(p, q, np.asarray(phi0 if phi0 is not None else [], float), math.nan, False,
                          row={"outcome": "not_solved", "reason": str(exc), "wall_time_s": time.perf_counter() - t0})
        ex = res.extra
        row = {k: ex.get(k) for k in REPORT}
        if res.converged:  # one vesicle with two poles apart, up-down symmetric (verify.updown)
            row.update(updown.describe(res.disc, res.phi))
        row.update({"band_margin": ex.get("band_margin"), "n_nodes": res.disc.n_nodes})
        row.update({"kkt_residual": res.kkt_residual, "outcome": str(res.outcome), "status": res.status,
                    "certifiable_tol": tol_to_certify(res), "iterations": res.iterations,
                    "wall_time_s": time.perf_counter() - t0})
        if not res.converged and not row.get("reason"):
            row["reason"] = res.status
        d = {"reduced_volume": res.lambda_volume * self.vpar.dalpha() + res.lambda_area * self.vpar.dbeta(),
             "c0": explicit_derivative("c0", res, sc)}  # the envelope identity (branch.params)
        dE_dp, dE_dq = d[self.param], d[self.second]
        return Sample(float(p), float(q), np.asarray(res.phi, float), float(res.energy), bool(res.converged),
                      (res.lambda_volume, res.lambda_area), dE_dp, dE_dq, row, res.disc if self.refined else None)

    def _refined(self, corr: RefinedCorrector, sc: Scene, phi0, lam0, disc0):
        """A refined point (``branch.refined_corrector``): up the start's ladder (phi0 None), else warm
        from phi0 on its mesh with at most ``REFINED_WARM_MAX_ITER`` iterations, then, if that fails,
        from the same field with IPOPT's own multipliers and the scene's iteration limit."""
        if phi0 is None:
            return corr.start(sc)
        disc = disc0 if disc0 is not None else corr.disc
        lam = lam0 if lam0 is not None else least_squares_multipliers(sc, disc, phi0)
        opts = IpoptOptions.from_scene(sc) if self.options is None else self.options
        warm = dataclasses.replace(opts, max_iter=min(REFINED_WARM_MAX_ITER, opts.max_iter))
        res = corr.solve(sc, phi0, lam, disc, options=warm)
        if not res.converged and res.iterations >= warm.max_iter:
            cold = corr.solve(sc, phi0, None, disc)
            res = dataclasses.replace(cold, iterations=res.iterations + cold.iterations)
        return res


def check(scene_a: Scene, scene_b: Scene, param: str, second: str | None, values, to=None,
          step=None) -> tuple[list[float], float]:
    """The arguments of a line, before any work: (values, step), or InputError naming the flag."""
    require_scene(scene_a)
    require_scene(scene_b)
    if param != "reduced_volume":
        raise InputError("--param", f"a transition line runs in reduced_volume (its crossing), got {param!r}")
    if second is None:
        raise InputError("--second", "missing: a transition line needs the second parameter (c0) it is continued in")
    if second != "c0":
        raise InputError("--second", f"must be c0 for a transition line in reduced_volume, got {second!r}")
    vals = [] if values is None else list(values)
    if not vals or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in vals):
        raise InputError("--values", f"give one or more finite values of {second}, got {values!r}")
    da, db = resolved.as_dict(scene_a), resolved.as_dict(scene_b)
    other = sorted(k for k in set(da) | set(db) if k not in ("initial", "name") and da.get(k) != db.get(k))
    if other:
        raise InputError("--transition", f"the two branches' scenes may differ in initial.* only, not in "
                         f"{', '.join(other)}")
    if scene_a.constraints.reduced_volume is None:
        raise InputError("constraints.reduced_volume", "a transition line starts from the scene's reduced volume")
    if to is None:
        raise InputError("--to", "missing: the reduced volume the crossing is searched towards")
    par = parameter(scene_a, "reduced_volume")
    step = check_range(par, to, step)
    check_end(scene_a, par, to)
    return [float(v) for v in vals], float(step)


def transition_line(scene_a: Scene, scene_b: Scene, second: str = "c0", values=(), *, step: float | None = None,
                    to: float | None = None, out: str | Path | None = None, options=None, progress=None,
                    starts: dict | None = None) -> Line:
    """The crossing of branches a and b (their scenes: the same problem, two starts) in the reduced
    volume, located from the scenes' reduced volume towards ``to`` with samples ``|step|`` apart at
    the scenes' c0 and continued to each c0 in ``values`` (module docstring; ``branch.transition``).
    ``out``: transition.json, transition_line.csv and the fields of both branches at each crossing,
    resumed after a kill; with ``out``, also ``phase_diagram.png`` (``branch.phase_figure``).
    ``starts``: {"a"|"b": (mesh or None, field)}, the first solve of that branch from this field
    (cold multipliers) instead of its scene's ``initial`` (e.g. ``branch.refined_corrector.seeded``
    from a sharp meridian: on a refined mesh at small eps a cold start from an ellipsoid takes
    hundreds of IPOPT iterations)."""
    vals, step = check(scene_a, scene_b, "reduced_volume", second, values, to, step)
    par = parameter(scene_a, "reduced_volume")
    meta = {"scene": scene_a.name, "scene_data": resolved.as_dict(scene_a), "other_initial":
            resolved.as_dict(scene_b).get("initial"), "second": second, "values": vals, "step": float(step),
            "to": float(to), **({"starts": sorted(starts)} if starts else {})}
    solver = VesicleCrossing(scene_a, scene_b, options, starts=starts)
    store = LineStore(None if out is None else Path(out), meta, solver.disc, second, "reduced_volume",
                      solver.mesh_of if solver.refined else None)
    rows = continue_line(solver, float(scene_a.model.c0), par.start, float(to), vals, abs(step), store,
                         in_range=lambda v: 0 < v <= 1, progress=progress)
    line = Line(second, tuple(rows), None if out is None else Path(out))
    if out is not None and any(r["converged"] for r in rows):
        from vesicle_opt.branch import phase_figure  # matplotlib with the figure only
        phase_figure.plot(line.points(), solver.disc, store.plotted, Path(out) / "phase_diagram.png")
    return line


def fold_line(scene: Scene, param: str, second: str, values, *, at: float, step: float, side: float,
              warm=None, options=None, progress=None) -> list:
    """The fold of the branch of ``scene`` in ``param`` (reduced_volume or c0) near ``at`` continued in
    ``second`` (the other one) from the scene's value to each of ``values``
    (``branch.fold_continuation``): samples ``|step|`` apart on the side ``side`` (+1: the branch
    exists above the fold); ``warm``: a field on the branch near the fold (e.g. a branch run's point
    before its located fold, ``Branch.field``), else cold from the scene's initial shape. Returns
    the ``Fold`` records (p None where none was found, and why)."""
    require_scene(scene)
    if param not in ("reduced_volume", "c0") or second not in ("reduced_volume", "c0") or param == second:
        raise InputError("--second", f"a fold line runs in one of reduced_volume, c0 and is continued in the "
                         f"other, got {param!r}, {second!r}")
    solver = VesicleCrossing(scene, None, options, param, second)
    q0 = parameter(scene, second).start
    w = None if warm is None else Sample(float(at), q0, np.asarray(warm, float), math.nan, True)
    return continue_fold(solver, q0, float(at), [float(v) for v in values], float(step), side, w, progress)
