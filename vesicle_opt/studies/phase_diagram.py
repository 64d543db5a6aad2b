"""The spontaneous-curvature phase diagram at c0 = 0 on the meridian half-plane (``mesh.axisymmetric``):
the prolate, oblate and stomatocyte branches at four eps, their transitions per eps (the prolate/oblate
and oblate/stomatocyte crossings, the stomatocyte's fold) and their eps -> 0 limits, against the sharp
references (``sharp.axisymmetric``, ``sharp.stomatocyte``) and the published values (``PUBLISHED``),
in the literature's units (f, v; Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991)).

Meshes: interface-refined meridian meshes (``mesh.refine = "interface"``, ``studies._meridian``),
eps/h = 4 in a band of 8 eps about the interface, coarse cells of 4 eps elsewhere, walls ``WALL`` eps
from the sharp shapes. The prolate and oblate walks are SEEDED with the tanh profile of the sharp shape
at their first v (``io.meridian.phase_field_of``, the mesh refined about that shape; the column
``seed`` says so): the tanh ellipsoid start reached another state at eps = 0.02 (f 1.502 against 1.284
from the sharp seed, measured). The stomatocyte walks start with no seed (``FULL["stomatocyte_start"]``
= "landing"): from the phi = 0 curve of the phase field's own cup, reached by a continuous switch at
the oblate's odd branch point in c0 at eps 0.03 (``studies._landing``: computed once, kept in
``states/``), the same way at every eps; "seed" starts them from the sharp stomatocyte instead.
R0 = 1 (area 4 pi), exact constraints, IPOPT, second-order checked (axisymmetric perturbations only).

Cases, one per (branch, eps, part), run in parallel through the study runner (``runner.run_cases``:
``--workers N`` local processes, or a dask cluster's executor, ``--scheduler``), the CSV resumable.
The v grid is fine where the transitions are and coarse elsewhere: ``near`` (prolate and oblate,
v 0.68 ... 0.62 by 0.01, warm-started along v, about the prolate/oblate crossing, sharp 0.6511), ``low``
(the oblate 0.63 ... 0.57 by 0.005-0.01, about its crossing with the stomatocyte, sharp 0.5909),
``far`` (v 0.95, 0.85, 0.75 and the prolate's 0.55, 0.5: each point from its own sharp shape), and
the stomatocyte's two walks from v = 0.62 (``up`` to its fold, ``down`` to 0.5; one case an eps, the seed
solved once). A crossing per eps
is the root of the difference of cubic splines f(v) through certified points of each branch's own
form (``branch.crossing``; an oblate that turned torus is not used); a fold per eps is the vertex
of v(lambda) (``_stomatocyte.fold_of``). The eps -> 0 limits (``extrapolate``): free-order Richardson
through the three finest eps with its observed order, p = 2 through the two finest, and an error
estimate (the change of the free-order limit from the three coarsest eps to the three finest).
``low_extra`` adds finer eps for the stomatocyte's transitions alone (the low oblate and both
stomatocyte walks; at eps >= 0.04 the oblate is a torus at its crossing with the stomatocyte): 0.02.

The mesh's share (``studies._hlevel``, stage two of the run): at fixed eps/h the P1 error of f does not
vanish as eps -> 0, so each transition's states are solved again at eps/h = 2 and 4, and 8 at the
transition's coarsest eps (same box and coarse cells), warm from the walks' saved fields
(``_meridian.save``), f and lambda extrapolated in h with the order observed at that coarsest eps
(``_hlevel.ORDER_FROM``), and the transitions moved by those shares before eps -> 0
(``crossings_h_corrected``, ``extrapolated_h_corrected``, ``h_levels``; ``_p2``: with p = 2).

Outputs: ``phase_diagram.csv`` (a row per point: f, c0_reduced, the sharp f, the verdicts, nodes, the
case's CPU time on its first row), ``phase_diagram_summary.json`` (``crossings``, ``extrapolated``,
``stomatocyte_fold``, ``oblate_stomatocyte_crossing``: per eps, eps -> 0, sharp, published; the
h-corrected ones beside them), rows of kind ``h_level`` (column ``eps_over_h``), ``states/`` (the
walks' fields: npz), ``phase_diagram.png`` (f against v per eps, the sharp branches, the transitions, meridian pictures).
Full: eps = 0.05, 0.04, 0.03, 0.025 (and 0.02 for the stomatocyte's transitions: ``low_extra``). Quick: eps = 0.1 at eps/h = 2 on the uniform mesh, v = 0.7,
0.65, sharp references with 8 modes: the plumbing (at eps = 0.1 the oblate seeds' dimples meet,
tori: no crossing). Extensions (other c0: ``EXTENSIONS``) add their own cases, rows and summary.
"""

