"""Energy diagrams: branches of equilibria in the reduced volume (``vesicle_opt.branch``).

2D: the closed-elastica branch from nu = 0.95 down to 0.5 (FD 128^2, box [-4, 4]^2, eps = 0.2,
perimeter S = 8, so R0 = S / 2 pi = 1.27), started from an ellipse; and the branch the solver
finds from the symmetric (circle) start, a saddle, followed as far as it holds.

3D (area 4 pi, so R0 = 1; Fourier spectral, Newton-Krylov, exact constraints): the prolate and the
oblate branch from v = 0.75 down to 0.575 (the sharp crossing is at v* = 0.651) at each eps of
``EPS_SEQUENCE``, started from a prolate and an oblate ellipsoid, each in a periodic box fitted to
its shape (``fitted_box``: the sharp extent ``EXTENT`` plus 8 eps of free space on every axis, one
spacing h = eps / 2.5); their crossing per eps (v and reduced energy, ``branch.crossing``: cubic splines of the
two branches, over the points that are closed vesicles of the branch's own form:
``form`` and ``topology``), and its eps -> 0 extrapolation (``extrapolate_crossing``).

Why no cubic box: in [-3, 3]^3 at 64^3, eps = 0.2, both the prolate start (v = 0.95) and the oblate
start (v = 0.75) ended on a round state (second moments isotropic, aspect 1.00, the same {phi > 0}
of 4801 nodes at every v from 0.95 to 0.55): the outer bulk of phi sits below -1 by a uniform
delta ~ -lambda_A eps^3 / 4 that takes up delta |Omega_out| / 2 of the volume constraint
int phi = alpha (its energy ~ 2 delta^2 / eps^3 per unit volume: for a given volume taken up it
falls like 1 / |Omega| as the box grows, and like eps^3 it vanishes as eps -> 0). ``bulk_offset``
is recorded for every point. A box fitted to the shape makes that state costly.

Margin to the periodic images: every row has ``image_gap`` = the box side minus the extent of
{phi > 0} along the worst axis (the free space between the shape and its image, in units of
length; ``gap_over_eps`` = that over eps), and the topology columns of the branch say when a shape
joins its image (``wraps``).

Each branch is one case of the study runner (any executor; each branch also resumes point by
point in its own directory ``<out>/<case>/``). ``--quick``: the two 2D branches on a coarse grid
in a box fitted to them (``QUICK_2D``: [-2.4, 2.4]^2 at 48^2, eps = 0.2, nu 0.95 -> 0.85). ``sharp_reduced_energy`` is the eps -> 0
reference of the point's reduced volume (``sharp_reference``: the 2D elastica, the 3D axisymmetric
prolate / oblate vesicle), and the JSON's ``crossing_3d_sharp`` the sharp prolate/oblate crossing
beside the phase-field ``crossing_3d_eps`` (per eps) and ``crossing_3d_extrapolated``.

Writes ``energy_diagram.csv`` (all rows), ``energy_diagram.png``, ``energy_diagram.json``
(points, certified counts, envelope residuals, wall times, the 3D crossing).
"""

from __future__ import annotations

import logging

import math
from pathlib import Path

import numpy as np

from vesicle_opt.branch import COLUMNS, branch, diagram
from vesicle_opt.branch.crossing import crossing, extrapolate_crossing
from vesicle_opt.io.files import load_npz
from vesicle_opt.mesh.base import grid_points
from vesicle_opt.mesh.spectral import even_fft_size
from vesicle_opt.scene.schema import from_dict
from vesicle_opt.sharp import axisymmetric, elastica
from vesicle_opt.studies._common import human, num, select
from vesicle_opt.studies.runner import run_study

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

