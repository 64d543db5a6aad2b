"""``branch(scene, param=, to=, step=, out=)``: a branch of equilibria in the reduced volume or c0.

Every point is an exact-constraint solve, warm-started from the predictor (``branch.arclength``),
with the front door's certificate, its second-order verdict (``second_order``,
``second_order_min_eigenvalue`` in mu_ref units, ``second_order_excluded``) and its topology:

* on IPOPT (2D, small 3D): ``branch.corrector``, the NLP, the solver and the check's operators
  built once per branch, the predicted multipliers (linear in p through the last two points) as
  IPOPT's warm start; on FD grids the check removes the rotation as it removes the translations
  (``rotation_rayleigh``: the rotation's Rayleigh quotient on T, mu_ref units, reported beside it);
  if warm IPOPT fails (at most ``corrector.WARM_MAX_ITER`` = 6 iterations), Newton at fixed p on the
  bordered system (``branch.bordered``) from the prediction, certified by IPOPT from Newton's point
  (``restarted`` true);
* near a fold (|t_p| < ``turn``) on IPOPT with lumped mass: the pseudo-arclength corrector with p
  free (``branch.bordered``: Newton on the KKT system bordered by the arclength equation), its
  point then certified at its own p by the fixed-p IPOPT solve, so a branch passes a turning point;
* on Newton-Krylov (``backend="newton-krylov"``, large 3D spectral grids): ``branch.nk_corrector``
  at fixed p (the step control aiming at its ``TARGET_ITERATIONS`` Newton steps), the front door's solve and check warm from the branch's previous point (predicted
  multipliers, the dual model, the check's coarsest eigenvectors; ``second_order_warm`` in the
  Result's extra), and near a fold the scalar iteration on p of ``branch.arclength`` (which
  approaches a fold but does not pass it); with ``solver.array = "jax"`` the front door itself.

Per accepted point the row also holds

* ``dE_dp`` = lambda_volume d alpha/dp + lambda_area d beta/dp + dE/dp|_phi (``branch.params``) and
  ``envelope_residual`` = |Delta E - (dE_dp_{i-1} + dE_dp_i)/2 Delta p| / |(dE_dp_{i-1} + dE_dp_i)/2 Delta p|
  on the interval from the previous accepted point: the envelope identity against the finite
  difference of E along the branch, O(Delta p^2) (the trapezoid rule's error; ``Branch.envelope_central``
  gives the three-point form at interior points);
* ``event`` = ``stability change`` where ``second_order_min_eigenvalue`` (the least eigenvalue of
  the reduced Hessian, symmetry modes excluded) changes sign from the previous accepted point;
  ``Branch.events`` classifies each as a ``fold`` (the parameter turns back within one interval of
  it) or a ``bifurcation``. With ``switch=True`` the run then starts a branch (``branch`` column 1,
  2, ...) from the saddle's field pushed along its critical eigenvector (the front door's
  ``history["second_order_mode"]``) and follows it towards ``to``.
* ``sharp_reduced_energy``: the place of a sharp-interface reference (``reference(param, value,
  dim)`` -> float or None, not computed here).

A failed corrector is a row (``converged`` false, its ``outcome`` and ``status``), the step halves.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from vesicle_opt.api import solve
from vesicle_opt.backends import choose_backend
from vesicle_opt.branch import arclength as arc
from vesicle_opt.branch.bordered import Affine, BorderedCorrector
from vesicle_opt.branch.corrector import IpoptCorrector, least_squares_multipliers
from vesicle_opt.branch.nk_corrector import TARGET_ITERATIONS as NK_TARGET_ITERATIONS, NewtonKrylovCorrector
from vesicle_opt.branch.params import Parameter, check_end, check_range, explicit_derivative, parameter
from vesicle_opt.branch.store import Store
from vesicle_opt.errors import InputError
from vesicle_opt.mesh import discretize
from vesicle_opt.scene.argument import require_scene
from vesicle_opt.scene.schema import Scene

SWITCH_AMPLITUDE = 0.05  # the seed phi_s + a |phi_s|_M mode of a branch switch (mode M-normalised)


@dataclass(frozen=True)
class Branch:
    """The rows of a branch run (``branch.store.COLUMNS``, parsed) and why each branch stopped."""

    param: str
    to: float
    step: float
    rows: tuple[dict, ...]
    stopped: dict  # branch id -> reason
    out: Path | None = None

    def points(self, branch: int | None = None) -> list[dict]:
        """The accepted (converged) points, of one branch when given."""
        return [r for r in self.rows if r["accepted"] and (branch is None or r["branch"] == branch)]

    @property
    def converged(self) -> bool:
        """Every branch reached ``to`` (or its end) and every accepted point is certified."""
        return all(v in ("reached", "max_points") for v in self.stopped.values()) and \
            all(r["converged"] for r in self.points())

    def envelope_central(self, branch: int = 0) -> list[tuple[int, float]]:
        """(point, |E'_FD - dE_dp| / |dE_dp|) at interior points, E'_FD the three-point derivative
        on the nonuniform parameter grid (second order)."""
        pts = self.points(branch)
        out = []
        for a, b, c in zip(pts, pts[1:], pts[2:]):
            h1, h2 = b["target"] - a["target"], c["target"] - b["target"]
            if h1 * h2 <= 0:
                continue  # a fold between: E is not a function of p there
            d = (-h2 / (h1 * (h1 + h2)) * a["energy"] + (h2 - h1) / (h1 * h2) * b["energy"]
                 + h1 / (h2 * (h1 + h2)) * c["energy"])
            out.append((b["point"], abs(d - b["dE_dp"]) / abs(b["dE_dp"])))
        return out

    def events(self, branch: int = 0) -> list[dict]:
        """Each stability change: {point, kind ('fold' | 'bifurcation'), saddle (the point with the
        negative eigenvalue)}."""
        pts = self.points(branch)
        out = []
        for k in range(1, len(pts)):
            if pts[k]["event"] != "stability change":
                continue
            dps = [pts[j + 1]["target"] - pts[j]["target"] for j in range(max(k - 2, 0), min(k + 1, len(pts) - 1))]
            turned = any(x * y < 0 for x, y in zip(dps, dps[1:]))
            saddle = pts[k] if pts[k]["second_order_min_eigenvalue"] < 0 else pts[k - 1]
            out.append({"point": pts[k]["point"], "kind": "fold" if turned else "bifurcation",
                        "saddle": saddle["point"], "target": saddle["target"]})
        return out


def _meta(scene: Scene, param: str, to: float, step: float, backend, switch: bool) -> dict:
    return {"scene": scene.name, "scene_data": repr(scene), "param": param, "to": float(to),
            "step": float(step), "backend": backend, "switch": bool(switch)}


class _Run:
    """One branch run: the corrector, the rows, the store (see ``branch``)."""

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

    def free_corrector(self, branch: int) -> Callable | None:
        """The corrector with p free (``branch.bordered``, then the fixed-p IPOPT solve at the p
        found, which certifies the point); None where it does not apply (Newton-Krylov backend,
        consistent mass): the walk then uses its scalar iteration (``branch.arclength``)."""
        if self.ipopt is None or self.ipopt.disc.consistent:
            return None

        def free(phi_pred, p_pred, t_phi, t_p, theta):
            t0 = time.perf_counter()
            lam = self.multipliers(branch, p_pred)
            if lam is None:
                lam = least_squares_multipliers(self.scene, self.ipopt.disc, phi_pred)
            nw = self.bordered().solve(phi_pred, p_pred, lam, t_phi, t_p, theta)
            if not nw.converged or (self.par.name == "reduced_volume" and not 0 < nw.p <= 1):
                why = nw.message or f"reduced_volume {nw.p:.6g} outside (0, 1]"
                return arc.Attempt(nw.p, phi_pred, False, nw.iterations,
                                   (None, f"bordered Newton: {why}", time.perf_counter() - t0, None))
            res = self.ipopt.solve(self.par.scene_at(self.scene, nw.p), nw.phi, nw.lam, feasibility=False)
            return arc.Attempt(nw.p, res.phi, res.converged, nw.iterations + res.iterations,
                               (res, None, time.perf_counter() - t0, False))
        return free

    def multipliers(self, branch: int, p: float) -> tuple[float, float] | None:
        """(lambda_volume, lambda_area) predicted at p: linear in p through the branch's last two
        accepted points (the last one's with one; None before), read from the rows, so that a
        resumed run starts each solve where the uninterrupted one did."""
        acc = [r for r in self.store.rows() if r["accepted"] and r["branch"] == branch]
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

    def ipopt_point(self, branch: int, sc: Scene, p: float, phi0: np.ndarray):
        """(result, restarted) at fixed p on IPOPT: warm from the prediction; if that fails (lumped
        mass), Newton at fixed p from the prediction (``BorderedCorrector.fixed``) and IPOPT warm
        from Newton's point, which certifies it (0 iterations where Newton converged); the
        iterations add up. (Measured, 128^2 elastica: warm IPOPT failed once, at nu = 0.576, and took
        2-3 iterations at the next eight points from the secant; a Newton-first rule after a
        fallback cost 4-8 s a point there.) The data are checked at the start and the end
        (``branch``); a point between whose targets were infeasible fails: a failed row."""
        lam0 = self.multipliers(branch, p)
        res = self.ipopt.solve(sc, phi0, lam0, feasibility=False)
        if res.converged or self.ipopt.disc.consistent:
            return res, False
        lam_n = lam0 if lam0 is not None else least_squares_multipliers(sc, self.ipopt.disc, phi0)
        nw = self.bordered().fixed(phi0, p, lam_n)
        if not nw.converged:
            return res, True
        polish = self.ipopt.solve(sc, nw.phi, nw.lam, feasibility=False)
        return dataclasses.replace(polish, iterations=res.iterations + nw.iterations + polish.iterations), True

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
                if self.nk is not None:  # warm: the predicted multipliers (None at a start: least squares)
                    res = self.nk.solve(sc, phi_start, None if start else self.multipliers(branch, p), branch)
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
            row.update({"outcome": "not_solved", "status": message})
            return row, None
        ex = res.extra
        row.update({k: ex.get(k) for k in ("reduced_volume", "reduced_energy", "second_order",
                                          "second_order_min_eigenvalue", "second_order_excluded",
                                          "rotation_rayleigh", "topology", "components",
                                          "h", "alpha", "beta", "volume", "area")})
        row["wraps"] = None if ex.get("wraps") is None else "".join("xyz"[i] for i in ex["wraps"]) or "none"
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
            mu0, mu1 = q["second_order_min_eigenvalue"], row["second_order_min_eigenvalue"]
            if mu0 is not None and mu1 is not None and mu0 * mu1 < 0:
                row["event"] = "stability change"
        if self.reference is not None:
            row["sharp_reduced_energy"] = self.reference(self.par.name, a.p, sc.dim)
        return row, res

    def record(self, branch: int) -> Callable:
        def rec(st: arc.Step):
            row, res = self.row(branch, st)
            self.store.append(row, res)
            if self.progress is not None:
                self.progress(row)
        return rec

    def follow(self, branch: int, p_start: float, seed: np.ndarray | None) -> str:
        """Walk (or resume) one branch; returns why it stopped."""
        mine = [r for r in self.store.rows() if r["branch"] == branch]
        recs = [{"p": r["target"], "phi": self.store.phi(r["point"]) if r["accepted"] else None,
                 "accepted": r["accepted"], "arc_step": r["arc_step"], "theta": r["arc_theta"]} for r in mine]
        track = arc.replay(self.s.step, recs) if recs else None
        _, why = arc.walk(self.s, p_start, self.corrector(seed, branch), self.weights, track, self.record(branch),
                          free=self.free_corrector(branch))
        return why


def branch(scene: Scene, param: str = "reduced_volume", to: float | None = None, step: float | None = None,
           out=None, *, backend: str | None = None, options=None, max_points: int = 200, switch: bool = True,
           reference: Callable | None = None, snapshots: bool = True,
           progress: Callable[[dict], None] | None = None, turn: float = arc.Settings.turn) -> Branch:
    """Follow the branch of equilibria of ``scene`` in ``param`` from the scene's value to ``to``
    (module docstring); ``step`` is the first (and largest) parameter step, signed towards ``to``
    (default: a 25th of the range). ``out``: a directory for branch.csv and the snapshots, resumed
    when it holds the same run. ``turn``: |t_p| below which the pseudo-arclength corrector runs
    (``branch.arclength``; above 1: every step after the first). Bad input raises InputError (naming
    the flag) before any solve."""
    require_scene(scene)
    if to is None:
        raise InputError("--to", "missing: the end value of the parameter")
    par = parameter(scene, param)
    step = check_range(par, to, step)
    check_end(scene, par, to)
    if not (isinstance(max_points, int) and max_points >= 2):
        raise InputError("max_points", f"allowed range >= 2, got {max_points!r}")
    if not (isinstance(turn, (int, float)) and 0 <= turn):
        raise InputError("turn", f"allowed range >= 0 (|t_p| below which the arclength corrector runs), got {turn!r}")
    meta = _meta(scene, param, to, step, backend, switch)
    if turn != arc.Settings.turn:
        meta["turn"] = float(turn)
    store = Store(None if out is None else Path(out), meta, snapshots)
    # the step control's target in the corrector's own iterations (Newton steps on Newton-Krylov)
    target = NK_TARGET_ITERATIONS if choose_backend(scene, backend) == "newton-krylov" else \
        arc.Settings.target_iterations
    settings = arc.Settings(step=step, to=float(to), max_points=max_points, turn=float(turn),
                            target_iterations=target)
    run = _Run(scene, par, settings, store, backend, options, reference, progress)
    stopped = {0: run.follow(0, par.start, None)}
    if switch:
        for k, ev in enumerate([e for e in _result(par, to, step, store, stopped, out).events(0)
                                if e["kind"] == "bifurcation"], start=1):
            stopped[k] = _switch(run, store, k, ev)
    result = _result(par, to, step, store, stopped, out)
    if out is not None and snapshots:
        write_diagram(result, Path(out) / "energy_diagram.png")
    return result


def write_diagram(b: Branch, path: Path, title: str = "") -> None:
    """The energy-diagram PNG of a run's branches (``branch.diagram``)."""
    # matplotlib loads with branch.diagram only: not with ``import vesicle_opt`` (a function-local
    # import on purpose, as io.output is for the CLI)
    from vesicle_opt.branch import diagram
    points = None if b.out is None else b.out / "points"
    series = [(f"branch {k}" if k else "branch", b.points(k), points) for k in sorted(b.stopped)]
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.png")  # drawn beside, then moved: an interrupt
    try:  # never leaves half a PNG
        diagram.plot(series, tmp, xlabel=b.param.replace("_", " "), title=title)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _result(par, to, step, store, stopped, out) -> Branch:
    return Branch(par.name, float(to), float(step), tuple(store.rows()), dict(stopped),
                  None if out is None else Path(out))


def _switch(run: _Run, store: Store, k: int, ev: dict) -> str:
    """Branch k from the saddle of a bifurcation event pushed along its critical eigenvector."""
    seed = store.seed(k)
    if seed is None:
        mode = store.mode(ev["saddle"])
        if mode is None:
            return "no eigenvector stored at the saddle"
        phi = store.phi(ev["saddle"])
        amp = SWITCH_AMPLITUDE * math.sqrt(float(np.dot(run.weights, phi * phi)))
        store.save_seed(k, ev["target"], phi + amp * mode)
        seed = store.seed(k)
    return run.follow(k, float(seed["p"]), np.asarray(seed["phi"], float))

