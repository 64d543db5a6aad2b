"""The mesh share of the ``phase_diagram`` study's transitions and its h -> 0 correction (not a study).

Why: at fixed eps/h the P1 error of f is a fixed fraction of f (the interface profile spans the same
number of cells at every eps), so it does not vanish as eps -> 0 at eps/h = 4 and biases the eps -> 0
limit (-0.0044 / -0.0051 in f at eps = 0.05 against eps/h = 8, measured). Here, per eps and transition,
the states AT the transition are solved again on the same box with the band's spacing halved and
doubled (eps/h = 2, 4, 8: ``mesh.levels`` one fewer / more, so the coarse cells and the box are the
same), each warm from the eps/h = 4 state interpolated onto the new band (``mesh.refine.transfer``,
through the front door's re-mesh: ``mesh.band_start``), and f (and the fold's lambda) extrapolated in h
(``share``: the observed order p from the three levels, ``verify.metrics.richardson``; the fixed p = 2
of a P1 energy from the two finest beside it). The level eps/h = 8 costs four times the nodes of eps/h
= 4 (140-240 k at eps 0.03-0.02; 11-111 CPU s a solve, one process at 7 GB: measured), so it is solved
at each transition's coarsest eps alone (``ORDER_FROM``), where it is cheapest and observes the order
(2.03-2.05 on every state, measured): at the finer eps the states get eps/h = 4 and 2, and their limit
uses that order (``share_at_order``: the P1 error at fixed eps/h is the same function of h/eps at
every eps, to leading order). The transition is then moved by its states' mesh shares
delta = y_4 - y_0 (y_0: the h -> 0 limit):

* a crossing of branches a, b located at v* at eps/h = 4 (``corrected_crossing``): each branch's
  spline f(v) shifted by its delta at v* (constant in v: its change over the shift is second order),
  the root found again (``branch.crossing.crossing``), to first order
  v' = v* + (delta_a - delta_b) / (f_a' - f_b')(v*);
* the fold (``corrected_fold``): its three points (fixed v; ``fold_points``, the selection of
  ``_stomatocyte.fold_of``) with f and lambda each shifted by their delta, the vertex found again.

Stage two of the study (``cases``): built from the transitions located on the eps/h = 4 rows, the
states read from the walks' saved fields (``_meridian.save``: one npz per converged point, ``STATES`` under the
output directory); a case per (transition, eps, state), its rows of kind ``h_level``. Stage three
(``order_cases``): where the coarsest eps refused eps/h = 2 (the fold at eps 0.04), eps/h = 8 at the next
eps down, so that the order is observed and not replaced by p = 2.
"""

from __future__ import annotations

import math
import time
import types
from pathlib import Path

import numpy as np

from vesicle_opt.branch.crossing import crossing
from vesicle_opt.mesh import discretize, refine
from vesicle_opt.sharp import axisymmetric as sharp
from vesicle_opt.sharp import stomatocyte as sharp_s
from vesicle_opt.studies._meridian import layout, scene, solve_quiet, state_path, walk
from vesicle_opt.studies import _landing as landing
from vesicle_opt.studies._stomatocyte import V_SEED, fold_of
from vesicle_opt.verify.metrics import richardson, richardson_fixed
from vesicle_opt.studies._common import num as _num

STATES = "states"  # the walks' saved fields (``_meridian.save``), under the study's output directory
LEVELS = (0, -1, 1)  # eps/h = 4 * 2^j: the eps/h = 4 state first, the others warm from it; eps/h = 8 is not
# solved where eps/h = 2 did not certify: it is there to observe the order, which needs all three (at the
# fold's coarsest eps, 0.04, eps/h = 2 was refused at all three points and eps/h = 8 cost 105 of stage
# two's 391 CPU s, the run's last case: measured)
CHEAP_LEVELS = (0, -1)  # at the finer eps: eps/h = 4 and 2, the order taken from the coarsest eps (``ORDER_FROM``)
ORDER_FROM = "coarsest"  # the eps whose states get eps/h = 8 too ("all": every eps, the former stage two)
TRANSITIONS = ("crossing", "oblate_stomatocyte", "fold")


# --- the arithmetic -------------------------------------------------------------------------------