NAME = "energy_diagram"
# the eps sequence of the 3D crossing: boxes fitted to each branch (``fitted_box``), uniform h = eps / 2.5
# (the 3D spectral grid error at eps/h = 2.13 is 1.8e-8 in the reduced energy: prolate v = 0.95,
# eps = 0.2, 64^3 against 96^3, measured), GAP_OVER_EPS eps of free space to the periodic image
EPS_OVER_H_FITTED = 2.5
GAP_OVER_EPS = 8.0  # the tanh tails of a shape and its image overlap ~ exp(-sqrt 2 gap / eps) ~ 1e-5
EPS_SEQUENCE = (0.2, 0.14, 0.1)
SEQUENCE_V = (0.75, 0.575)  # the branches of the sequence run from 0.75 down to 0.575 (the crossing ~0.65)
# sharp extents (vesicle_opt.sharp.axisymmetric, area 4 pi) over v in [0.575, 0.75]: prolate length
# 4.845 (v = 0.575) and width 1.225 (v = 0.75); oblate width 2.482 (v = 0.575), thickness 0.813 (0.75)
# --quick: a box fitted to the 2D shapes (R0 = 1.27; at nu = 0.85 the elastica spans ~3.2) at
# eps/h = 2, at least 7.5 eps of free space to the image (measured). The former quick setting (eps 0.4
# in [-4, 4]^2) left the circle start's bulk carrying 20 % of V (its share grows like eps^3 |Omega_out|),
# which verify.shape rightly refused as wrong_shape; here the bulk offset is 0.001-0.006 and both
# branches are certified (the symmetric one a saddle at every point: measured)
QUICK_2D = {"half_box": 2.4, "n": 48, "epsilon": 0.2, "to": 0.85, "step": -0.05}
EXTENT = {"prolate": (4.85, 1.23, 1.23), "oblate": (2.49, 2.49, 0.82)}


def sharp_reference(case: dict):
    """The sharp-interface reference of a case's column ``sharp_reduced_energy``: f(param, value,
    dim) -> the reduced energy of the eps -> 0 shape at that reduced volume, computed by
    ``vesicle_opt.sharp`` (no code shared with the phase-field path): the 2D elastica (its 2-fold
    minimum; the symmetric-start case follows a saddle branch and gets none), the 3D axisymmetric
    prolate / oblate vesicle of the case's branch. None where no reference applies."""
    which = {"elastica-2d": "elastica"}.get(case["case"])
    which = next((f for f in ("prolate", "oblate") if case["case"].startswith(f)), which)

    def f(param: str, value: float, dim: int):
        if which is None or param != "reduced_volume" or not 0 < value < 1:
            return None
        sol = elastica.solve(value) if which == "elastica" else axisymmetric.solve(value, which)
        return float(sol.reduced_energy) if sol.converged else None
    return f
EXTRA = [c for c in COLUMNS if c != "case"] + ["image_gap", "gap_over_eps", "form", "aspect", "branch_stopped",
                                              "bulk_offset"]


def scene(case: dict):
    """The scene of a case (plain data, so that cases pickle): the cubic box [-half_box, half_box]^dim,
    or the case's own ``box`` (the fitted boxes of the eps sequence)."""
    box = case.get("box") or [[-case["half_box"], case["half_box"]]] * case["dim"]
    raw = {"domain": {"box": box, "boundary": "periodic"},
           "mesh": {"kind": case["mesh"], "n": case["n"]}, "model": {"epsilon": case["epsilon"]},
           "constraints": {"reduced_volume": case["start_v"], "area": case["area"]},
           "initial": case["initial"],
           "solver": {"method": "exact", "tol": 1e-8, "backend": case["backend"], "max_iter": case["max_iter"]}}
    return from_dict(raw, case["case"])


def fitted_box(extent: tuple[float, float, float], epsilon: float, eps_over_h: float = EPS_OVER_H_FITTED,
               gap_over_eps: float = GAP_OVER_EPS) -> tuple[list[list[float]], list[int]]:
    """(box, n) of a periodic box centred at 0 holding a shape of this sharp extent with ``gap_over_eps``
    eps of free space to its image on every axis, at the uniform spacing h = eps / eps_over_h (h
    rounded down so that every side is n h with n an even 5-smooth integer)."""
    h = epsilon / eps_over_h
    n = [even_fft_size(max(4.0, (e + gap_over_eps * epsilon) / h)) for e in extent]
    return [[-k * h / 2, k * h / 2] for k in n], n