from __future__ import annotations

import importlib
import json
import logging
import math
import time
from pathlib import Path

import numpy as np

from vesicle_opt.branch.crossing import crossing, extrapolate_crossing
from vesicle_opt.io.meridian import meridian_curves
from vesicle_opt.sharp import axisymmetric as sharp
from vesicle_opt.studies._meridian import layout, walk
from vesicle_opt.studies import _hlevel as hl
from vesicle_opt.studies import _landing as landing
from vesicle_opt.studies import _stomatocyte as stoma
from vesicle_opt.studies._pd_figure import figure
from vesicle_opt.studies.runner import run_into
from vesicle_opt.studies._common import num as _num

log = logging.getLogger(__name__)

NAME = "phase_diagram"
BRANCHES = ("prolate", "oblate")
NEAR = (0.68, 0.67, 0.66, 0.65, 0.64, 0.63, 0.62)  # about the prolate/oblate crossing (sharp 0.6511): 0.01 steps
FULL = {"epsilons": (0.05, 0.04, 0.03, 0.025), "eps_over_h": 4.0, "refine": True, "n_modes": 16, "near": NEAR,
        # far from the transitions: coarse, each point seeded from its sharp shape (independent solves)
        "far": {"prolate": (0.95, 0.85, 0.75, 0.55, 0.5), "oblate": (0.95, 0.85, 0.75)},
        # the oblate about its crossing with the stomatocyte (sharp 0.5909); at eps >= 0.04 its dimples
        # meet near there (a torus: measured), so that crossing has eps <= 0.03 only
        "oblate_low": (0.63, 0.62, 0.61, 0.6, 0.595, 0.59, 0.585, 0.58, 0.57),
        # the stomatocyte from the seed at 0.62: up to the fold (sharp 0.6604) in shrinking steps, down past
        # the oblate crossing to 0.5
        # (the phase field's fold lies above the sharp one: the grid goes on to 0.69, the walk ends past it)
        "stomatocyte_up": (0.62, 0.63, 0.64, 0.645, 0.65, 0.653, 0.656, 0.658, 0.66, 0.662, 0.664, 0.666, 0.668,
                           0.67, 0.672, 0.675, 0.678, 0.682, 0.686, 0.69),
        "stomatocyte_down": (0.62, 0.61, 0.6, 0.595, 0.59, 0.585, 0.58, 0.57, 0.55, 0.5),
        "stomatocyte_modes": 32,
        # finer eps for the stomatocyte's transitions alone (the oblate/stomatocyte crossing and the fold: a
        # third level, an observed order in eps): the low oblate and both stomatocyte walks, the down walk
        # ending below that crossing. eps = 0.02: its stomatocyte seed (v = 0.62) converged in 129 IPOPT
        # iterations, 65 CPU s, on the box centred where the pin holds it (``_meridian.layout``), in 178 on the
        # former box (past the former 150-iteration cap, where it had ended, kkt 0.36): ``SEED_MAX_ITER``, measured
        "low_extra": (0.02,), "down_extra_min": 0.57,
        # the stomatocyte walks' first curve: "landing" (no seed: ``_landing``, the phase field's own cup reached by
        # switching at eps 0.03; the sharp seed's cup to f 3e-8 at eps 0.04-0.02, measured) or "seed" (the sharp one)
        "stomatocyte_start": "landing"}