def share(h, y) -> dict:
    """The h -> 0 limit of y(h) = y_0 + C h^p from three levels (h decreasing by halves): the observed
    order ``order`` and its limit ``limit`` (``metrics.richardson``; nan where no p in [0.25, 8]
    fits), the p = 2 limit from the two finest (``limit_p2``), and the mesh share of the middle level
    (the study's eps/h = 4) against each: ``share`` = y(h_mid) - limit, ``share_p2``. Where no order
    is observed (two levels: the coarsest not certified; or none fits) ``share`` is the p = 2 one,
    and ``order_used`` says which order the share has."""
    h, y = np.asarray(h, float), np.asarray(y, float)
    order = np.argsort(-h)
    h, y = h[order], y[order]
    d = np.diff(y[-3:])
    lim, p = richardson(h, y) if len(h) >= 3 and np.isfinite(d).all() and (d != 0).all() else (math.nan, math.nan)
    return _record(p, lim, richardson_fixed(h, y, 2.0), y[len(y) - 2])


def _record(p: float, lim: float, lim2: float, at: float) -> dict:
    """A share's record: the share of the level valued ``at`` against the limit of order ``p``
    (``lim``), or against the p = 2 limit ``lim2`` where ``lim`` is nan (no order observed)."""
    observed = math.isfinite(lim)
    return {"order": p, "limit": lim, "limit_p2": lim2, "share": at - (lim if observed else lim2),
            "share_p2": at - lim2, "order_used": p if observed else 2.0}


def corrected_crossing(va, fa, vb, fb, delta_a: float, delta_b: float) -> dict | None:
    """``crossing`` of the branches (va, fa) and (vb, fb) with each f lowered by its mesh share."""
    return crossing(va, np.asarray(fa, float) - delta_a, vb, np.asarray(fb, float) - delta_b)


def fold_points(v) -> list[int]:
    """The indices (walk order) of the three points ``_stomatocyte.fold_of`` fits: about the
    largest v, or the last three when the walk ends there; [] with fewer than three or a maximum first."""
    v = np.asarray(v, float)
    k = int(np.argmax(v)) if len(v) else 0
    if len(v) < 3 or k == 0:
        return []
    return [k - 1, k, k + 1] if k < len(v) - 1 else [k - 2, k - 1, k]


def corrected_fold(v, f, lam, delta_f, delta_lam):
    """``_stomatocyte.fold_of`` of the three fold points with f and lambda each lowered by its share."""
    return fold_of(v, np.asarray(f, float) - delta_f, np.asarray(lam, float) - delta_lam)


# --- the states -----------------------------------------------------------------------------------

def _load(path):
    import skfem  # third-party, lazy

    z = np.load(path)
    mesh = skfem.MeshTri(np.asarray(z["p"], float), np.asarray(z["t"], np.int64))
    lay = {"box": z["box"].tolist(), "n": [int(k) for k in z["n"]], "h": float(z["h"]),
           "mesh": {"kind": "axisymmetric", "n": [int(k) for k in z["n"]], "refine": "interface",
                    "levels": int(z["levels"]), "band": float(z["band"])}}
    return mesh, np.asarray(z["phi"], float), float(z["h_fine"]), lay


def level_layout(lay: dict, j: int) -> dict:
    """The layout with the band's spacing h / 2^j on the same box and coarse cells."""
    return {**lay, "h": lay["h"] / 2**j, "mesh": {**lay["mesh"], "levels": lay["mesh"]["levels"] + j}}