def cases(quick: bool) -> list[dict]:
    d2 = {"dim": 2, "half_box": 4.0, "mesh": "fd", "n": 128, "epsilon": 0.2, "area": 8.0, "start_v": 0.95,
          "to": 0.5, "step": -0.015, "backend": "ipopt",
          "max_iter": 400}  # the cold start only: warm points are capped at 6 IPOPT iterations by the
    # branch's corrector (branch.corrector.WARM_MAX_ITER; they take 2-4). Measured at 128^2: the
    # ellipse start 14 iterations, the circle start 160 (60 left it unconverged: "start failed")
    if quick:
        d2.update(QUICK_2D)
    out = [{**d2, "case": "elastica-2d", "initial": {"shape": "ellipse", "semi_axes": [1.45, 1.1]}},
           {**d2, "case": "symmetric-2d", "initial": {"shape": "circle", "radius": 1.27}}]
    if quick:
        return out
    d3 = {"dim": 3, "mesh": "spectral", "epsilon": 0.2, "area": 4 * math.pi, "step": -0.025,
          "backend": "newton-krylov", "max_iter": 500}
    # no cubic box: in [-3, 3]^3 (64^3, eps = 0.2) every start (prolate v = 0.95, oblate v = 0.75) ended
    # on a round state whose bulk absorbs the volume constraint (module docstring, ``bulk_offset``)
    seq = []
    for eps in EPS_SEQUENCE:
        for f, axes in (("prolate", [1.6, 0.7, 0.7]), ("oblate", [1.2, 1.2, 0.4])):
            box, n = fitted_box(EXTENT[f], eps)
            seq.append({**d3, "case": f"{f}-3d-eps{eps:g}", "box": box, "n": n, "epsilon": eps,
                        "start_v": SEQUENCE_V[0], "to": SEQUENCE_V[1], "sequence": eps,
                        "initial": {"shape": "ellipsoid", "semi_axes": axes}})
    return out + seq


def bulk_offset(snapshot: dict) -> float:
    """1 + the median of phi over the nodes with phi < -0.5. Far from the interface the KKT equation
    of a node gives phi = -1 - delta with delta ~ -lambda_A eps^3 / (4 rigidity) (checked by a test
    to 1e-6), so the bulk takes up delta |Omega_out| / 2 of the volume constraint: ~0.015-0.02 in
    the 6^3 box's round states, 0.025-0.041 on the fitted eps = 0.2 prolate branch (measured)."""
    phi = np.asarray(snapshot["phi"]).ravel()
    out = phi[phi < -0.5]
    return float(1 + np.median(out)) if out.size else math.nan


def image_gap(snapshot: dict, epsilon: float) -> tuple[float, float]:
    """(box side - extent of {phi > 0}) on the worst axis, and that over eps, from a grid snapshot."""
    grid = tuple(int(k) for k in np.atleast_1d(snapshot["grid_shape"]))
    inside = np.asarray(snapshot["phi"]).reshape(grid) > 0
    box = np.asarray(snapshot["box"], float)
    gaps = []
    for ax in range(len(grid)):
        occupied = np.any(inside, axis=tuple(a for a in range(len(grid)) if a != ax))
        side = box[ax, 1] - box[ax, 0]
        gaps.append(side * (1 - occupied.sum() / grid[ax]))  # the free cells' length along this axis
    g = float(min(gaps))
    return g, g / epsilon


def form(snapshot: dict) -> tuple[str, float]:
    """(prolate | oblate | round, the ratio of the largest to the smallest principal semi-axis) of
    {phi > 0} from the second moments of its grid nodes (the shapes here are centred and do not
    wrap). 2D: "elongated" or "round"."""
    grid = tuple(int(k) for k in np.atleast_1d(snapshot["grid_shape"]))
    box = np.asarray(snapshot["box"], float)
    axes = [np.linspace(lo, hi, k, endpoint=False) for (lo, hi), k in zip(box, grid)]
    pts = grid_points(axes)
    inside = pts[np.asarray(snapshot["phi"]).ravel() > 0]
    ev = np.sort(np.linalg.eigvalsh(np.cov(inside.T)))
    ratio = float(np.sqrt(ev[-1] / ev[0]))
    if ratio < 1.05:
        return "round", ratio
    if len(grid) == 2:
        return "elongated", ratio
    # prolate: the middle axis near the smallest; oblate: near the largest
    return ("prolate" if ev[1] - ev[0] < ev[2] - ev[1] else "oblate"), ratio


def run(case: dict) -> list[dict]:
    out = Path(case["out"]) / case["case"]
    b = branch(scene(case), "reduced_volume", to=case["to"], step=case["step"], out=out, switch=False,
               reference=sharp_reference(case))
    rows = []
    for r in b.rows:
        row = {**r, "scene": case["case"], "method": "exact", "branch_stopped": b.stopped[r["branch"]]}
        snap = load_npz(out / "points" / f"point-{int(r['point']):04d}.npz") if r["accepted"] else None
        if snap is not None:
            row["image_gap"], row["gap_over_eps"] = image_gap(snap, case["epsilon"])
            row["form"], row["aspect"] = form(snap)
            row["bulk_offset"] = bulk_offset(snap)
        rows.append(row)
    return rows


