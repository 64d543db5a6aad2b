"""The ordinary fold of a vesicle branch continued in a second parameter (``branch.ordinary_fold``
on IPOPT), and the fold line of a walked branch with the method its fold needs.

``FoldSolver.free(q)``: the point with p free on a hyperplane at q, Newton on the bordered KKT
system of (6)-(8) (``branch.bordered``: sparse LU, translations pinned by phase conditions on
periodic grids; one CasADi Jacobian per value of q, since alpha or C move with it), then the fixed-p
IPOPT solve at the p found from Newton's point (``branch.corrector``), which certifies it and runs
the second-order check whose least few eigenvalues give the index. IPOPT with lumped mass only.

``from_branch(b, second, values, kind)``: the first located fold of a walked run ``b`` continued in
``second``. ``kind`` = ``ordinary``: this module, started from the walk's two points on either side
of the fold (the centre their mean, t their chord, h half of it); ``symmetric``: a symmetric turn in
its symmetric subspace (``branch.symmetric_fold``); ``auto``: ordinary where the walk located the
fold by an index change on the chord (``located_by`` = ``chord``), symmetric where it saw a turn with
no change of index (``parabola``). Measured on the 2D pair of droplets (FD 48^2, eps 0.4): below
nu_c ~ 0.802 the walk's first fold is an ordinary one (chord; the pair's rotation negative on both
sheets), above it the symmetric turn. ``fold_line.csv``: ``symmetric_fold.COLUMNS``, ``located_by``
= ``chord`` and ``fold_kind`` = ``ordinary`` here.

Example (the API)::

    import vesicle_opt as vo
    from vesicle_opt.branch.ordinary_fold_vesicle import from_branch
    b = vo.branch(scene, "c0", to=2.5, step=0.1, switch=False, out="out/c0")  # scene at nu = 0.78
    for f in from_branch(b, "reduced_volume", [0.77, 0.79], kind="ordinary"):
        print(f.q, f.p, f.eigenvalue, f.error, f.sheets, f.vertex, f.converged)
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from vesicle_opt.backends import choose_backend
from vesicle_opt.branch import ordinary_fold as of
from vesicle_opt.branch import symmetric_fold as sf
from vesicle_opt.branch.bordered import Affine, BorderedCorrector
from vesicle_opt.branch.corrector import IpoptCorrector, least_squares_multipliers
from vesicle_opt.branch.events import FOLD, Point
from vesicle_opt.branch.params import parameter
from vesicle_opt.branch.store import cell_text
from vesicle_opt.errors import InputError
from vesicle_opt.mesh import discretize

KINDS = ("auto", "symmetric", "ordinary")


class FoldSolver:
    """Certified points of ``scene`` with p free at (., q) (module docstring)."""

    def __init__(self, scene, param: str, second: str, options=None):
        self.corr = IpoptCorrector(scene, options)
        self.disc, self.scene = self.corr.disc, self.corr.scene
        self.param, self.second = param, parameter(scene, second)
        self.weights = np.asarray(self.disc.weights, float)
        self.solves = 0
        self._bordered: tuple[float, BorderedCorrector] | None = None  # the last q's (one CasADi graph)

    def scene_at(self, p: float, q: float):
        sec = self.second.scene_at(self.scene, q)
        return parameter(sec, self.param).scene_at(sec, p)

    def bordered(self, q: float) -> BorderedCorrector:
        if self._bordered is None or self._bordered[0] != q:
            sec = self.second.scene_at(self.scene, q)
            a, b, c = parameter(sec, self.param).affine(sec)
            self._bordered = (q, BorderedCorrector(sec, self.disc, Affine(a, b, c)))
        return self._bordered[1]

    def free(self, q: float):
        def point(phi_pred, p_pred, t_phi, t_p, theta) -> Point | None:
            self.solves += 1
            try:
                lam = least_squares_multipliers(self.scene_at(p_pred, q), self.disc, phi_pred)
                nw = self.bordered(q).solve(phi_pred, p_pred, lam, t_phi, t_p, theta)
                if not nw.converged or (self.param == "reduced_volume" and not 0 < nw.p <= 1):
                    return None
                res = self.corr.solve(self.scene_at(nw.p, q), nw.phi, nw.lam, feasibility=False)
            except InputError:
                return None
            eig = res.extra.get("second_order_eigenvalues")
            if not res.converged or not eig:
                return None
            return Point(float(nw.p), np.asarray(res.phi, float), res.energy, tuple(eig),
                         tuple(res.extra.get("second_order_errors") or ()), (res.lambda_volume, res.lambda_area), res)
        return point


def check(scene, param: str, second: str) -> None:
    """An ordinary fold line's arguments, before any work (InputError naming the flag or key)."""
    if param not in ("reduced_volume", "c0") or second not in ("reduced_volume", "c0") or param == second:
        raise InputError("--second", f"a fold line runs in one of reduced_volume, c0 and is continued in the "
                         f"other, got {param!r}, {second!r}")
    if choose_backend(scene) != "ipopt" or discretize(scene).consistent:
        raise InputError("backend", "an ordinary fold's line needs the IPOPT backend with lumped mass (the "
                         "bordered corrector, branch.bordered)")
    if not scene.solver.second_order:
        raise InputError("solver.second_order", "an ordinary fold is located on the second-order check's "
                         "eigenvalues: set solver.second_order = true")