QUICK = {"epsilons": (0.1,), "eps_over_h": 2.0, "refine": False, "n_modes": 8, "near": (0.7, 0.65)}
EXTENSIONS: tuple[str, ...] = ("_pear",)  # c0 = 2.4 (full run only); the hook: private modules of this package (e.g. "_pear") with
# cases(quick) -> [case], run(case) -> [row] and summary(rows) -> dict; their cases carry "extension"
CUP = 0.1  # a pole dimple deeper than the other by this fraction of the height: a cup (stomatocyte)
COLUMNS = ["branch", "shape", "c0", "target_v", "epsilon", "n", "h", "f", "c0_reduced", "reduced_volume", "sharp_f",
           "f_minus_sharp", "converged", "second_order", "second_order_min_eigenvalue", "topology",
           "kkt_residual", "iterations", "wall_time_s", "seed", "status", "kind", "side", "lambda", "walk",
           "part", "nodes", "cpu_time_s", "transition", "eps_over_h", "state", "point"]


def _extension(name: str):
    return importlib.import_module(f"vesicle_opt.studies.{name}")


def cases(quick: bool, states=None) -> list[dict]:
    """One case per (branch, eps, part): the parts and eps values run in parallel (the runner), in
    the order of what the transitions need (the pool takes them in order; a run stopped early, and
    resumed, has the transitions first): the sharp stomatocyte; the prolate/oblate ``near`` walks;
    the stomatocyte's walks (``up`` to its fold, then ``down`` from the same seed: one case an eps; with
    ``low_extra``'s finer eps); the ``low`` oblate (its crossing with the stomatocyte's ``down`` walk;
    with ``low_extra``'s); the ``far`` points; within
    each the finest (longest) eps first. ``states``: where the walks save their points' fields (``_hlevel``)."""
    cfg = QUICK if quick else FULL
    common = {"eps_over_h": cfg["eps_over_h"], "refine": cfg["refine"], "n_modes": cfg["n_modes"],
              "states": None if states is None else str(states)}
    order = sorted(cfg["epsilons"])
    out = [{"case": f"{b}-eps{eps:g}", "branch": b, "epsilon": eps, "part": "near", "vs": list(cfg["near"]), **common}
           for eps in order for b in BRANCHES]
    if not quick:
        st = {**common, "n_modes": 24}

        def walk_case(eps, v_min=0.0):  # both walks from one seed (``_stomatocyte.phase_case``)
            return {"case": f"stomatocyte-eps{eps:g}", "branch": "stomatocyte", "epsilon": eps, "walk": "both",
                    "vs": list(cfg["stomatocyte_up"]), "vs_down": [v for v in cfg["stomatocyte_down"] if v >= v_min],
                    "start": cfg["stomatocyte_start"], **st}
        out = [{"case": "stomatocyte-sharp", "branch": "stomatocyte", "epsilon": 0.0, "n_modes": cfg["stomatocyte_modes"]}] \
            + out + [walk_case(eps, cfg["down_extra_min"] if eps in cfg["low_extra"] else 0.0)
                     for eps in sorted(cfg["low_extra"]) + order]
        for eps in sorted(cfg["low_extra"]) + order:
            out += [{"case": f"oblate-low-eps{eps:g}", "branch": "oblate", "epsilon": eps, "part": "low",
                     "vs": list(cfg["oblate_low"]), **common}]
        out += [{"case": f"{b}-far-eps{eps:g}", "branch": b, "epsilon": eps, "part": "far", "vs": list(vs), **common}
                for eps in order for b, vs in cfg["far"].items()]
    for name in EXTENSIONS:
        out += [{**c, "extension": name} for c in _extension(name).cases(quick)]
    return out


def shape_of(disc, phi) -> str:
    """The state's form from its meridian curve (``io.meridian``): "cup" when one pole's dimple (its
    depth below the curve's extreme z on its side) exceeds the other's by ``CUP`` of the height
    (a stomatocyte; an oblate's dimples are equal), else "prolate" (height > width) or "oblate";
    "torus" for one closed curve off the axis (an oblate whose dimples met: the phase field changes
    topology at finite eps), "other" for anything else."""
    curves = meridian_curves(disc, phi)
    if len(curves) == 1 and len(curves[0]) > 2 and np.array_equal(curves[0][0], curves[0][-1]):
        return "torus"
    if len(curves) != 1 or curves[0][0][0] > 0 or curves[0][-1][0] > 0:
        return "other"
    r, z = curves[0][:, 0], curves[0][:, 1]
    height = float(z.max() - z.min())
    poles = sorted((z[0], z[-1]))
    dimples = (poles[0] - float(z.min()), float(z.max()) - poles[1])
    if abs(dimples[0] - dimples[1]) > CUP * height:
        return "cup"
    return "prolate" if height > 2 * float(r.max()) else "oblate"


