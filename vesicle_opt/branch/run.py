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
  Result's extra); after the first step (``NK_TURN``) every point by the p-free corrector
  ``branch.nk_free`` (bordered Newton on the KKT system, GMRES with a Schur-complement
  preconditioner on the Newton-Krylov model, ``branch.krylov_bordered``; ``krylov_iterations``
  the GMRES counts of its Newton steps), then certified and checked at its own p by that fixed-p
  solve, so a branch passes turning points and follows saddles; every point at a fixed p (the
  first and the final step, the tree's location and switch trials) is the same Newton with p held
  (t_phi = 0, t_p = 1), certified likewise, the fixed-p solve (a minimiser, which leaves saddles)
  its fallback (``restarted`` true); with ``solver.array = "jax"`` the front door itself (the
  scalar iteration on p of ``branch.arclength`` near a fold, which approaches it but does not pass it).

Per accepted point the row also holds

* ``dE_dp`` = lambda_volume d alpha/dp + lambda_area d beta/dp + dE/dp|_phi (``branch.params``) and
  ``envelope_residual`` = |Delta E - (dE_dp_{i-1} + dE_dp_i)/2 Delta p| / |(dE_dp_{i-1} + dE_dp_i)/2 Delta p|
  on the interval from the previous accepted point: the envelope identity against the finite
  difference of E along the branch, O(Delta p^2) (the trapezoid rule's error; ``Branch.envelope_central``
  gives the three-point form at interior points);
* ``event`` = ``stability change`` where ``second_order_min_eigenvalue`` (the least eigenvalue of
  the reduced Hessian, symmetry modes excluded) changes its certified sign (the verdict's: below
  -TOL_REL, or positive beyond its error bound; ``events.sign``) from the last accepted point that had one;
  ``Branch.events`` classifies each as a ``fold`` (the parameter turns back within one interval of
  it) or a ``bifurcation``; ``second_order_eigenvalues`` / ``second_order_errors`` hold the check's
  least few (';'-joined) and ``index`` the number certified negative (below -TOL_REL: ``events.index``,
  1 or more exactly where the verdict reads saddle);
* the diagram (``branch.tree``): every change of the count negative beyond its error bound
  (``events.decided``, at most ``index``) is located (a ``locate`` row, ``event``
  ``fold`` or ``branch point``, ``Branch.located``), and with ``switch`` the branches leaving each
  branch point are followed in both directions, recursively to ``depth`` levels (``branch`` the id,
  ``parent`` the branch left); with ``deflate`` = N, where switching found none, up to N other
  points at the start by deflation, each a new root (``Branch.parents``: the tree);
* ``sharp_reduced_energy``: the place of a sharp-interface reference (``reference(param, value,
  dim)`` -> float or None, not computed here).

A failed corrector is a row (``converged`` false, its ``outcome`` and ``status``), the step halves.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from vesicle_opt.backends import choose_backend
from vesicle_opt.branch import arclength as arc
from vesicle_opt.branch.deflation import supported as deflation_supported
from vesicle_opt.branch.events import FOLD, classify
from vesicle_opt.branch.nk_corrector import TARGET_ITERATIONS as NK_TARGET_ITERATIONS
from vesicle_opt.branch.params import check_end, check_range, parameter
from vesicle_opt.branch.store import Store
from vesicle_opt.branch.tree import grow
from vesicle_opt.branch.vesicle import VesicleProblem
from vesicle_opt.errors import InputError
from vesicle_opt.model.profile import interface_secant
from vesicle_opt.scene import resolved
from vesicle_opt.scene.argument import require_scene
from vesicle_opt.scene.schema import Scene



@dataclass(frozen=True)
class Branch:
    """The rows of a branch run (``branch.store.COLUMNS``, parsed) and why each branch stopped."""

    param: str
    to: float
    step: float
    rows: tuple[dict, ...]
    stopped: dict  # branch id -> reason
    out: Path | None = None
    parents: dict = dataclasses.field(default_factory=dict)  # branch id -> parent id (None: a root)
    scene: Scene | None = dataclasses.field(default=None, repr=False)  # the scene the branch started from

    def field(self, point: int) -> dict:
        """The snapshot of ``point`` (``points/point-NNNN.npz``, the ``io.fields`` layout: phi, nodes,
        grid_shape, box, p[, mode]); InputError when the run kept no files (``out`` None)."""
        if self.out is None:
            raise InputError("out", "this branch was run without out=: no snapshots were kept")
        from vesicle_opt.io import fields  # numpy only; local to keep the branch package's imports short
        return fields.read(self.out / "points" / f"point-{point:04d}.npz")

    def points(self, branch: int | None = None) -> list[dict]:
        """The accepted (converged) points, of one branch when given."""
        return [r for r in self.rows if r["accepted"] and (branch is None or r["branch"] == branch)]

    @property
    def converged(self) -> bool:
        """The root reached ``to`` (or max_points), every other branch ended as a branch of a tree
        does (``ENDINGS``), and every accepted point is certified."""
        return all(v.startswith(ENDINGS) for v in self.stopped.values()) and \
            self.stopped.get(0) in ("reached", "max_points") and all(r["converged"] for r in self.points())

    def children(self, branch: int) -> list[int]:
        """The ids of the branches that left ``branch`` (switched at its branch points), ascending."""
        return sorted(k for k, v in self.parents.items() if v == branch)

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
            kind = classify([q["target"] for q in pts], k)
            saddle = pts[k] if pts[k]["second_order_min_eigenvalue"] < 0 else pts[k - 1]
            out.append({"point": pts[k]["point"], "kind": "fold" if kind == FOLD else "bifurcation",
                        "saddle": saddle["point"], "target": saddle["target"]})
        return out

    def located(self, branch: int | None = None) -> list[dict]:
        """The located events (``branch.events``): rows with ``event`` ``fold`` or ``branch point``."""
        return [r for r in self.rows if r["corrector"] == "locate" and (branch is None or r["branch"] == branch)]


NK_TURN = 2.0  # Newton-Krylov: the p-free corrector (``branch.nk_free``) at every step after the first
# (|t_p| <= 1 < 2): Newton on the KKT system converges on saddle branches, where the fixed-p solve, a
# minimiser, wanders off (the 2D circle's index-2 branch, spectral 48^2: it stopped at nu = 0.657; p free,
# nu 0.95 -> 0.5 in 21 points, 2.5 s), and costs no more than it on minima (3-5 Newton steps a point)
ENDINGS = ("reached", "max_points", "joined", "known", "left the range", "none found")


def _meta(scene: Scene, param: str, to: float, step: float, backend, switch: bool, depth: int = 1,
          deflate: int = 0) -> dict:
    # scene_data: the resolved scene as a JSON table (``scene.resolved.as_dict``; it was a Python repr
    # string before the npz format had a version), so ``vo.load_branch`` rebuilds the Scene
    meta = {"scene": scene.name, "scene_data": resolved.as_dict(scene), "param": param, "to": float(to),
            "step": float(step), "backend": backend, "switch": bool(switch)}
    if depth != 1:  # the keys of older runs, unchanged where the defaults are kept
        meta["depth"] = depth
    if deflate:
        meta["deflate"] = deflate
    return meta


def branch(scene: Scene, param: str = "reduced_volume", to: float | None = None, step: float | None = None,
           out: str | Path | None = None, *, backend: str | None = None,
           options: "IpoptOptions | NewtonKrylovOptions | None" = None, max_points: int = 200, switch: bool = True,
           reference: Callable | None = None, snapshots: bool = True,
           progress: Callable[[dict], None] | None = None, turn: float | None = None,
           depth: int = 1, deflate: int = 0) -> Branch:
    """Follow the branch of equilibria of ``scene`` in ``param`` from the scene's value to ``to``
    (module docstring); ``step`` is the first (and largest) parameter step, signed towards ``to``
    (default: a 25th of the range). ``out``: a directory for branch.csv and the snapshots, resumed
    when it holds the same run. ``turn``: |t_p| below which the pseudo-arclength corrector runs
    (``branch.arclength``; above 1: every step after the first; None: ``arclength.Settings.turn``
    on IPOPT, every step on Newton-Krylov, ``NK_TURN``). ``switch``, ``depth``: follow the
    branches leaving located branch points, recursively to ``depth`` levels; ``deflate``: up to this
    many other points at the start by deflation where switching found none (``branch.tree``). Bad
    input raises InputError (naming the flag) before any solve."""
    require_scene(scene)
    if to is None:
        raise InputError("--to", "missing: the end value of the parameter")
    par = parameter(scene, param)
    step = check_range(par, to, step)
    check_end(scene, par, to)
    if not (isinstance(max_points, int) and max_points >= 2):
        raise InputError("max_points", f"allowed range >= 2, got {max_points!r}")
    nk = choose_backend(scene, backend) == "newton-krylov"
    explicit = turn is not None
    if turn is None:
        turn = NK_TURN if nk and scene.solver.array != "jax" else arc.Settings.turn
    if isinstance(turn, bool) or not (isinstance(turn, (int, float)) and 0 <= turn):
        raise InputError("turn", f"allowed range >= 0 (|t_p| below which the arclength corrector runs), got {turn!r}")
    for name, v in (("--depth", depth), ("--deflate", deflate)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise InputError(name, f"allowed range: an integer >= 0, got {v!r}")
    if deflate and deflation_supported(scene, backend) is not None:  # before any work: never a silent no-op
        raise InputError("--deflate", deflation_supported(scene, backend))
    meta = _meta(scene, param, to, step, backend, switch, depth, deflate)
    if explicit and turn != arc.Settings.turn:
        meta["turn"] = float(turn)
    store = Store(None if out is None else Path(out), meta, snapshots)
    step = store.meta["step"]  # an extension of a finished run (further --to) keeps its first step
    # the step control's target in the corrector's own iterations (Newton steps on Newton-Krylov)
    target = NK_TARGET_ITERATIONS if nk else arc.Settings.target_iterations
    # on Newton-Krylov the p-free corrector starts from the secant in the profile's coordinate, which moves
    # the interface, where that start has the smaller error (``model.profile``; octant prolate, 205 k nodes:
    # Newton steps a point 10/8/7/7 -> 8/7/5/5)
    settings = arc.Settings(step=step, to=float(to), max_points=max_points, turn=float(turn),
                            target_iterations=target,
                            predict=interface_secant if nk and scene.solver.array != "jax" else None)
    problem = VesicleProblem(scene, par, settings, store, backend, options, reference, progress)
    nodes = grow(problem, depth, switch, deflate)
    result = Branch(par.name, float(to), float(step), tuple(store.rows()), {k: n.stopped for k, n in nodes.items()},
                    None if out is None else Path(out), {k: n.parent for k, n in nodes.items()}, scene=scene)
    store.finish(result.stopped)  # branch.json's "stopped": why each branch ended (vo.load_branch reads it)
    if out is not None and snapshots:
        write_diagram(result, Path(out) / "energy_diagram.png")
    return result


def write_diagram(b: Branch, path: Path, title: str = "") -> None:
    """The energy-diagram PNG of a run's branches (``branch.diagram``)."""
    # matplotlib loads with branch.diagram only: not with ``import vesicle_opt`` (a function-local
    # import on purpose, as io.output is for the CLI)
    from vesicle_opt.branch import diagram
    points = None if b.out is None else b.out / "points"
    series = [(f"branch {k}" if k else "branch", b.points(k), points) for k in sorted(b.stopped) if b.points(k)]
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.png")  # drawn beside, then moved: an interrupt
    try:  # never leaves half a PNG
        diagram.plot(series, tmp, xlabel=b.param.replace("_", " "), title=title, events=b.located(),
                     dim=b.scene.dim if b.scene is not None else 3)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
