"""The 3D prolate/oblate crossing and its eps -> 0 limit, on mirror grids (one octant).

Prolate and oblate vesicles are mirror-symmetric in the three coordinate planes, so each is solved on
the octant [0, L_x] x [0, L_y] x [0, L_z] with natural boundaries, ``mesh.kind = "spectral"``,
``domain.boundary = "natural"`` (``mesh.cosine``: the cosine-series grid, exactly the Fourier
spectral grid of the doubled periodic box restricted to even fields; 8x fewer nodes). The scene's
targets and every reported quantity (volume, area, energy, reduced volume and energy) are the full
vesicle's (``mesh.cosine``'s scaling convention). The second-order check on this grid sees only
mirror-symmetric perturbations: ``second_order = "minimum"`` here means a minimum within that class
(the column ``second_order_excluded`` says so), never more.

Per eps of ``EPS_SEQUENCE``: the prolate and the oblate branch at the v of ``V_RANGE`` in steps of
``V_STEP`` (plus ``V_DENSE`` at ``DENSE_EPS``; the finest eps from 0.71 to ``FINEST_V_END`` only),
each point the front door's exact-constraint Newton-Krylov solve (tol 1e-8, area 4 pi, so R0 = 1)
warm-started from the branch's previous point, the first cold from a prolate / oblate ellipsoid
centred at the corner 0; on a box fitted to the branch's sharp half-extent over that range
(``HALF_EXTENT``, from ``vesicle_opt.sharp.axisymmetric``) plus ``GAP_OVER_EPS`` / 2 eps, so that
the free space to the mirror image across a far face is ``GAP_OVER_EPS`` eps; uniform spacing
h = eps / ``EPS_OVER_H`` (``octant_box``). The crossing per eps (``crossing``): a cubic spline of
each branch's reduced energy in v through its points that are certified closed vesicles of the
branch's own form (``form`` on the unfolded field, topology sphere-like), the root of the
difference inside both ranges (on the sharp branches at the same v grid it recovers the sharp
crossing to 2e-6 in v, 8e-6 in e; linear interpolation: ~5e-4); its eps -> 0 limit
(``extrapolate``): Richardson with free order through the three finest eps (the observed order),
with fixed order 2 through the two finest, and the least-squares line in eps^2 through all,
against the sharp crossing v* = 0.651076, e* = 1.823471 (``sharp.axisymmetric.crossing``,
computed here; the literature reference for the prolate/oblate crossing of the
spontaneous-curvature model at c0 = 0 is Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991),
whose value, v ~ 0.652, is quoted from memory and was not checked against the paper). Each
point's reduced energy is compared with the sharp prolate / oblate at its v (one warm-started
sharp branch per run, ``summary``'s ``sharp_branches``) and the errors' observed order in eps
fitted (``metrics.observed_order``, ``energy_error_vs_sharp``).

Measured (full run, 2 shared cores, load 2-5; ``vesicle-opt study crossing_3d``): the crossing v =
0.68309, 0.67424, 0.66741, 0.65914 and reduced energy 1.81530, 1.81937, 1.82020, 1.82179 at eps =
0.07, 0.06, 0.05, 0.035 (v - v* = 0.0320, 0.0232, 0.0163, 0.0081: observed order 1.98); fixed
order 2 from the two finest: v = 0.651206, e = 1.823307 (1.3e-4 and -1.6e-4 from v*, e*); free-order
Richardson on v through the three finest: 0.650185 (order 1.83); least squares in eps^2 through all
four: v = 0.651132, e = 1.824312; on e no free-order Richardson (its differences are not
monotone: 4.1e-3 then 8e-4 then 1.6e-3). The branch energies' error against the sharp ones is
O(eps^2): prolate 0.207, 0.095, 0.046, 0.022 at v = 0.71 (order 2.14 over eps = 0.1 ... 0.035),
oblate 0.071, 0.052, 0.036, 0.017 (order 2.03). Not every eps has both branches near the crossing:
the oblate opens into a torus (genus 1, lower energy: tori reach the Willmore bound pi/2 ~ 1.57 in
reduced units) once the discocyte's centre is thinner than ~6.5 eps: at every v for eps = 0.1, below
0.68 for 0.07, 0.66 for 0.06, 0.65 for 0.05 (the sharp centre thickness is 0.55 at v = 0.71, 0.38 at
0.65); and the prolate at v = 0.59 joins its mirror image across the far face (a tube: "wraps") at
eps = 0.07 and 0.05, longer than the sharp shape. Those points stay in the CSV and are left out of
the crossing (``good_points``). eps = 0.1 therefore has no crossing. Nodes and time per point (the
runner's case time, solve and check): eps = 0.035 prolate 524 880 (4.2 M in the doubled box) 242-372 s,
oblate 400 000 84-129 s; eps = 0.05 205 k / 192 k 15-65 s; eps = 0.06 156 k / 123 k 4-13 s.

Each point (eps, form, v) is one case of the study runner (a row appended as it finishes; a killed
run resumes at the next point, warm-started from the certified field saved in ``<out>/<branch>/``). ``--quick``: eps = 0.25 only, v 0.71 -> 0.67 (a smoke run).
Writes ``crossing_3d.csv``, ``crossing_3d.json``, ``crossing_3d.png`` (the energy diagram near the crossing).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from vesicle_opt.api import solve
from vesicle_opt.branch.crossing import crossing, extrapolate_crossing
from vesicle_opt.io.files import json_safe, load_npz, save_npz
from vesicle_opt.mesh import cosine
from vesicle_opt.mesh.base import grid_points
from vesicle_opt.mesh.spectral import even_fft_size
from vesicle_opt.scene.schema import from_dict
from vesicle_opt.sharp import axisymmetric
from vesicle_opt.studies._common import human, num, plt, savefig, select
from vesicle_opt.studies.runner import run_study
from vesicle_opt.verify.metrics import observed_order

log = logging.getLogger(__name__)

NAME = "crossing_3d"
EPS_SEQUENCE = (0.1, 0.07, 0.06, 0.05, 0.035)
EPS_OVER_H = 2.5  # the spacing of the earlier fitted periodic boxes (energy_diagram), for comparison
GAP_OVER_EPS = 8.0  # free space to the mirror image: tanh tails overlap ~ exp(-sqrt 2 * 8) ~ 1e-5
V_RANGE = (0.71, 0.59)
V_STEP = -0.02
AREA = 4 * math.pi
# sharp half-extents over v in [0.59, 0.71] (sharp.axisymmetric, area 4 pi; long / symmetry axis x
# for the prolate, z for the oblate): prolate half-length 2.352 (v = 0.59), half-width 0.590 (0.71);
# oblate radius 1.240 (0.59), half-thickness 0.382 (0.71)
HALF_EXTENT = {"prolate": (2.36, 0.60, 0.60), "oblate": (1.25, 1.25, 0.39)}
START_AXES = {"prolate": [1.75, 0.65, 0.65], "oblate": [1.25, 1.25, 0.4]}  # ellipsoids near v = 0.71
V_DENSE = (0.70, 0.68, 0.66)  # added at DENSE_EPS: there the oblate opens into a torus just below the
DENSE_EPS = (0.07, 0.06)  # crossing (measured: at v = 0.67 for eps = 0.07, 0.63 for 0.05)
FINEST_V_END = 0.65  # the finest eps stops here: its crossing lies near 0.66 and a point costs ~5 min
# (525 k nodes, 2 shared cores, load ~4), the points below would not move it
V_QUICK = (0.71, 0.69)
TOL = 1e-8  # the exact solve's KKT tolerance (the energy_diagram branches' value)


def octant_box(half_extent, epsilon: float, eps_over_h: float = EPS_OVER_H,
               gap_over_eps: float = GAP_OVER_EPS) -> tuple[list[list[float]], list[int]]:
    """(box, n): [0, L_i] with L_i = n_i h >= half_extent_i + gap_over_eps eps / 2, h = eps / eps_over_h,
    n_i even and 5-smooth (coarse levels halve it)."""
    h = epsilon / eps_over_h
    n = [even_fft_size(max(4.0, (e + gap_over_eps * epsilon / 2) / h)) for e in half_extent]
    return [[0.0, k * h] for k in n], n


def cases(quick: bool) -> list[dict]:
    """One case per (eps, form, v), in the order they run (one worker): each branch's v descending,
    so that a point warm-starts from the one before it (``run``)."""
    seq = (0.25,) if quick else EPS_SEQUENCE
    base = tuple(round(V_RANGE[0] + k * V_STEP, 6) for k in range(int(round((V_RANGE[1] - V_RANGE[0]) / V_STEP)) + 1))
    out = []
    for eps in seq:
        vs = V_QUICK if quick else tuple(sorted(set(base) | (set(V_DENSE) if eps in DENSE_EPS else set()),
                                                reverse=True))
        if not quick and eps == min(seq):
            vs = tuple(v for v in vs if v >= FINEST_V_END)
        for f in ("prolate", "oblate"):
            box, n = octant_box(HALF_EXTENT[f], eps)
            for i, v in enumerate(vs):
                out.append({"case": f"{f}-eps{eps:g}-v{v:g}", "branch": f"{f}-eps{eps:g}", "form": f,
                            "epsilon": eps, "box": box, "n": n, "v": v, "previous_v": vs[i - 1] if i else None,
                            "area": AREA, "max_iter": 500,
                            "initial": {"shape": "ellipsoid", "semi_axes": START_AXES[f], "center": [0.0, 0.0, 0.0]}})
    return out


def scene(case: dict):
    raw = {"domain": {"box": case["box"], "boundary": "natural"},
           "mesh": {"kind": "spectral", "n": case["n"]}, "model": {"epsilon": case["epsilon"]},
           "constraints": {"reduced_volume": case["v"], "area": case["area"]},
           "initial": case["initial"],
           "solver": {"method": "exact", "tol": TOL, "backend": "newton-krylov", "max_iter": case["max_iter"]}}
    return from_dict(raw, case["case"])


def _field_path(case: dict, v: float) -> Path:
    return Path(case["out"]) / case["branch"] / f"phi-v{v:g}.npz"


def run(case: dict) -> list[dict]:
    """One point: the front door at (eps, form, v), warm-started from the branch's previous point
    (its certified field, saved beside the CSV) or, for the first point or after a failure, cold
    from the case's ellipsoid (nested iteration from coarser grids)."""
    sc = scene(case)
    prev = None if case["previous_v"] is None else load_npz(_field_path(case, case["previous_v"]))
    r = solve(sc, x0=None if prev is None else prev["phi"], throw=False)
    ex = r.extra
    snap = {"phi": r.phi, "grid_shape": np.array(case["n"]), "box": np.array(case["box"])}
    found, aspect = form(snap)
    gap, gap_eps = image_gap(snap, case["epsilon"])
    if r.converged:
        save_npz(_field_path(case, case["v"]), phi=r.phi)
    return [{"scene": case["branch"], "method": "exact", "n": "x".join(map(str, case["n"])),
             "h": case["epsilon"] / EPS_OVER_H, "energy": r.energy, "volume_residual": r.volume_residual,
             "area_residual": r.area_residual, "lambda_volume": r.lambda_volume, "lambda_area": r.lambda_area,
             "iterations": r.iterations, "wall_time_s": r.wall_time_s, "status": str(r.outcome),
             "branch_form": case["form"], "epsilon": case["epsilon"], "nodes": int(np.prod(case["n"])),
             "target_v": case["v"], "start": "cold" if prev is None else "warm",
             "reduced_volume": ex.get("reduced_volume"), "reduced_energy": ex.get("reduced_energy"),
             "volume": ex.get("volume"), "area": ex.get("area"), "kkt_residual": r.kkt_residual,
             "converged": r.converged, "second_order": ex.get("second_order"),
             "second_order_min_eigenvalue": ex.get("second_order_min_eigenvalue"),
             "second_order_excluded": ex.get("second_order_excluded"), "topology": ex.get("topology"),
             "form": found, "aspect": aspect, "image_gap": gap, "gap_over_eps": gap_eps}]