def _row(which, res, v, eps, lay, sharp_f, seed, side="", walk="", part="") -> dict:
    """A study row of one solve (``_meridian``): literature units, verdicts, mesh and cost."""
    ex = res.extra
    f = ex.get("f", math.nan)
    return {"branch": which, "shape": shape_of(res.disc, res.phi) if res.converged else None, "c0": 0.0,
            "target_v": v, "epsilon": eps, "n": "x".join(map(str, lay["n"])), "h": lay["h"], "f": f,
            "c0_reduced": ex.get("c0_reduced"), "reduced_volume": ex.get("reduced_volume"),
            "sharp_f": sharp_f, "f_minus_sharp": f - sharp_f,
            "converged": res.converged, "second_order": ex.get("second_order"),
            "second_order_min_eigenvalue": ex.get("second_order_min_eigenvalue"),
            "topology": ex.get("topology"), "kkt_residual": res.kkt_residual,
            "iterations": res.iterations, "wall_time_s": res.wall_time_s, "seed": seed,
            "status": res.outcome, "kind": "point", "side": side, "walk": walk, "part": part,
            "lambda": res.lambda_volume, "nodes": res.disc.n_nodes}


def _stomatocyte_row(res, v, eps, lay, sharp_f, seed, side, walk) -> dict:
    return _row("stomatocyte", res, v, eps, lay, sharp_f, seed, side, walk, walk)


def run(case: dict) -> list[dict]:
    t0 = time.process_time()
    rows = _run(case)
    if rows and "cpu_time_s" not in rows[0]:  # the case's CPU time (this process's), on its first row
        rows[0]["cpu_time_s"] = time.process_time() - t0  # (h-level rows carry their own, per level)
    return rows


def _run(case: dict) -> list[dict]:
    if "extension" in case:
        return _extension(case["extension"]).run(case)
    if "transition" in case:  # stage two: a state at a transition on finer and coarser bands (``_hlevel``)
        return hl.run(case, lambda res, v, eps, lay: _row(case["branch"], res, v, eps, lay, math.nan,
                                                          f"eps/h = 4 state ({case['source']})", part="h_level"))
    if case["branch"] == "stomatocyte":
        if case["epsilon"] == 0:
            return stoma.sharp_case(case)
        start, missed = landing.start(case)
        rows = stoma.phase_case(case, _stomatocyte_row, start)
        if missed and rows:
            rows[0]["seed"] = f"{rows[0]['seed']}; {missed}"
        return rows
    eps, which, vs = case["epsilon"], case["branch"], case["vs"]
    refs = sharp.branch(vs, which, case["n_modes"], second_order=False) if case["part"] != "far" else \
        [sharp.solve(v, which, case["n_modes"], second_order=False) for v in vs]
    meridians = [ref.meridian(2048) for ref in refs]
    lay = layout(meridians, eps, case["eps_over_h"], case.get("refine", True))
    name = f"{NAME}-{which}"
    if case["part"] == "far":  # each point from its own sharp shape
        points = [next(walk(lay, eps, [v], m, name)) for v, m in zip(vs, meridians)]
    else:
        points = list(walk(lay, eps, vs, meridians[0], name, states=case.get("states"), case=case["case"]))
    return [_row(which, res, v, eps, lay, ref.reduced_energy, seed, part=case["part"])
            for (v, res, seed), ref in zip(points, refs)]


def _by_v(rows: list[dict], key: str = "reduced_volume", value: str = "f") -> tuple[list[float], list[float]]:
    """(v, f) of rows, one per v (parts of a branch overlap: the first row at a v), v increasing."""
    pts: dict[float, float] = {}
    for r in rows:
        pts.setdefault(round(_num(r[key]), 9), _num(r[value]))
    vs = sorted(v for v in pts if math.isfinite(v) and math.isfinite(pts[v]))
    return vs, [pts[v] for v in vs]