def _walked(case: dict) -> tuple[dict, dict]:
    """({v: Result}, layout): the eps/h = 4 states at the case's points where no saved field is there,
    from ONE walk (``_meridian.walk``) over ``case["walk_vs"]`` from the sharp shape at its first v (the
    prolate and oblate: the sharp shape at v itself; the stomatocyte: from ``_stomatocyte.V_SEED``, its
    up or down grid as the study's own walks, from the seedless landing's curve where ``states`` holds
    it (``studies._landing``: the walks' own start), else from the sharp stomatocyte), stopped at the
    first point that fails."""

    eps, vs, b = case["epsilon"], case["walk_vs"], case["branch"]
    if b == "stomatocyte":
        found = landing.read(Path(case["state"]).parent / landing.FILE) if case.get("state") else None
        meridians = [found[:2] if found is not None else sharp_s.start_point(vs[0], 0.0, 24).meridian(2048)]
    else:  # the box of the walks' own: about the sharp shapes of their whole grid (``layout_vs``)
        grid = case.get("layout_vs") or vs
        meridians = [ref.meridian(2048) for ref in sharp.branch(grid, b, 16, second_order=False)]
        meridians.insert(0, meridians[grid.index(vs[0])] if vs[0] in grid else
                         sharp.solve(vs[0], b, 16, second_order=False).meridian(2048))
    meridian = meridians[0]
    lay = layout(meridians, eps, 4.0)
    want = {float(q["v"]) for q in _points(case)}
    got = {}
    for v, res, _ in walk(lay, eps, vs, meridian, f"phase_diagram-h-{case['case']}", lambda r: not r.converged):
        if res.converged and float(v) in want:
            got[float(v)] = res
    return got, lay


def _points(case: dict) -> list[dict]:
    """The states of a case: its ``points`` (the fold's three) or the case itself (a crossing's state)."""
    return case.get("points") or [case]


def run(case: dict, point_row) -> list[dict]:
    """The levels ``LEVELS`` of each state of the case (``_points``; module docstring): rows of kind
    ``h_level`` (``point_row(res, v, eps, lay)``: the study's row). The eps/h = 4 solve warm from the
    saved state interpolated onto a band about its interface, or, where a field was not saved, the
    state of one walk to the points (``_walked``: its CPU time in the first row's); the other levels
    warm from that eps/h = 4 state."""
    t0 = time.process_time()
    pts = _points(case)
    walked, lay_w = ({}, None) if all(q.get("state") and Path(q["state"]).is_file() for q in pts) else _walked(case)
    t_walk, rows = time.process_time() - t0, []
    for q in pts:
        rows += _levels(case, q, walked.get(float(q["v"])), lay_w, point_row)
    if rows:
        rows[0]["cpu_time_s"] = rows[0].get("cpu_time_s", 0.0) + t_walk
    return rows


def _levels(case: dict, q: dict, base, lay_w, point_row) -> list[dict]:
    """The levels of one state ``q`` (v, point, state, source) of ``case``: ``base`` its walked eps/h = 4
    Result (with the walk's layout ``lay_w``) or None (its saved field)."""

    eps, v, t0 = case["epsilon"], float(q["v"]), time.process_time()
    tag = {"kind": "h_level", "transition": case["transition"], "point": q.get("point", ""),
           "state": q["source"] if base is None else f"walked: {case['walk_vs']}"}
    if base is None and not (q.get("state") and Path(q["state"]).is_file()):
        return [{"branch": case["branch"], "epsilon": eps, "target_v": v, "converged": False, "eps_over_h": 4.0,
                 "status": "the walk to the state did not reach it", **tag}]
    if base is None:
        mesh, phi, h_fine, lay0 = _load(q["state"])
    else:
        lay0 = lay_w
    rows = []
    for j in case.get("levels", LEVELS):
        if j > 0 and any(r["eps_over_h"] < 4.0 and str(r.get("converged")) != "True" for r in rows):
            continue  # no order to observe without eps/h = 2 (``LEVELS``)
        lay = level_layout(lay0, j)
        if j == 0 and base is not None:
            res = base
        else:
            sc = scene(lay, eps, v, f"phase_diagram-h-{case['case']}{q.get('point', '')}-j{j}")
            if base is None:
                disc = discretize(sc, interface=refine.remesh_distance(mesh, phi, math.sqrt(2.0) * h_fine))
                start = types.SimpleNamespace(disc=disc, phi=refine.transfer(mesh, phi, disc.nodes))
            else:
                start = base
            res = solve_quiet(sc, start)
        rows.append({**point_row(res, v, eps, lay), **tag, "eps_over_h": round(eps / lay["h"], 9),
                     "cpu_time_s": time.process_time() - t0})
        t0 = time.process_time()
        if j == 0:
            if not res.converged:
                break  # no state to refine
            base = res
    return rows


# --- stage two: the cases from the located transitions --------------------------------------------