def unfolded_inside(snapshot: dict) -> tuple[np.ndarray, np.ndarray]:
    """(points, inside) of the full vesicle: the octant snapshot reflected into the doubled box."""
    grid = tuple(int(k) for k in np.atleast_1d(snapshot["grid_shape"]))
    box = np.asarray(snapshot["box"], float)
    h = (box[:, 1] - box[:, 0]) / np.array(grid)
    axes = [lo + hh * (np.arange(-k, k) + 0.5) for (lo, _), hh, k in zip(box, h, grid)]
    pts = grid_points(axes)
    return pts, cosine.unfold(np.asarray(snapshot["phi"]), grid).ravel() > 0


def form(snapshot: dict) -> tuple[str, float]:
    """(prolate | oblate | round, largest / smallest principal semi-axis) of the unfolded {phi > 0}."""
    pts, inside = unfolded_inside(snapshot)
    ev = np.sort(np.linalg.eigvalsh(np.cov(pts[inside].T)))
    ratio = float(np.sqrt(ev[-1] / ev[0]))
    if ratio < 1.05:
        return "round", ratio
    return ("prolate" if ev[1] - ev[0] < ev[2] - ev[1] else "oblate"), ratio


def image_gap(snapshot: dict, epsilon: float) -> tuple[float, float]:
    """The least free space between the shape and its mirror image across a far face (twice the
    distance from {phi > 0} to that face), and that over eps."""
    grid = tuple(int(k) for k in np.atleast_1d(snapshot["grid_shape"]))
    inside = np.asarray(snapshot["phi"]).reshape(grid) > 0
    box = np.asarray(snapshot["box"], float)
    gaps = []
    for ax in range(len(grid)):
        occupied = np.any(inside, axis=tuple(a for a in range(len(grid)) if a != ax))
        last = int(np.max(np.nonzero(occupied)[0])) + 1 if occupied.any() else 0
        gaps.append(2 * (box[ax, 1] - box[ax, 0]) * (1 - last / grid[ax]))
    g = float(min(gaps))
    return g, g / epsilon


