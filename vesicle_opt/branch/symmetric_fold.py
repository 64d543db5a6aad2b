"""A symmetric turning point continued in a second parameter q, in its symmetric subspace.

A branch can turn in p with its critical eigenvalue only touching zero (``branch.events``: a turn
with no change of index). Measured on the nu = 0.8 ellipse in c0 (2D, FD 48^2, eps 0.4): by c0 ~ 0.3
it has split into two droplets that drift apart along the branch; at c0 = 0.734765 they sit half
a box apart, and the sheet beyond the turn is the image of the sheet before under the half-box
shift S (x -> x + L/2 along the pair's axis, a permutation of the grid's nodes). E and p are even
along the branch there, so the turn is not a generic fold: it is the branch point of the
S-symmetric branch (the pair exactly half a box apart), on which the S-odd mode (the droplets'
relative translation) changes stability; the walked branch is the one that leaves it. Two things
break a fold continuation there (``branch.fold_continuation``): the envelope coordinate dE/dp is
even too (no vertex of p(dE/dp)), and the Hessian of the full system is singular with a critical
mode outside the branch's own symmetry class.

In the symmetric subspace both are regular. The S-symmetric branch is smooth through the turn,
and the test function

    g(p, q) = the least eigenvalue of the reduced Hessian H v = mu M v (paper eqs. (6)-(8), the
    Lagrangian's Hessian on T = {dA.v = dB.v = 0}, ``verify.second_order``) on the fields that are
    even under every mirror x_i -> -x_i of the grid and odd under S (``odd_basis``),

crosses zero linearly in p at the turn. ``locate`` finds that zero at one q by the Illinois
iteration of ``events.locate_branch_point`` on S-symmetric solves (``branch.corrector``'s IPOPT,
warm), each checked to stay in the subspace (``asymmetry``, the largest change of phi under the
group) and certified as any branch point; ``line`` continues it over ``values`` of q, outward from
q0, each q predicted by the secant through the last two turns and warm from the last located
field. The restricted eigenproblem is dense and small (|nodes| / 8 in 2D): g is computed exactly up
to round-off, and its error bound is the residual of the pair in the full space on T (the M^{-1}
norm, mu_ref units, as ``verify.verdict``), which also checks that the subspace is invariant.

Example (the API; the fold of a c0 branch continued in the reduced volume)::

    import vesicle_opt as vo
    from vesicle_opt.branch.symmetric_fold import line
    b = vo.branch(scene, "c0", to=2.5, step=0.1, out="out/c0")  # its located fold (parabola) at p_f
    turn = [r for r in b.located(0) if r["event"] == "fold"][0]
    near = max(b.points(0), key=lambda r: r["target"])            # the walked point nearest the turn
    folds = line(scene, "c0", "reduced_volume", [0.79, 0.81], at=turn["target"],
                 warm=b.field(near["point"])["phi"])
    for f in folds: print(f.q, f.p, f.eigenvalue, f.error, f.converged)
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import math
import time
from pathlib import Path
from typing import ClassVar

import numpy as np
import scipy.linalg as sla

from vesicle_opt.branch import events as ev
from vesicle_opt.branch.corrector import IpoptCorrector, least_squares_multipliers
from vesicle_opt.branch.lines import LINE_COLUMNS
from vesicle_opt.branch.params import parameter
from vesicle_opt.branch.store import cell_text
from vesicle_opt.branch.transition import outward
from vesicle_opt.errors import InputError
from vesicle_opt.model import functionals as F
from vesicle_opt.nlp import build_nlp
from vesicle_opt.verify import second_order
from vesicle_opt.verify import verdict as V

ASYMMETRY_TOL = 1e-6  # a solve whose phi changes by more under the group left the subspace (measured
# on the walked branch: mirror residuals 2e-10 - 6e-9; the sheets near the turn differ by > 1e-2)
P_TOL = 1e-7  # the turn to this (the walk's zigzag there ~5e-6, NK and IPOPT's spread 6e-6)
EXPAND = 4  # bracket widenings (doubling) when p_pred +- dp has no sign change


def group(shape, axis: int) -> list[tuple[np.ndarray, int]]:
    """The group's node permutations and characters: every product of the mirrors i -> (n - i) mod n
    (one per axis, about the box's centre node) with the half shift along ``axis`` (character -1)."""
    idx = np.arange(int(np.prod(shape))).reshape(shape)
    out = []
    for flips in itertools.product((False, True), repeat=len(shape)):
        a = idx
        for ax, f in enumerate(flips):
            if f:
                a = np.roll(np.flip(a, ax), 1, axis=ax)
        for shift in (0, 1):
            b = np.roll(a, shape[axis] // 2, axis=axis) if shift else a
            out.append((b.ravel(), -1 if shift else 1))
    return out


def pair_axis(phi: np.ndarray, shape) -> int:
    """The axis along which phi is nearest its half-box shift (the droplets' axis at the turn)."""
    f = np.asarray(phi, float).reshape(shape)
    even = [ax for ax in range(len(shape)) if shape[ax] % 2 == 0]
    if not even:
        raise InputError("mesh.n", f"a half-box shift needs an even number of nodes on an axis, got {tuple(shape)}")
    return min(even, key=lambda ax: float(np.abs(np.roll(f, shape[ax] // 2, axis=ax) - f).max()))


def symmetric(phi: np.ndarray, perms) -> np.ndarray:
    """phi's projection on the fields invariant under the whole group (the mean of its images)."""
    phi = np.asarray(phi, float)
    return sum(phi[p] for p, _ in perms) / len(perms)


def asymmetry(phi: np.ndarray, perms) -> float:
    """max |phi - g phi| over the group (0 on the S-symmetric branch, up to round-off)."""
    phi = np.asarray(phi, float)
    return max(float(np.abs(phi[p] - phi).max()) for p, _ in perms)


def odd_basis(perms, n: int) -> np.ndarray:
    """An orthonormal basis (columns) of the fields with g v = chi(g) v for every g of the group
    (mirror-even, S-odd): P e_j for one node j of each orbit, P the character projector; distinct
    orbits have disjoint supports, so the columns are orthogonal."""
    inv = [np.argsort(p) for p, _ in perms]
    rep = np.min(np.stack([iv for iv in inv]), axis=0)  # the least node of each node's orbit
    cols = []
    for j in np.flatnonzero(rep == np.arange(n)):
        c = np.zeros(n)
        for (p, chi), iv in zip(perms, inv):
            c[iv[j]] += chi  # (g v)_i = v_{p(i)}: P e_j is chi(g) at i = p^-1(j)
        nrm = np.linalg.norm(c)
        if nrm > 1e-12:
            cols.append(c / nrm)
    return np.column_stack(cols)


def odd_eigenvalue(scene, disc, res, basis: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(mu, err, v): the least eigenvalue of the reduced Hessian on the odd subspace, in mu_ref
    units, its error bound (the pair's residual in the full space on T) and its mode (module
    docstring)."""
    nlp = build_nlp(scene, disc, check=False)
    H = second_order.hessian(nlp, res.x, res.lam_g)
    n = disc.n_nodes
    w = np.asarray(disc.weights, float)

    def reduced(v):  # H on phi with w = Delta_h phi (as ``verify.second_order``)
        if H.shape[0] == n:
            return H @ v
        full = H @ np.concatenate([v, disc.apply_laplacian(v)])
        return full[:n] + disc.apply_laplacian_transpose(full[n:])
    eps, C = scene.model.epsilon, scene.model.C
    grads = F.gradients(disc, res.phi, eps, C)[1:]
    onto_ab, _ = second_order.tangent_projector(np.column_stack(grads), disc.solve_mass)
    Q = np.column_stack([onto_ab(basis[:, j]) for j in range(basis.shape[1])])
    HQ = np.column_stack([reduced(Q[:, j]) for j in range(Q.shape[1])])
    A, B = Q.T @ HQ, Q.T @ (w[:, None] * Q)
    mu_ref = V.mu_ref(scene.model.rigidity, eps, nlp.beta, disc.dim)
    mus, Y = sla.eigh((A + A.T) / 2, (B + B.T) / 2)
    v = Q @ Y[:, 0]
    trans = second_order.translation_modes(disc, res.phi)
    _, on_t = second_order.tangent_projector(np.column_stack([*grads, *(w * t for t in trans)]), disc.solve_mass)
    r = on_t(reduced(v) - mus[0] * w * v)
    err = math.sqrt(max(float(r @ disc.solve_mass(r)), 0.0)) / math.sqrt(float(v @ (w * v))) / mu_ref
    floor = np.finfo(float).eps * float(np.abs(mus).max()) / mu_ref  # round-off of the dense solve
    return float(mus[0] / mu_ref), max(err, floor), v / math.sqrt(float(v @ (w * v)))


@dataclasses.dataclass
class Turn:
    """The symmetric turn at one q: p (None: not found, ``reason``), its energy, the odd
    eigenvalue there and its bound, the final bracket in p, the located point's asymmetry, solves,
    and the wall and CPU seconds it took."""

    q: float
    p: float | None
    energy: float | None
    eigenvalue: float
    error: float
    bracket: float
    asymmetry: float
    solves: int
    wall: float
    cpu: float
    point: ev.Point | None = dataclasses.field(default=None, repr=False)
    reason: str | None = None
    kind: ClassVar[str] = "symmetric"  # fold_line.csv's fold_kind

    @property
    def converged(self) -> bool:
        return self.reason is None


class SymmetricSolver:
    """S-symmetric certified solves of ``scene`` at (p, q) and their odd eigenvalue."""

    def __init__(self, scene, param: str, second: str, axis: int | None, warm: np.ndarray, options=None):
        self.corr = IpoptCorrector(scene, options)
        self.disc, self.param, self.second = self.corr.disc, parameter(scene, param), parameter(scene, second)
        self.scene, shape = scene, tuple(self.disc.grid_shape)
        if warm.shape != (self.disc.n_nodes,):
            raise InputError("warm", f"a field of {self.disc.n_nodes} nodes (the scene's grid), got shape {warm.shape}")
        self.axis = pair_axis(warm, shape) if axis is None else axis
        self.perms = group(shape, self.axis)
        self.basis = odd_basis(self.perms, self.disc.n_nodes)
        self.solves = 0

    def scene_at(self, p: float, q: float):
        if self.second.name == "c0":  # c0 first: its scene_at resets the constraints
            return self.param.scene_at(self.second.scene_at(self.scene, q), p)
        return self.second.scene_at(self.param.scene_at(self.scene, p), q)

    def point(self, p: float, q: float, phi0, lam0=None) -> ev.Point | None:
        """The certified S-symmetric point at (p, q) from phi0 (symmetrised), None where the solve
        failed or left the subspace."""
        sc = self.scene_at(p, q)
        phi0 = symmetric(phi0, self.perms)
        self.solves += 1
        try:
            lam = lam0 if lam0 is not None else least_squares_multipliers(sc, self.disc, phi0)
            res = self.corr.solve(sc, phi0, lam, feasibility=False)
            if not res.converged:
                res = self.corr.solve(sc, phi0, None, feasibility=False)
        except InputError:
            return None
        if not res.converged or asymmetry(res.phi, self.perms) > ASYMMETRY_TOL:
            return None
        mu, err, _ = odd_eigenvalue(sc, self.disc, res, self.basis)
        return ev.Point(float(p), np.asarray(res.phi, float), res.energy, (mu,), (err,),
                        (res.lambda_volume, res.lambda_area), res)


def locate(solver: SymmetricSolver, q: float, p_pred: float, dp: float, phi0, lam0=None) -> Turn:
    """The zero of the odd eigenvalue at q near ``p_pred``: a bracket p_pred -+ dp (widened,
    doubling, until one end's eigenvalue is decidedly negative and the other's not), then the Illinois
    iteration to ``P_TOL`` or to the eigenvalue's own bound (``events.locate_branch_point``)."""
    t0, c0, s0 = time.perf_counter(), time.process_time(), solver.solves

    def done(reason, loc=None, pt=None):
        pt = pt if loc is None else loc.point
        mu, err = (pt.eigenvalues[0], pt.errors[0]) if pt is not None else (math.nan, math.nan)
        return Turn(q, None if reason else pt.p, None if reason else pt.energy, mu, err,
                    math.nan if loc is None else loc.bracket,
                    math.nan if pt is None else asymmetry(pt.phi, solver.perms), solver.solves - s0,
                    time.perf_counter() - t0, time.process_time() - c0, pt, reason)
    mid = solver.point(p_pred, q, phi0, lam0)
    if mid is None:
        return done(f"no symmetric point at p = {p_pred:.8g}")
    a = b = mid
    for _ in range(EXPAND + 1):
        lo = solver.point(p_pred - dp, q, mid.phi, mid.lam)
        hi = solver.point(p_pred + dp, q, mid.phi, mid.lam)
        if lo is None or hi is None:
            return done(f"no symmetric point at p = {p_pred:.8g} -+ {dp:.3g}", pt=mid)
        for x, y in ((lo, mid), (mid, hi)):
            if x.decided != y.decided:  # one decidedly negative, the other not (``events.decided``)
                a, b = x, y
        if a is not b:
            break
        dp *= 2
    else:
        return done(f"the odd eigenvalue keeps its sign within {dp:.3g} of p = {p_pred:.8g}", pt=mid)
    loc = ev.locate_branch_point(lambda p, phi, lam: solver.point(p, q, phi, lam), a, b, P_TOL)
    if loc.point is None:
        return done(f"the location failed ({loc.located_by})", pt=mid)
    if abs(loc.eigenvalue) > loc.error and loc.bracket > P_TOL:
        return done(f"not located: |mu| = {abs(loc.eigenvalue):.3g} > its bound {loc.error:.3g}", loc)
    return done(None, loc)


def check(scene, param: str, second: str, dp: float = 1e-3) -> None:
    """The arguments of a line, before any work (InputError naming the flag or key)."""
    if param not in ("reduced_volume", "c0") or second not in ("reduced_volume", "c0") or param == second:
        raise InputError("--second", f"a fold line runs in one of reduced_volume, c0 and is continued in the "
                         f"other, got {param!r}, {second!r}")
    if scene.mesh.kind not in ("fd", "spectral") or scene.domain.boundary != "periodic" or scene.dim != 2:
        raise InputError("mesh.kind", "a symmetric turn's line needs a periodic 2D fd or spectral grid (its "
                         "half-box shift)")
    if isinstance(dp, bool) or not (isinstance(dp, (int, float)) and dp > 0):
        raise InputError("dp", f"allowed range > 0, got {dp!r}")


def line(scene, param: str, second: str, values, *, at: float, warm, dp: float = 1e-3, axis: int | None = None,
         options=None, progress=None) -> list[Turn]:
    """The symmetric turn of ``scene``'s branch in ``param`` near ``at`` (a warm field near it, e.g.
    the walked point nearest the located fold), continued in ``second`` from the scene's value to
    each of ``values``, outward (module docstring); a failure ends its direction."""
    check(scene, param, second, dp)
    solver = SymmetricSolver(scene, param, second, axis, np.asarray(warm, float), options)
    q0 = solver.second.start

    def step(q: float, past: list[Turn]) -> Turn:
        if not past:  # the start
            pred, phi, lam = float(at), warm, None
        else:
            last = past[-1]
            pred = last.p if len(past) < 2 else last.p + (q - last.q) * (last.p - past[-2].p) / (last.q - past[-2].q)
            phi, lam = last.point.phi, last.point.lam
        return locate(solver, q, pred, dp, phi, lam)
    return outward(q0, [float(v) for v in values], step, progress)


COLUMNS = LINE_COLUMNS + ["converged", "reason", "bracket", "asymmetry", "solves", "wall_time_s", "cpu_time_s",
                          "fold_kind", "critical", "sheet_a_target", "sheet_b_target", "vertex_target"]
# fold_kind: "symmetric" (this module's turns) or "ordinary" (``branch.ordinary_fold``); the last four are
# the ordinary fold's (the critical eigenvalue's position, p on its two sheets' points, the parabola's vertex)


def from_branch(b, second: str, values, *, dp: float = 1e-3, options=None, progress=None) -> list[Turn]:
    """The line of the first located fold of a walked branch run ``b`` (``branch.run.Branch``, run
    with ``out``: its snapshots give the warm field, the walked point nearest the fold), continued
    in ``second`` to each of ``values``; ``out/fold_line.csv`` (``COLUMNS``: ``branch.lines``'
    columns, ``located_by`` = ``symmetric``, and the line's own; ``fold_kind`` = ``symmetric``) where
    the run has ``out``. No
    located fold: []."""
    folds = [r for r in b.located(0) if r["event"] == ev.FOLD]
    if not folds:
        return []
    if b.out is None:
        raise InputError("out", "the branch run kept no snapshots: run it with out= for the warm field")
    at = folds[0]["target"]
    near = min(b.points(0), key=lambda r: abs(r["target"] - at))
    turns = line(b.scene, b.param, second, values, at=at, warm=b.field(near["point"])["phi"], dp=dp,
                 options=options, progress=progress)
    rows = [{"second": second, "value": t.q, "param": b.param, "target": t.p, "energy": t.energy,
             "reduced_energy": None if t.point is None or t.p is None else t.point.payload.extra.get("reduced_energy"),
             "branch": 0, "located_by": "symmetric", "detected_at": None, "critical_eigenvalue": t.eigenvalue,
             "critical_error": t.error, "converged": t.converged, "reason": t.reason, "bracket": t.bracket,
             "asymmetry": t.asymmetry, "solves": t.solves, "wall_time_s": t.wall, "cpu_time_s": t.cpu,
             "fold_kind": "symmetric"} for t in turns]
    with open(Path(b.out) / "fold_line.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, COLUMNS, lineterminator="\n")
        w.writeheader()
        w.writerows({k: cell_text(v) for k, v in r.items()} for r in rows)
    return turns