def cases(rows: list[dict], summary: dict, states, grids: dict) -> list[dict]:
    """The h-level cases of the transitions in ``summary`` (the eps/h = 4 rows' ``crossings``,
    ``oblate_stomatocyte_crossing``, ``stomatocyte_fold``), in that order: for a crossing, each
    branch's state nearest it (its walk's saved field) solved at the crossing's v; for the fold, its
    three points. Each case also carries the walk that reaches its state where no field was saved
    (``_walked``; ``grids``: the stomatocyte's ``up`` and ``down`` v grids from ``V_SEED``, the oblate's
    ``low`` grid; the box about the sharp shapes of the ``near`` or ``low`` grid, as the walks')."""

    out = []
    pts = [r for r in rows if str(r.get("kind", "point")) in ("point", "") and str(r.get("converged")) == "True"]

    def nearest(sel, v):
        return min(sel, key=lambda r: abs(_num(r["reduced_volume"]) - v)) if sel else None

    def layout_vs(branch, transition):
        return list(grids["low"] if transition == "oblate_stomatocyte" else grids["near"]) if branch != "stomatocyte" else []

    def walk_vs(branch, v, transition):
        if branch == "oblate" and transition == "oblate_stomatocyte":  # cold from the sharp oblate there: no
            return [u for u in grids["low"] if u > v] + [float(v)]  # oblate at eps 0.025 (measured): the low walk
        if branch != "stomatocyte":
            return [float(v)]
        grid = grids["up"] if v > V_SEED else grids["down"]
        return [u for u in grid if (u < v if v > V_SEED else u > v)] + [float(v)]

    def add(transition, branch, eps, v, src, point=""):
        if src is None:
            return
        out.append({"case": f"h-{transition}-{branch}{point}-eps{eps:g}", "transition": transition, "branch": branch,
                    "epsilon": eps, "v": float(v), "point": point, "source": f"{src['case']} v {_num(src['target_v']):g}",
                    "state": str(state_path(states, src["case"], _num(src["target_v"]))), "walk_vs": walk_vs(branch, v, transition),
                    "layout_vs": layout_vs(branch, transition)})

    for e, x in summary.get("crossings", {}).items():
        eps = float(e)
        for b in ("prolate", "oblate"):
            add("crossing", b, eps, x["v"], nearest([r for r in pts if _num(r["epsilon"]) == eps and r["branch"] == b
                                                      and r.get("part") == "near" and r.get("shape") == b], x["v"]))
    for e, x in summary.get("oblate_stomatocyte_crossing", {}).get("per_eps", {}).items():
        eps = float(e)
        here = [r for r in pts if _num(r["epsilon"]) == eps]
        add("oblate_stomatocyte", "oblate", eps, x["v"],
            nearest([r for r in here if r["branch"] == "oblate" and r.get("part") == "low" and r.get("shape") == "oblate"], x["v"]))
        add("oblate_stomatocyte", "stomatocyte", eps, x["v"],
            nearest([r for r in here if r["branch"] == "stomatocyte" and r.get("walk") == "down"
                     and r.get("shape") in ("cup", None, "")], x["v"]))
    for e in sorted(summary.get("stomatocyte_fold", {}).get("per_eps", {}), key=float):  # one case an eps (one walk
        # to its points), the finest first: the longest, and the two the p = 2 limit is taken through
        eps = float(e)
        up = up_walk(pts, eps)
        idx = fold_points([_num(r["reduced_volume"]) for r in up])
        if idx:
            v_top = max(_num(up[k]["target_v"]) for k in idx)
            add("fold", "stomatocyte", eps, v_top, up[idx[-1]])
            out[-1]["points"] = [{"v": _num(up[k]["target_v"]), "point": str(i), "state": str(state_path(
                states, up[k]["case"], _num(up[k]["target_v"]))), "source": f"{up[k]['case']} v {_num(up[k]['target_v']):g}"}
                for i, k in enumerate(idx)]
    coarsest = {}
    for c in out:
        coarsest[c["transition"]] = max(coarsest.get(c["transition"], 0.0), c["epsilon"])
    for c in out:  # eps/h = 8 where it is cheapest (``ORDER_FROM``): the order observed there serves every eps
        c["levels"] = list(LEVELS if ORDER_FROM == "all" or c["epsilon"] == coarsest[c["transition"]] else CHEAP_LEVELS)
    return out