EXTRA = ["branch_form", "epsilon", "nodes", "target_v", "start", "reduced_volume", "reduced_energy",
         "volume", "area", "kkt_residual", "converged", "second_order", "second_order_min_eigenvalue",
         "second_order_excluded", "topology", "form", "aspect", "image_gap", "gap_over_eps"]
# (the sharp reference per v is computed once per run, in ``summary``: one warm-started sharp branch)


def _true(x) -> bool:
    return str(x) in ("True", "true", "1")


def good_points(rows: list[dict], shape: str) -> list[dict]:
    """Certified points that are closed vesicles of the branch's own form."""
    return [r for r in rows if _true(r.get("converged")) and r.get("form") == shape
            and str(r.get("topology", "")).startswith("sphere-like")]


def summary(rows: list[dict], case_list: list[dict]) -> dict:
    """Per branch: points, certified closed vesicles of its form, verdicts, time per point; per eps
    the crossing and its distance to the sharp one; the extrapolation; the branch errors' order."""
    out: dict = {"branches": {}}
    by_eps: dict = {}
    for name in dict.fromkeys(c["branch"] for c in case_list):
        c = next(c for c in case_list if c["branch"] == name)
        sel = select(rows, scene=name)
        good = good_points(sel, c["form"])
        walls = [num(r.get("wall_time_s")) for r in sel]
        out["branches"][name] = {
            "epsilon": c["epsilon"], "n": c["n"], "nodes": int(np.prod(c["n"])),
            "doubled_box_nodes": 8 * int(np.prod(c["n"])), "points": len(sel),
            "certified": sum(_true(r.get("converged")) for r in sel), "good_points": len(good),
            "minimum_within_mirror_class": sum(r.get("second_order") == "minimum" for r in sel),
            "saddle_within_mirror_class": sum(r.get("second_order") == "saddle" for r in sel),
            "median_wall_time_s_per_point": float(np.nanmedian(walls)) if walls else None,
            "min_gap_over_eps": min((num(r.get("gap_over_eps")) for r in sel), default=None)}
        by_eps.setdefault(c["epsilon"], {})[c["form"]] = good
    vs = sorted({num(c["v"]) for c in case_list}, reverse=True)
    sharp = {f: {s.v: s for s in axisymmetric.branch(vs, f, second_order=False)} for f in ("prolate", "oblate")}
    out["sharp_branches"] = {f: {f"{v:g}": {"reduced_energy": s.reduced_energy, "kkt_residual": s.kkt_residual}
                                 for v, s in by_v.items()} for f, by_v in sharp.items()}
    per_eps, err = {}, {}
    for eps, both in sorted(by_eps.items(), reverse=True):
        pro, obl = both.get("prolate", []), both.get("oblate", [])
        x = crossing([num(r["reduced_volume"]) for r in pro], [num(r["reduced_energy"]) for r in pro],
                     [num(r["reduced_volume"]) for r in obl], [num(r["reduced_energy"]) for r in obl])
        if x is not None:
            per_eps[eps] = x
        for f, pts in both.items():
            for r in pts:  # the sharp branch's value at the point's target v (its v to 1e-8)
                d = num(r["reduced_energy"]) - sharp[f][num(r["target_v"])].reduced_energy
                err.setdefault(f, {}).setdefault(num(r["target_v"]), {})[eps] = d
    v_s, e_s = axisymmetric.crossing()
    out["crossing_sharp"] = {"reduced_volume": v_s, "reduced_energy": e_s,
                             "literature": "Seifert, Berndl & Lipowsky, PRA 44, 1182 (1991): v ~ 0.652"}
    out["crossing_eps"] = {f"{e:g}": {**x, "dv_to_sharp": x["reduced_volume"] - v_s,
                                      "de_to_sharp": x["reduced_energy"] - e_s} for e, x in per_eps.items()}
    if per_eps:
        eps = sorted(per_eps, reverse=True)
        out["crossing_order_observed"] = {
            key: observed_order(eps, [abs(per_eps[e][key] - ref) for e in eps]) if len(eps) >= 2 else math.nan
            for key, ref in (("reduced_volume", v_s), ("reduced_energy", e_s))}
    if len(per_eps) >= 2:
        ex = extrapolate_crossing(per_eps)
        for key, ref in (("reduced_volume", v_s), ("reduced_energy", e_s)):
            for how in ("_richardson", "_p2", "_lsq_p2"):
                if key + how in ex:
                    ex[key + how + "_minus_sharp"] = ex[key + how] - ref
        out["crossing_extrapolated"] = ex
    out["energy_error_vs_sharp"] = {
        f: {f"{v:g}": {"errors": {f"{e:g}": d for e, d in sorted(by_v[v].items(), reverse=True)},
                       "order": observed_order(sorted(by_v[v], reverse=True),
                                               [abs(by_v[v][e]) for e in sorted(by_v[v], reverse=True)])}
            for v in sorted(by_v) if len(by_v[v]) >= 2}
        for f, by_v in err.items()}
    return json_safe(out)