def extrapolate(per_eps: dict) -> dict:
    """``branch.crossing.extrapolate_crossing`` of {eps: crossing} and an error estimate of its
    free-order limit (``*_error``): with four levels the change of the free-order Richardson limit
    from the three coarsest to the three finest eps (and ``order_*_coarse``, the order those
    give), with three its distance to the p = 2 limit of the two finest; nan with two."""
    out = extrapolate_crossing(per_eps)
    eps = sorted(per_eps, reverse=True)
    for key in ("reduced_volume", "reduced_energy"):
        out[key + "_error"] = math.nan
        if len(eps) >= 4:
            coarse = extrapolate_crossing({e: per_eps[e] for e in eps[:3]})
            out[key + "_error"] = abs(out[key + "_richardson"] - coarse[key + "_richardson"])
            out["order_" + key + "_coarse"] = coarse["order_" + key]
        elif len(eps) == 3:
            out[key + "_error"] = abs(out[key + "_richardson"] - out[key + "_p2"])
    return out


def summarise(rows: list[dict]) -> dict:
    """Per eps the prolate/oblate crossing in (v, f) of certified points of their branch's form (a
    walk that left its form, e.g. an oblate turned torus, is not used), and its eps -> 0 limit
    (``extrapolate``); the stomatocyte's transitions (``stomatocyte_summary``); the extensions'."""
    every, rows = rows, _c0_zero(rows)  # the extensions' rows (other c0) go to their own summary
    sh = hl.shares(rows)  # the h-levels of the transitions' states (stage two)
    rows = [r for r in rows if r.get("kind") != "h_level"]
    ok = [r for r in rows if str(r.get("converged")) == "True" and r.get("shape", r["branch"]) == r["branch"]]
    per_eps, data = {}, {}
    for eps in sorted({_num(r["epsilon"]) for r in ok}, reverse=True):
        data[eps] = [c for b in BRANCHES for c in _by_v([r for r in ok if _num(r["epsilon"]) == eps and r["branch"] == b])]
        x = crossing(*data[eps])
        if x is not None:
            per_eps[eps] = x
    out = {"crossings": _vf(per_eps)}
    if len(per_eps) >= 2:
        out["extrapolated"] = extrapolate(per_eps)
    out.update(_corrected(*hl.crossings({e: data[e] for e in per_eps}, sh, "crossing", BRANCHES, per_eps)))
    out.update(stomatocyte_summary(rows, sh))
    one_eps = [r for r in rows if _num(r["epsilon"]) == max(_num(q["epsilon"]) for q in rows)]
    x = crossing(*[c for b in BRANCHES for c in _by_v([r for r in one_eps if r["branch"] == b], "target_v", "sharp_f")])
    if x is not None:  # the sharp branches' crossing through the same points (a spline, as the phase field's)
        out["sharp_crossing_at_these_points"] = {"v": x["reduced_volume"], "f": x["reduced_energy"]}
    for name in EXTENSIONS:
        out.update(_extension(name).summary(every))
    return out


def _vf(per_eps: dict) -> dict:
    return {f"{e:g}": {"v": x["reduced_volume"], "f": x["reduced_energy"]} for e, x in per_eps.items()}


def _corrected(per: dict, per2: dict, levels: dict, prefix: str = "") -> dict:
    """The h-corrected transitions per eps (``crossings_h_corrected``: the observed orders' mesh shares;
    ``..._p2``: p = 2), their eps -> 0 limits (``extrapolated_h_corrected``, ``..._p2``) and the states'
    levels (``h_levels``: per eps, per state: eps/h, f, observed order, mesh share of eps/h = 4)."""
    names = ("per_eps_h_corrected", "extrapolated_h_corrected") if prefix else ("crossings_h_corrected",
                                                                                "extrapolated_h_corrected")
    out = {names[0]: _vf(per), names[0] + "_p2": _vf(per2), "h_levels": {f"{e:g}": x for e, x in levels.items()}}
    for d, suffix in ((per, ""), (per2, "_p2")):
        if len(d) >= 2:
            out[names[1] + suffix] = extrapolate(d)
    return out