def _state_key(r: dict) -> tuple:
    """(transition, branch + point, eps): one state of a transition at one eps, as its h-level rows (and
    its case's points) name it."""
    return r["transition"], r["branch"] + str(r.get("point") or ""), _num(r["epsilon"])


def order_cases(rows: list[dict], staged: list[dict]) -> list[dict]:
    """Stage three: for a transition none of whose states has eps/h = 2, 4 and 8 certified at any eps
    (its coarsest eps refused eps/h = 2, so ``LEVELS`` skipped eps/h = 8 there and every share fell
    back to p = 2: measured at the fold, eps 0.04), eps/h = 8 at the next eps down whose states all
    have eps/h = 2 and 4 certified: those ``staged`` cases again with the levels (1,) alone (warm from
    the saved state, as each level is) and the name suffix "-order" (the runner's resume key).
    ``shares`` then reads the order there. [] where no transition needs it."""
    got: dict = {}
    for r in rows:
        if r.get("kind") == "h_level" and str(r.get("converged")) == "True":
            got.setdefault(_state_key(r), set()).add(_num(r["eps_over_h"]))
    out = []
    for t in dict.fromkeys(c["transition"] for c in staged):
        if any(k[0] == t and {2.0, 4.0, 8.0} <= lv for k, lv in got.items()):
            continue  # the order is observed at some eps
        mine = [c for c in staged if c["transition"] == t]
        tried = {c["epsilon"] for c in mine if 1 in c.get("levels", LEVELS)}
        for eps in sorted({c["epsilon"] for c in mine} - tried, reverse=True):
            cs = [c for c in mine if c["epsilon"] == eps]
            if all({2.0, 4.0} <= got.get(_state_key({**c, "point": q.get("point")}), set())
                   for c in cs for q in _points(c)):
                out += [{**c, "case": f"{c['case']}-order", "levels": [1]} for c in cs]
                break
    return out


def up_walk(rows: list[dict], eps: float) -> list[dict]:
    """The stomatocyte's certified up-walk cups at eps, in walk order (what the fold is located on)."""
    return [r for r in rows if r["branch"] == "stomatocyte" and _num(r["epsilon"]) == eps and r.get("walk") == "up"
            and str(r.get("kind", "point")) in ("point", "") and str(r.get("converged")) == "True"
            and r.get("shape", "cup") in ("cup", None, "")]


# --- the summary ----------------------------------------------------------------------------------

def share_at_order(h, y, p: float) -> dict:
    """``share``'s record from the two levels eps/h = 2 and 4 (h decreasing) with the order ``p``
    observed on three levels at another eps (``shares``; nan: none observed, p = 2 used): the limit
    y_4 + (y_4 - y_2) / (2^p - 1) and the share of eps/h = 4, the finest here."""
    h, y = np.asarray(h, float), np.asarray(y, float)
    order = np.argsort(-h)
    h, y = h[order], y[order]
    lim = richardson_fixed(h, y, p) if math.isfinite(p) else math.nan
    return _record(p, lim, richardson_fixed(h, y, 2.0), y[-1])


def shares(rows: list[dict]) -> dict:
    """{(transition, branch+point, eps): share(...) of f and of lambda, with the levels' eps/h and f}
    from the certified ``h_level`` rows. With eps/h = 2, 4, 8: ``share`` (its own observed order);
    with eps/h = 2 and 4 only (the finer eps: ``cases``, ``ORDER_FROM``): ``share_at_order`` with the
    order of f (and of lambda) observed on the same state of the same transition at the coarsest eps
    that has three levels (``order_from_eps``); a state without a certified eps/h = 4 level, or with it
    alone, is left out (one with eps/h = 4 and 8 only gets the p = 2 share: ``share``)."""
    out, two = {}, {}
    hl = [r for r in rows if r.get("kind") == "h_level" and str(r.get("converged")) == "True"]
    for key in sorted({_state_key(r) for r in hl}):
        sel = [r for r in hl if _state_key(r) == key]
        sel = list({_num(r["eps_over_h"]): r for r in reversed(sel)}.values())  # one a level: the first row's
        got = {_num(r["eps_over_h"]) for r in sel}
        if 4.0 not in got or len(got) < 2:
            continue
        sel.sort(key=lambda r: _num(r["eps_over_h"]))
        h = [key[2] / _num(r["eps_over_h"]) for r in sel]
        entry = {"eps_over_h": [_num(r["eps_over_h"]) for r in sel], "f": [_num(r["f"]) for r in sel],
                 "lambda": [_num(r["lambda"]) for r in sel], "v": _num(sel[0]["target_v"])}
        if 8.0 in got:
            out[key] = {**entry, "f_share": share(h, entry["f"]), "lambda_share": share(h, entry["lambda"])}
        else:
            two[key] = (h, entry)
    for key, (h, entry) in two.items():  # the order of the same state at the coarsest eps with three levels
        ref = [k for k in out if k[:2] == key[:2] and math.isfinite(out[k]["f_share"]["order"])]
        k_ref = max(ref, key=lambda k: k[2]) if ref else None
        p_f, p_l = ((out[k_ref][q]["order"] if k_ref else math.nan) for q in ("f_share", "lambda_share"))
        out[key] = {**entry, "f_share": share_at_order(h, entry["f"], p_f),
                    "lambda_share": share_at_order(h, entry["lambda"], p_l),
                    "order_from_eps": k_ref[2] if k_ref else math.nan}
    return out