def figure(rows: list[dict], info: dict, path: Path) -> None:
    """The energy diagram near the crossing: reduced energy against v per eps (prolate circles,
    oblate squares, solid lines: the certified closed vesicles of the branch's own form,
    ``good_points``; dashed means unstable in every figure of the package, and none is here), the
    sharp branches (prolate black, oblate grey) and each crossing (x), the sharp one (star)."""
    pyplot = plt()
    fig, ax = pyplot.subplots(figsize=(6.4, 4.6))
    eps_all = sorted({num(r["epsilon"]) for r in rows}, reverse=True)
    colours = pyplot.cm.viridis(np.linspace(0.0, 0.85, max(1, len(eps_all))))
    for colour, eps in zip(colours, eps_all):
        for shape, style in (("prolate", "o-"), ("oblate", "s-")):
            good = sorted(good_points([r for r in rows if num(r["epsilon"]) == eps and r.get("branch_form") == shape],
                                      shape), key=lambda r: num(r["reduced_volume"]))
            if good:
                ax.plot([num(r["reduced_volume"]) for r in good], [num(r["reduced_energy"]) for r in good],
                        style, color=colour, ms=3, lw=1, label=f"{shape}, eps = {eps:g}")
        x = info.get("crossing_eps", {}).get(f"{eps:g}")
        if x:
            ax.plot(x["reduced_volume"], x["reduced_energy"], "x", color=colour, ms=8)
    for shape, colour in (("prolate", "k"), ("oblate", "0.55")):
        pts = sorted((float(v), d["reduced_energy"]) for v, d in info.get("sharp_branches", {}).get(shape, {}).items())
        if pts:
            ax.plot(*zip(*pts), "-", color=colour, lw=1.5, label=f"{shape}, sharp")
    xs = info.get("crossing_sharp")
    if xs:
        ax.plot(xs["reduced_volume"], xs["reduced_energy"], "*", color="k", ms=11, label="sharp crossing")
    ax.set_xlabel("reduced volume v")
    ax.set_ylabel("reduced energy E / (16 sqrt(2) pi / 3)")
    ax.set_title("3D prolate / oblate, octant mirror grids (x: crossing per eps)", fontsize=9)
    ax.legend(fontsize=6, ncol=2)
    savefig(fig, path)


def main(out: Path, quick: bool = False, executor=None, workers: int = 1) -> int:
    out = Path(out)
    case_list = [{**c, "out": str(out)} for c in cases(quick)]
    rows, info = run_study(NAME, case_list, run, summary, out, executor, workers, EXTRA)
    if rows:
        figure(rows, info, out / f"{NAME}.png")
    for name, v in info.items():
        log.info(f"{NAME}: {name}: {human(v)}")
    ok = all(v["points"] >= 2 and v["certified"] == v["points"] for v in info["branches"].values())
    return 0 if ok else 1