def _c0_zero(rows: list[dict]) -> list[dict]:
    """The rows of this module's own branches (c0 = 0), not the extensions'."""
    return [r for r in rows if r["branch"] in (*BRANCHES, "stomatocyte")]


PUBLISHED = {"prolate/oblate": (0.650, 1.830), "oblate/stomatocyte": (0.59, 1.98), "stomatocyte fold": (0.66, 1.96),
             "pear/prolate c0=2.4": (0.746, 0.107)}  # Seifert, Berndl & Lipowsky 1991, read off their
# figures (+-0.005 in v, +-0.01 in f; the oblate/stomatocyte f between 1.96 and 2.0: its middle)


def _stomatocyte_transitions(rows: list[dict], eps: float) -> dict:
    """At one eps: the stomatocyte's fold (``_stomatocyte.fold_of`` on the up walk in walk order) and
    its crossing with the oblate (spline crossing of its lower side and the oblate's points)."""
    st = [r for r in rows if r["branch"] == "stomatocyte" and _num(r["epsilon"]) == eps
          and str(r.get("kind", "point")) == "point" and str(r.get("converged")) == "True"]
    out = {}
    up = hl.up_walk(st, eps)  # in walk order (the CSV keeps a case's rows in order)
    fv = stoma.fold_of(*[[_num(r[k]) for r in up] for k in ("reduced_volume", "f", "lambda")]) if len(up) >= 3 else None
    if fv is not None:
        out["fold"] = {"reduced_volume": fv[0], "reduced_energy": fv[1]}
        out["fold_up"] = up
    lower = _by_v([r for r in st if r.get("side") == "lower" and r.get("shape", "cup") in ("cup", None, "")])
    obl = _by_v([r for r in rows if r["branch"] == "oblate" and _num(r["epsilon"]) == eps
                 and str(r.get("converged")) == "True" and r.get("shape") == "oblate"])
    if len(lower[0]) >= 2 and len(obl[0]) >= 2:
        x = crossing(*lower, *obl)
        if x is not None:
            out["crossing"], out["crossing_data"] = x, (*obl, *lower)
    return out


def stomatocyte_summary(rows: list[dict], sh: dict | None = None) -> dict:
    """The stomatocyte's fold and oblate/stomatocyte crossing per eps > 0, their eps -> 0 limits
    (``extrapolate_crossing``: free-order Richardson through three eps and its order, p = 2 through the
    two finest), the sharp ones (eps = 0 rows of kind fold / crossing) and the published values; with
    the h-levels' shares ``sh`` (``_hlevel.shares``) their h-corrected values (``_corrected``)."""
    per = {"fold": {}, "crossing": {}, "fold_up": {}, "crossing_data": {}}
    for eps in sorted({_num(r["epsilon"]) for r in rows if r["branch"] == "stomatocyte"} - {0.0}, reverse=True):
        for k, x in _stomatocyte_transitions(rows, eps).items():
            per[k][eps] = x
    corr = {"crossing": hl.crossings(per["crossing_data"], sh or {}, "oblate_stomatocyte", ("oblate", "stomatocyte"),
                                     per["crossing"]),
            "fold": ({}, {}, {})}
    for e, up in per["fold_up"].items():
        for d, y in zip(corr["fold"], hl.fold(up, sh or {}, e)):
            if y:
                d[e] = y
    out = {}
    for k, name in (("fold", "stomatocyte fold"), ("crossing", "oblate/stomatocyte")):
        key = "stomatocyte_fold" if k == "fold" else "oblate_stomatocyte_crossing"
        sharp_rows = [r for r in rows if r["branch"] == "stomatocyte" and r.get("kind") == k]
        entry = {"per_eps": {f"{e:g}": {"v": x["reduced_volume"], "f": x["reduced_energy"]} for e, x in per[k].items()},
                 "published": {"v": PUBLISHED[name][0], "f": PUBLISHED[name][1]}}
        if sharp_rows:
            entry["sharp"] = {"v": _num(sharp_rows[0]["reduced_volume"]), "f": _num(sharp_rows[0]["f"])}
        if len(per[k]) >= 2:
            entry["extrapolated"] = extrapolate(per[k])
        if sh:
            entry.update(_corrected(*corr[k], prefix=key))
        out[key] = entry
    return out