def summary(rows: list[dict], case_list: list[dict]) -> dict:
    out = {}
    for c in case_list:
        sel = select(rows, scene=c["case"])
        acc = [r for r in sel if str(r.get("accepted")) in ("True", "true")]
        env = [num(r.get("envelope_residual")) for r in acc if r.get("envelope_residual") not in (None, "")]
        steps = [abs(num(x["target"]) - num(y["target"])) for x, y in zip(acc, acc[1:])]
        out[c["case"]] = {
            "points": len(acc), "attempts": len(sel),
            "certified": sum(str(r.get("converged")) in ("True", "true") for r in acc),
            "minimum": sum(r.get("second_order") == "minimum" for r in acc),
            "saddle": sum(r.get("second_order") == "saddle" for r in acc),
            "marginal": sum(r.get("second_order") == "marginal" for r in acc),  # zero within its bound
            "not_checked": sum(r.get("second_order") not in ("minimum", "saddle", "marginal") for r in acc),
            "stopped": sel[-1].get("branch_stopped") if sel else None,
            "reduced_volume_range": [num(acc[0]["reduced_volume"]), num(acc[-1]["reduced_volume"])] if acc else None,
            "wall_time_s": float(np.nansum([num(r.get("wall_time_s")) for r in sel])),
            "envelope_residual_max": max(env) if env else None,
            "max_step": max(steps) if steps else None,
            "envelope_over_step2_max": max(e / s**2 for e, s in zip(env, steps)) if env and steps else None,
            "min_image_gap_over_eps": min((num(r.get("gap_over_eps")) for r in acc), default=None),
        }
    def acc(rs, shape):  # accepted points that are closed vesicles of the branch's own shape
        return [r for r in rs if str(r.get("accepted")) in ("True", "true") and r.get("form") == shape
                and str(r.get("topology", "")).startswith("sphere-like")]
    seq = sorted({c["sequence"] for c in case_list if "sequence" in c}, reverse=True)
    per_eps = {}
    for eps in seq:
        pro = acc(select(rows, scene=f"prolate-3d-eps{eps:g}"), "prolate")
        obl = acc(select(rows, scene=f"oblate-3d-eps{eps:g}"), "oblate")
        x = crossing([num(r["reduced_volume"]) for r in pro], [num(r["reduced_energy"]) for r in pro],
                     [num(r["reduced_volume"]) for r in obl], [num(r["reduced_energy"]) for r in obl])
        if x is not None:
            per_eps[eps] = x
    if per_eps:
        out["crossing_3d_eps"] = {f"{e:g}": x for e, x in per_eps.items()}
        out["crossing_3d_extrapolated"] = extrapolate_crossing(per_eps)
    if seq:
        v_s, e_s = axisymmetric.crossing()  # the sharp-interface crossing (vesicle_opt.sharp)
        out["crossing_3d_sharp"] = {"reduced_volume": v_s, "reduced_energy": e_s}
    return out


def main(out: Path, quick: bool = False, executor=None, workers: int = 1) -> int:
    out = Path(out)
    case_list = [{**c, "out": str(out)} for c in cases(quick)]
    rows, info = run_study(NAME, case_list, run, summary, out, executor, workers, EXTRA)
    series = []
    for c in case_list:
        b_dir = out / c["case"]
        acc = [r for r in select(rows, scene=c["case"]) if str(r.get("accepted")) in ("True", "true")]
        parsed = [{"point": int(num(r["point"])), "target": num(r["target"]),
                   "reduced_energy": num(r["reduced_energy"]), "second_order_min_eigenvalue": num(r.get("second_order_min_eigenvalue")), "accepted": True,
                   "branch": 0} for r in acc]
        series.append((c["case"], parsed, b_dir / "points"))
    for dim in (2, 3):
        mine = [s for s, c in zip(series, case_list) if c["dim"] == dim]
        if mine:
            diagram.plot(mine, out / f"{NAME}-{dim}d.png", xlabel="reduced volume", dim=dim,
                         title=f"{dim}D energy diagram (solid: stable, dashed: unstable)")
    for name, v in info.items():
        log.info(f"{NAME}: {name}: {human(v)}")
    ok = all(v["points"] >= 2 and v["certified"] == v["points"] for k, v in info.items() if not k.startswith("crossing_3d"))
    return 0 if ok else 1