def applicable(scene, param: str, second: str) -> dict:
    """{kind: None where its line can run on ``scene``, else the InputError that says why not}."""
    out = {}
    for kind, chk in (("symmetric", sf.check), ("ordinary", check)):
        try:
            chk(scene, param, second)
            out[kind] = None
        except InputError as exc:
            out[kind] = exc
    return out


def check_kind(scene, param: str, second: str, kind: str) -> None:
    """``--fold-kind`` and the scene, before any work: the kind asked for (auto: either) can run."""
    if kind not in KINDS:
        raise InputError("--fold-kind", f"one of {', '.join(KINDS)}, got {kind!r}")
    why = applicable(scene, param, second)
    if kind != "auto" and why[kind] is not None:
        raise why[kind]
    if kind == "auto" and all(e is not None for e in why.values()):
        sym, ordi = why["symmetric"], why["ordinary"]
        if sym.key == ordi.key:  # the same argument (--second): one message
            raise sym
        raise InputError(sym.key, f"{str(sym)[len(sym.key) + 2:]}; an ordinary fold's line: {ordi}")


def line(scene, param: str, second: str, values, *, a_phi, b_phi, at: float, theta: float = 1.0,
         options=None, progress=None) -> list[of.Fold]:
    """The ordinary fold of ``scene``'s branch in ``param`` near ``at``, between two fields on its
    two sheets (``a_phi``, ``b_phi``: e.g. the walked points around the located fold), continued in
    ``second`` from the scene's value to each of ``values`` (``branch.ordinary_fold.line``)."""
    check(scene, param, second)
    solver = FoldSolver(scene, param, second, options)
    a, b = (np.asarray(x, float) for x in (a_phi, b_phi))
    if a.shape != (solver.disc.n_nodes,) or b.shape != a.shape:
        raise InputError("warm", f"two fields of {solver.disc.n_nodes} nodes (the scene's grid), got "
                                 f"{a.shape}, {b.shape}")
    d = b - a
    length = math.sqrt(float(solver.weights @ (d * d)))
    if length == 0:
        raise InputError("warm", "the two fields are equal: no chord through the fold")
    return of.line(solver, solver.second.start, (a + b) / 2, float(at), d / length, length / 2,
                   values, theta, progress)


def _ordinary_start(b, row):
    """The walked points just before and after the located fold ``row`` (its ``detected_at``)."""
    pts = b.points(0)
    j = next(i for i, r in enumerate(pts) if r["point"] == row["detected_at"])
    return pts[j - 1], pts[j]


def from_branch(b, second: str, values, *, kind: str = "auto", options=None, progress=None) -> list:
    """The first located fold of the walked run ``b`` continued in ``second`` (module docstring);
    ``out/fold_line.csv`` where the run has ``out``. No located fold (of that kind): []."""
    check_kind(b.scene, b.param, second, kind)
    if kind == "auto":  # a kind that cannot run on this scene is not chosen
        why = applicable(b.scene, b.param, second)
        kind = "ordinary" if why["symmetric"] is not None else "symmetric" if why["ordinary"] is not None else kind
    folds = [r for r in b.located(0) if r["event"] == FOLD]
    if kind == "ordinary":
        folds = [r for r in folds if r["located_by"] == "chord"]
    if not folds:
        return []
    if kind == "symmetric" or (kind == "auto" and folds[0]["located_by"] != "chord"):
        return sf.from_branch(b, second, values, options=options, progress=progress)
    if b.out is None:
        raise InputError("out", "the branch run kept no snapshots: run it with out= for the warm fields")
    lo, hi = _ordinary_start(b, folds[0])
    folds_found = line(b.scene, b.param, second, values, a_phi=b.field(lo["point"])["phi"],
                       b_phi=b.field(hi["point"])["phi"], at=folds[0]["target"],
                       theta=lo.get("arc_theta") or 1.0, options=options, progress=progress)
    rows = [{"second": second, "value": f.q, "param": b.param, "target": f.p, "energy": f.energy,
             "reduced_energy": None if f.point is None or f.p is None else f.point.payload.extra.get("reduced_energy"),
             "branch": 0, "located_by": "chord", "detected_at": None, "critical_eigenvalue": f.eigenvalue,
             "critical_error": f.error, "converged": f.converged, "reason": f.reason, "bracket": f.bracket,
             "solves": f.solves, "wall_time_s": f.wall, "cpu_time_s": f.cpu, "fold_kind": "ordinary",
             "critical": f.critical, "sheet_a_target": None if f.sheets is None else f.sheets[0],
             "sheet_b_target": None if f.sheets is None else f.sheets[1], "vertex_target": f.vertex}
            for f in folds_found]
    with open(Path(b.out) / "fold_line.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, sf.COLUMNS, lineterminator="\n")
        w.writeheader()
        w.writerows({k: cell_text(v) for k, v in r.items()} for r in rows)
    return folds_found