def main(out, quick: bool = False, executor=None, workers: int = 1) -> int:
    columns = COLUMNS + [c for n in EXTENSIONS for c in _extension(n).COLUMNS if c not in COLUMNS]
    states = Path(out) / hl.STATES
    first = landing.prepare(cases(quick, states))  # the stomatocyte walks' seedless start, made once
    out, rows, good = run_into(NAME, first, run, out, executor=executor, workers=workers, extra_columns=columns)
    # stage two: the states at the transitions located on those rows, on finer and coarser bands
    second = hl.cases(good, summarise(good), states, {"up": FULL["stomatocyte_up"], "down": FULL["stomatocyte_down"],
                                                      "low": FULL["oblate_low"], "near": FULL["near"]})
    if second:
        out, rows, good = run_into(NAME, second, run, out, executor=executor, workers=workers, extra_columns=columns)
        third = hl.order_cases(good, second)  # eps/h = 8 one eps down where the coarsest refused eps/h = 2
        if third:
            out, rows, good = run_into(NAME, third, run, out, executor=executor, workers=workers,
                                       extra_columns=columns)
    summary = summarise(good)
    v_s, f_s = sharp.crossing() if not quick else (math.nan, math.nan)  # ~20 s: the full run's reference
    summary["sharp_crossing"] = {"v": v_s, "f": f_s}
    summary["timings"] = timings(good)
    (out / f"{NAME}_summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    for e, x in summary["crossings"].items():
        log.info(f"eps {e}: crossing v = {x['v']:.5f}, f = {x['f']:.5f} (sharp {v_s:.5f}, {f_s:.5f})")
    for key in ("stomatocyte_fold", "oblate_stomatocyte_crossing"):
        for e, x in summary.get(key, {}).get("per_eps", {}).items():
            log.info(f"eps {e}: {key} v = {x['v']:.5f}, f = {x['f']:.5f}")
    for name, ext in (("crossing", summary.get("extrapolated_h_corrected")),
                      *((k, summary.get(k, {}).get("extrapolated_h_corrected")) for k in ("stomatocyte_fold",
                                                                                         "oblate_stomatocyte_crossing"))):
        if ext:
            log.info(f"eps -> 0, h-corrected {name} (p = 2): v = {ext['reduced_volume_p2']:.5f}, f = {ext['reduced_energy_p2']:.5f}")
    if good:
        figure(_c0_zero(good), summary, out / f"{NAME}.png", PUBLISHED)
    # the up walk's last point lies past the phase field's fold (no stomatocyte there): its expected end
    certified = all(str(r.get("converged")) == "True" for r in good
                    if not (r["branch"] == "stomatocyte" and r.get("walk") == "up"))
    return 0 if good and len(good) == len(rows) and certified else 1


def timings(rows: list[dict]) -> dict:
    """Per case its CPU time (``cpu_time_s``: the worker process's, on its first row), its solves'
    wall time (sum of ``wall_time_s``) and points; their totals: what the idle wall time on N cores
    is judged by (CPU seconds / N for cases balanced over the workers)."""
    per: dict[str, dict] = {}
    for r in rows:
        c = per.setdefault(r.get("case", ""), {"cpu_s": 0.0, "solve_wall_s": 0.0, "points": 0})
        cpu, wall = _num(r.get("cpu_time_s")), _num(r.get("wall_time_s"))
        c["cpu_s"] += cpu if math.isfinite(cpu) else 0.0
        c["solve_wall_s"] += wall if math.isfinite(wall) else 0.0
        c["points"] += 1
    return {"per_case": per, "cpu_s_total": sum(c["cpu_s"] for c in per.values()),
            "solve_wall_s_total": sum(c["solve_wall_s"] for c in per.values()),
            "h_level_cpu_s": sum(c["cpu_s"] for k, c in per.items() if str(k).startswith("h-"))}