def _report(s: dict, f_walk: float) -> dict:
    """One state's levels in the summary: eps/h, f, the observed order of f, the mesh shares, and
    ``same_state``: its eps/h = 4 f minus the walks' f there (the spline's at a crossing, the walk's
    row at a fold point): the h-levels' state is the walks' one when this is at the solver's tolerance."""
    fs = s["f_share"]
    return {"v": s["v"], "eps_over_h": s["eps_over_h"], "f": s["f"], "order": fs["order"], "order_used": fs["order_used"],
            "order_from_eps": s.get("order_from_eps"),  # None: its own three levels
            "f_limit": fs["limit"], "mesh_share": fs["share"], "mesh_share_p2": fs["share_p2"],
            "lambda_order": s["lambda_share"]["order"], "same_state": s["f"][s["eps_over_h"].index(4.0)] - f_walk}


def crossings(data: dict, sh: dict, transition: str, branches, located: dict) -> tuple[dict, dict, dict]:
    """The corrected crossings per eps from ``data`` {eps: (va, fa, vb, fb)} (the eps/h = 4 points of
    the two branches), the shares ``sh`` (``shares``) and the crossings ``located`` on those points:
    ({eps: crossing} with the observed orders' shares, the same with p = 2, {eps: {branch: ``_report``}})."""
    per, per2, levels = {}, {}, {}
    for eps, (va, fa, vb, fb) in data.items():
        a, b = (sh.get((transition, br, eps)) for br in branches)
        if a is None or b is None:
            continue
        levels[eps] = {br: _report(s, located[eps]["reduced_energy"]) for br, s in zip(branches, (a, b))}
        for out, key in ((per, "share"), (per2, "share_p2")):
            da, db = a["f_share"][key], b["f_share"][key]
            x = corrected_crossing(va, fa, vb, fb, da, db) if math.isfinite(da) and math.isfinite(db) else None
            if x is not None:
                out[eps] = x
    return per, per2, levels


def fold(up: list[dict], sh: dict, eps: float) -> tuple[dict | None, dict | None, dict]:
    """The corrected fold at eps from the up walk's rows ``up`` (walk order) and the shares of its three
    fold points: (fold with the observed orders' shares, with p = 2, {point: ``_report``})."""
    idx = fold_points([_num(r["reduced_volume"]) for r in up])
    s = [sh.get(("fold", f"stomatocyte{i}", eps)) for i in range(len(idx))]
    if not idx or any(x is None for x in s):
        return None, None, {}
    v, f, lam = ([_num(up[k][c]) for k in idx] for c in ("reduced_volume", "f", "lambda"))
    out = []
    for key in ("share", "share_p2"):
        df, dl = (np.array([x[q][key] for x in s]) for q in ("f_share", "lambda_share"))
        fv = corrected_fold(v, f, lam, df, dl) if np.isfinite(df).all() and np.isfinite(dl).all() else None
        out.append({"reduced_volume": fv[0], "reduced_energy": fv[1]} if fv is not None else None)
    return out[0], out[1], {str(i): _report(x, f[i]) for i, x in enumerate(s)}
