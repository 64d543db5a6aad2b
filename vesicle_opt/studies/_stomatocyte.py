"""The stomatocyte cases of the ``phase_diagram`` study (c0 = 0): the sharp branch (eps = 0 rows,
``sharp.stomatocyte``) and the phase-field branch at one eps on the meridian half-plane.

Phase field: the first point of each walk, at v = ``V_SEED`` (the lower side of the fold), starts
from the tanh profile of a meridian curve there (``io.meridian.phase_field_of``, on a mesh refined
about it: ``studies._meridian``; column ``seed``): the sharp stomatocyte's (a SEED, as the prolate and
oblate cases start from their sharp shapes), or the phi = 0 curve of the phase field's own seedless
landing (``studies._landing``: ``switched`` + ``down_in_v`` below, at eps 0.03; the full study's
default, ``phase_diagram.FULL["stomatocyte_start"]``), which at eps 0.04-0.02 reaches the seeded cup.
The sharp stomatocyte itself is reached without a seed, by switching at the sharp oblate's branch point (``sharp.stomatocyte_switch``: v = 0.51044);
the phase field has no such route here yet: at the eps this machine affords (>= 0.025) the meridian
oblate's dimples meet (a torus) above v = 0.51 (at v = 0.58 for eps = 0.03, measured).
``seedless`` tries another (``branch.detour``): the oblate walked out in c0 at fixed v to where its odd
mode is unstable (the sharp branch point at v = 0.62 is at c0 = -0.985, the poles 0.27 R0 apart),
pushed along that mode, the landing walked back to c0 = 0; it is opt-in (case key ``seedless``;
docs/guide/bifurcation.md, "A detour in c0"). At eps 0.03 every push lands on a genus-1 state, not
the cup: a sickle-shaped torus (one closed meridian curve off the axis, up-down symmetric), a
certified minimum from c0 = -1.5 back to 0 (f 1.93522 there, below the seeded cup's 1.96834), so the
detour ends "no switch to B" and the walk starts from the seed (its rows say so); at v 0.66 / 0.70
(c0 -2.0 / -2.5) the pushes pinch the cup's neck instead (two nested spheres); at eps 0.02 (push at
c0 -1.25) the same torus (f 1.93269 at c0 0).
``switched`` + ``down_in_v`` reach it without a seed by a continuous switch (``branch.emanate``): the
branch out of the oblate's odd branch point in c0 followed by pseudo-arclength, c0 free, on a uniform
mesh. At eps 0.03 it is subcritical; at v 0.60 / 0.62 it turns at a fold in c0 (-0.523 / -0.390; at
0.62 it ends on another up-down symmetric state, dimples 0.14 R0 apart, at c0 -0.54), at v 0.66
(``V_SWITCH``) it passes c0 = 0, and the minimiser from there walked down in v at c0 = 0 is at v 0.62
the seeded cup's mirror image (f to 2.6e-15; docs/guide/bifurcation.md, "A continuous switch");
opt-in, no case calls them.
From the seed two walks at fixed v (``_meridian.walk``: exact IPOPT solves, each warm from the
previous point, second-order checked, axisymmetric perturbations only): ``up`` towards the fold on
the v grid ``up`` (its steps shrinking towards the sharp fold, 0.6604), ending at the first point
that does not converge or is no cup (past the phase field's fold there is no stomatocyte at that
v); ``down`` below the crossing with the oblate. Fixed-v minimisers stay on the fold's lower
(stable) side, so the fold is located from the lower side (``fold_of``). The branch package's
pseudo-arclength walk (p free) had stalled below the fold (steps shrinking to dv 4e-4; at v
0.645/0.638/0.637 after 26 points at eps 0.04/0.03/0.025): the axial slide was held by neither its
IPOPT solves nor its bordered Newton. With the axial pin (``branch.bordered.axial_pin``) it passes a
fold on IPOPT and on Newton-Krylov from this seed on uniform meshes at eps/h = 2, but at eps 0.1 and
0.05 the states there are no stomatocytes (a shell round a pocket, then a torus; a torus: the
meridian's topology, ``verify.topology``); at eps 0.04 (cups) both pass the stomatocyte's own fold
(``tests/branch/test_stomatocyte_cup_fold.py``; docs/guide/bifurcation.md). The study's refined meshes are banded about a shape, which the
branch package cannot yet take from a seed field, so its walks stay at fixed v. Every row carries the
sharp lower side at its v (``sharp_f``: Newton at 24 modes from the previous sharp point).

One case an eps walks both ways (``walk`` "both": ``vs`` up, then ``vs_down`` down from the same seeded
first point; the seed, 38-130 IPOPT iterations at eps 0.04-0.02, is solved once, where two cases
solved it twice: 144 of the diagram's 2016 CPU s, measured). The up walk stops before a grid point
that lies past the fold the lower side extrapolates to (``fold_of`` on its minima so far, by more than
``PAST_FOLD``): no minimiser exists there, and IPOPT ran to ``UP_MAX_ITER`` at that point (the last
point of every up walk, ~100 of the diagram's CPU s, measured).

The fold of a walk (``fold_of``): the branch's v and f are smooth in the volume multiplier
lambda = df/dv (``lambda_volume`` of the solves, any fixed unit), which is monotone through a fold,
while f(v) has a cusp there; near it v = v* - a (lambda - lambda*)^2. With points on both sides the
fold is the vertex of the parabola v(lambda) through the three around the largest v; with the lower
side only, the vertex of the parabola through its three points nearest the fold (an extrapolation
in lambda of at most ``AHEAD`` times the last lambda step), f the parabola f(lambda) there.
"""

from __future__ import annotations

import math
import types

import numpy as np

from vesicle_opt.branch.bordered import Affine, BorderedCorrector
from vesicle_opt.branch.corrector import IpoptCorrector
from vesicle_opt.branch.detour import detour
from vesicle_opt.branch.emanate import follow
from vesicle_opt.branch.params import parameter
from vesicle_opt.io.meridian import meridian_curves
from vesicle_opt.sharp import axisymmetric as sharp_a
from vesicle_opt.sharp import stomatocyte as sharp_s
from vesicle_opt.studies._common import num as _num
from vesicle_opt.studies._meridian import MAX_ITER, SEED_MAX_ITER, layout, scene, seed, solve_quiet, walk
from vesicle_opt.verify import updown

V_SEED = 0.62  # the seed's reduced volume: the lower side, 0.04 below the sharp fold (0.6604)
V_DOWN = 0.575  # the sharp reference's lower end: below the crossing with the oblate (0.5903)
AHEAD = 3.0  # a lower-side fold is extrapolated in lambda by at most this many of its last lambda steps
UP_MAX_ITER = 75  # IPOPT's cap on the up walk's warm points: the converged ones took <= 48 (eps 0.02, v 0.662,
# next to the fold: measured); the walk's last point lies past the fold, where no minimiser exists and IPOPT
# runs to the cap (150 iterations there, a third of the eps 0.03 walk's CPU time: measured)
SHARP_MODES = 24  # the sharp lower side at each phase-field point (fold 0.660376 at 24 modes, 0.660850 at 48)
PAST_FOLD = 5e-4  # the up walk skips a grid v this far past its lower-side fold (the lower-side vertex fell
# 1.1e-4 short of the walked fold at eps 0.05, measured; the grid's last steps are 2e-3)


def fold_of(v, f, lam) -> tuple[float, float] | None:
    """(v, f) at the fold of a branch given per point (v, f, lambda = df/dv in any fixed unit), in
    walk order (module docstring): the vertex of the parabola v(lambda) through the largest v and its
    two neighbours when the walk turned; else, on a walk that ends at its largest v (the lower side
    only), through its last three points, if the vertex lies ahead of the last lambda by at most
    ``AHEAD`` lambda steps; None otherwise."""
    v, f, lam = (np.asarray(x, float) for x in (v, f, lam))
    k = int(np.argmax(v))
    if len(v) < 3 or k == 0:
        return None
    sel = slice(k - 1, k + 2) if k < len(v) - 1 else slice(k - 2, k + 1)
    cv = np.polyfit(lam[sel], v[sel], 2)
    if cv[0] >= 0:
        return None
    at = -cv[1] / (2 * cv[0])
    if k == len(v) - 1:  # lower side only: the vertex must lie ahead, and not far
        dl = lam[k] - lam[k - 1]
        if not (0 <= (at - lam[k]) / dl <= AHEAD):
            return None
    return float(np.polyval(cv, at)), float(np.polyval(np.polyfit(lam[sel], f[sel], 2), at))


def sharp_case(case: dict) -> list[dict]:
    """The sharp stomatocyte branch (``sharp.stomatocyte.reference``): eps = 0 rows, its fold and
    its crossing with the oblate as rows of kind ``fold`` / ``crossing``."""
    ref = sharp_s.reference(0.0, case["n_modes"], ds=case.get("ds", 0.05), v_low=V_DOWN)
    base = {"branch": "stomatocyte", "shape": "cup", "c0": 0.0, "epsilon": 0.0, "n": str(case["n_modes"]),
            "converged": True, "seed": "three-arc cup (sharp.stomatocyte.cup_start)", "status": "ok"}
    rows = []
    for side in ("lower", "upper"):
        for v, f in ref[side]:
            rows.append({**base, "kind": "point", "side": side, "target_v": v, "reduced_volume": v, "f": f,
                         "sharp_f": f})
    for kind in ("fold", "crossing"):
        v, f = ref[kind]
        rows.append({**base, "kind": kind, "side": "", "target_v": v, "reduced_volume": v, "f": f, "sharp_f": f})
    return rows


def phase_case(case: dict, point_row, start_curve=None) -> list[dict]:
    """The phase-field stomatocyte at ``case["epsilon"]``, the walk ``case["walk"]`` (up / down, or
    "both": up over ``vs``, then down over ``vs_down`` from the same first point) from the seed at
    vs[0] = ``V_SEED`` (module docstring), or from ``start_curve`` = (r, z, label) there (a meridian
    curve in the seed's place, the label the first row's ``seed``: ``studies._landing``'s seedless
    one), or with ``case["seedless"]`` from the detour in c0
    (``seedless``: its solves are rows of kind "detour", their c0 their own; the seed where it is not
    reached, the column ``seed`` saying so);
    ``point_row(res, v, eps, lay, sharp_f, seed, side, walk)`` makes a study row (side "lower":
    fixed-v minimisers)."""
    eps, name = case["epsilon"], "phase_diagram-stomatocyte"
    seed_pt = sharp_s.start_point(case["vs"][0], 0.0, case["n_modes"])  # the sharp reference (and the seed)
    r, z = seed_pt.meridian(2048)
    rows, start, first = [], None, f"sharp stomatocyte at v = {case['vs'][0]} (a seed)"
    if start_curve is not None:
        r, z, first = start_curve
    if case.get("seedless"):
        d, lay = seedless(case["vs"][0], eps, case["eps_over_h"], case.get("refine", True), name=f"{name}-detour")
        for st in d.steps:
            rows.append({**point_row(st.state, case["vs"][0], eps, lay, math.nan, f"detour {st.leg}", "", "detour"),
                         "c0": st.q, "kind": "detour"})
        if d.reached:
            start = d.end.state
            first = f"no seed: detour in c0 from the oblate (switched at c0 = {d.switched_at:g})"
        else:  # the seed after all, and the rows say why
            rows[-1]["status"] = f"detour not reached: {d.stopped}"
            first += "; the detour in c0 was not reached"
    if start is None:
        lay = layout([(r, z)], eps, case["eps_over_h"], case.get("refine", True))
    legs = [("up", case["vs"]), ("down", case["vs_down"])] if case["walk"] == "both" else [(case["walk"], case["vs"])]
    for leg, vs in legs:
        if leg == "down" and case["walk"] == "both":  # from the up walk's first point, solved once
            if start is None:
                break
            vs, first = vs[1:], "the up walk's first point (the same seed)"
        got = _leg(case, leg, vs, lay, eps, name, (r, z), start, first, seed_pt, point_row)
        if leg == "up" and case["walk"] == "both":
            start = got[0][1] if got and got[0][1].converged else None
        rows += [row for row, _ in got]
    return rows


def _leg(case, leg, vs, lay, eps, name, first_shape, start, first, seed_pt, point_row) -> list:
    """One walk of ``phase_case`` (up / down) over ``vs``: [(row, Result)]; an up walk stops after a
    point that is no cup or did not converge, or before a v past its lower-side fold (``PAST_FOLD``)."""
    sharp_pts = {case["vs"][0]: seed_pt}
    mins: list = []  # (v, f, lambda) of the walk's cups so far, one a grid point of ``vs``

    out: list = []

    def stop(res) -> bool:  # past the fold (no minimiser), or no stomatocyte any more (a torus, an oblate)
        # the point's row, made by the loop below before the walk resumes and asks here: its shape
        if not res.converged or out[-1][0]["shape"] != "cup":
            return True
        mins.append((_num(res.extra.get("reduced_volume")), _num(res.extra.get("f")), res.lambda_volume))
        fv = fold_of(*zip(*mins)) if leg == "up" and len(mins) >= 3 else None
        return bool(fv is not None and len(mins) < len(vs) and vs[len(mins)] > fv[0] + PAST_FOLD)

    cap = UP_MAX_ITER if leg == "up" else MAX_ITER
    for k, (v, res, label) in enumerate(walk(lay, eps, vs, first_shape, f"{name}-{leg}", stop, start,
                                             case.get("states"), case.get("case", name), max_iter=cap)):
        q = sharp_pts.get(v)
        if q is None:
            try:
                q = sharp_s.newton(list(sharp_pts.values())[-1].a, v, 0.0, case["n_modes"])
                sharp_pts[v] = q
            except (sharp_s.NotConverged, np.linalg.LinAlgError):
                q = None  # past the sharp fold: no lower-side point
        seed = first if k == 0 else label
        out.append((point_row(res, v, eps, lay, q.f if q is not None else math.nan, seed, "lower", leg), res))
    return out


# --- the seedless start: a detour in c0 (``branch.detour``) ----------------------------------------
DETOUR_C0 = (0.0, -0.5, -1.0, -1.25, -1.5)  # the way out at V_SEED (literature c0): the sharp oblate's odd branch
# point at v = 0.62 is at c0 = -0.985 (odd eigenvalue +0.088 at -0.75, -0.0055 at -1.0); the meridian oblate
# at eps 0.03 is a saddle from c0 = -1.0 (least eigenvalue -0.0014 mu_ref; -0.0092 at -1.5; +0.0053 at -0.5)
PUSH_BEYOND = -1.0  # no push before (at -0.5 the oblate is stable); at c0 = -1.0 (mu -0.0014) pushes
# capped at 150 IPOPT iterations moved f by 8e-4 only, at 800 they left the oblate (measured, eps 0.03)
PUSH_AMPLITUDE = 0.5  # the push's largest change of phi (the critical mode scaled to this max |.|)
PUSH_ITER = 800  # IPOPT iterations of a pushed solve: on the tall box they took 82-96 (eps 0.03, measured)
TALL = 0.8  # the box's least half-height (before the walls' 12 eps) in units of the oblate's radius: the cup
# (sharp, v 0.62) spans -0.84 .. +0.70 (c0 0) and -0.86 .. +0.80 (c0 -1) about its volume centroid, which the
# axial pin holds at mid-height; 0.8 x 1.238 = 0.99. On the box about the oblate (half-height 0.34 + 12 eps) the
# pushes landed on tubes from wall to wall (f 1.33 / 1.49 / 1.13 at c0 = -1.0 / -1.25 / -1.5, no cup); on this
# one (n_z even, ``_meridian.layout``) on a sickle torus, f 2.72638 / 2.99431 / 3.29131 (both signs, amplitudes 0.05
# and 0.5, and a shift of the dimples by 0.25 along the axis: the same torus), no cup either (measured, eps 0.03)
OBLATE_MODES = 16  # the sharp oblate of the detour's start (as phase_diagram's oblate rows)


def tall_layout(mer, eps: float, eps_over_h: float, refine: bool = True) -> dict:
    """The detour's box: about the oblate's meridian ``mer`` (centred at z = 0) and at least ``TALL``
    times its radius above and below z = 0 (room for the cup the push turns it into), the walls'
    ``WALL`` eps beyond and n_z even (``_meridian.layout``: with n_z odd the band mesh is not mirrored
    about mid-height and the pin holds a force; on this box at eps 0.03, n_z = 19, the oblate's cold start
    ended kkt_not_met, kkt_dual 1.67e-6, pin multiplier -0.11; with 20 rows it is certified in 14 IPOPT
    iterations, multiplier -4e-12, measured)."""
    half = TALL * float(np.max(mer[0]))
    return layout([mer, (np.zeros(2), np.array([-half, half]))], eps, eps_over_h, refine)


def seedless(v: float, eps: float, eps_over_h: float, refine: bool = True, c0s=DETOUR_C0,
             name: str = "phase_diagram-stomatocyte-detour", push_beyond: float | None = None):
    """The phase-field stomatocyte at (v, c0 = c0s[0] = 0) reached WITHOUT a stomatocyte seed
    (``branch.detour``): the oblate from its sharp shape (as the oblate rows start), walked in c0
    at fixed v down ``c0s`` until its least eigenvalue (the odd mode) is negative, the solve from it
    pushed along that mode, the cup it lands on walked back to c0 = 0. Returns (the Detour, the
    layout); ``detour.end.state`` is the certified stomatocyte (a Result) when ``detour.reached``.
    ``push_beyond``: ``PUSH_BEYOND`` unless given."""
    ref = sharp_a.solve(v, "oblate", OBLATE_MODES, second_order=False)
    mer = ref.meridian(2048)
    lay = tall_layout(mer, eps, eps_over_h, refine)

    def solve(c0, start):
        pushed = isinstance(start, types.SimpleNamespace) and getattr(start, "pushed", False)
        sc = scene(lay, eps, v, f"{name}-c{c0:g}-eps{eps:g}", c0=c0, max_iter=PUSH_ITER if pushed else MAX_ITER)
        return solve_quiet(sc, seed(sc, *mer, eps, lay["h"]) if start is None else start)

    def check(res):
        mu = res.extra.get("second_order_min_eigenvalue")
        mode = res.history.get("second_order_mode")
        return res.converged, (math.nan if mu is None else float(mu)), mode

    def push(res, mode, a):
        mode = np.asarray(mode, float)
        phi = np.clip(res.phi + a * mode / np.abs(mode).max(), -1.0, 1.0)
        return types.SimpleNamespace(disc=res.disc, phi=phi, pushed=True)

    def is_cup(res):
        return updown.describe(res.disc, res.phi).get("form") == "cup"

    def is_oblate(res):
        return updown.describe(res.disc, res.phi).get("form") == "oblate"

    return detour(solve, check, push, is_cup, c0s, PUSH_AMPLITUDE,
                  PUSH_BEYOND if push_beyond is None else push_beyond, is_oblate), lay


# --- the seedless start by continuation: the branch out of the oblate's odd branch point in c0 -----
SWITCH_C0 = (0.0, -0.4, -0.7, -0.8, -0.85, -0.9)  # the oblate's walk in c0 at v 0.62 (literature c0): its
# least eigenvalue +0.0106, +0.0058, +0.0019, +0.0005, -0.0002, -0.0009 mu_ref (eps 0.03, eps/h 2, measured)
SWITCH_EPS_OVER_H = 2.0  # the uniform mesh of the walk (the branch moves the interface by O(R0): no band
# holds it); 19.7 k nodes on the tall box at eps 0.03, ~2.5 s a point of 5-10 Newton or chord steps (measured)
SWITCH_AMPLITUDE = 0.02  # a of the switch (<u - u*, v>_w = a, v M-normalised, max |v| 3.9): at 0.1 the
# bordered Newton diverged (c0 -> -5e8), at 0.02 it converged in 11 steps (measured)
SWITCH_DS = (0.02, 0.3)  # the arclength's first and largest step: |phi|_w = 4.5 on this box, so a step changes
# the field by at most ~7 % (the walks measured stayed at 0.007-0.03: Newton took 6-10 steps)


def switched(v: float, eps: float, eps_over_h: float = SWITCH_EPS_OVER_H, c0s=SWITCH_C0,
             amplitude: float = SWITCH_AMPLITUDE, budget_s: float = 3000.0, name: str = "stomatocyte-switch"):
    """The phase-field stomatocyte's branch at (v, c0 = 0) WITHOUT a seed, by continuation
    (``branch.emanate``; at eps 0.03 it gets there at v = ``V_SWITCH``, not at 0.60 / 0.62: module docstring):
    the oblate (from its sharp shape) walked in c0 down ``c0s`` on the uniform tall box to the first
    sign change of its least eigenvalue, the branch point located by the secant (one solve), then the
    branch leaving it along the critical (odd) mode followed with c0 free (the bordered corrector, the
    axial pin as its phase condition) until c0 passes 0, every point required to stay one meridian
    curve from the axis to the axis (``verify.updown.form`` oblate or cup: no torus, no two
    components); the landing certified by the fixed-c0 IPOPT solve and its second-order check.
    Returns a namespace: ``oblate`` [(c0, Result)], ``c_star`` (literature c0), ``bp`` (its Result), ``followed`` (the
    ``Followed``, its p = model.c0 = c0 / 2), ``end`` (the certified Result at c0 = 0 or None), ``lay``,
    ``corrector``."""
    import types as _t


    mer = sharp_a.solve(v, "oblate", OBLATE_MODES, second_order=False).meridian(2048)
    lay = tall_layout(mer, eps, eps_over_h, refine=False)
    # the cold solves' cap (the oblate's start, ``down_in_v``'s slide off the landing: 210 iterations at
    # v 0.66, eps 0.03, measured; MAX_ITER's 150 stopped it short)
    sc = scene(lay, eps, v, name, max_iter=SEED_MAX_ITER)
    corr = IpoptCorrector(sc)
    par = parameter(sc, "c0")
    out = _t.SimpleNamespace(oblate=[], c_star=None, bp=None, followed=None, end=None, lay=lay, corrector=corr)
    res = corr.solve(sc, seed(sc, *mer, eps, lay["h"]).phi, None)

    def at(c0, phi, last):  # warm (capped at WARM_MAX_ITER = 6), else cold from the same field
        warm = corr.solve(par.scene_at(sc, c0 / 2), phi, (last.lambda_volume, last.lambda_area))
        return warm if warm.converged else corr.solve(par.scene_at(sc, c0 / 2), phi, None)
    for c0 in c0s:
        if c0 != c0s[0]:
            res = at(c0, res.phi, res)
        if not res.converged:
            return out
        out.oblate.append((c0, res))
        if len(out.oblate) > 1 and res.extra["second_order_min_eigenvalue"] < 0:
            break
    else:
        return out
    (ca, ra), (cb, rb) = out.oblate[-2:]
    ma, mb = ra.extra["second_order_min_eigenvalue"], rb.extra["second_order_min_eigenvalue"]
    c_star = ca - ma * (cb - ca) / (mb - ma)
    s = (c_star - ca) / (cb - ca)
    bp = at(c_star, (1 - s) * ra.phi + s * rb.phi, ra)
    if not bp.converged:
        return out
    out.c_star, out.bp = c_star, bp
    bc = BorderedCorrector(corr.scene, corr.disc, Affine(*par.affine(sc)))

    def accept(nw) -> bool:  # one meridian curve from the axis to the axis: no torus, no two components
        return updown.form(meridian_curves(corr.disc, nw.phi)) in ("oblate", "cup")

    out.followed = follow(bc, bp.phi, c_star / 2, (bp.lambda_volume, bp.lambda_area),
                          bp.history["second_order_mode"], amplitude, corr.disc.weights, 0.0, accept=accept,
                          ds=SWITCH_DS[0], ds_max=SWITCH_DS[1], budget_s=budget_s)
    if out.followed.end is not None:
        e = out.followed.end
        out.end = corr.solve(sc, e.phi, e.lam, feasibility=False)
    return out


V_SWITCH = 0.66  # where the branch of ``switched`` reaches c0 = 0 (eps 0.03): it turns in c0 at -0.523 / -0.390 for
# v 0.60 / 0.62 and passes c0 = 0 at v 0.66, next to the cup's fold in v (sharp 0.6604), measured


def down_in_v(corr, sc, phi, vs) -> list:
    """The landing of ``switched`` (``phi`` at c0 = 0, v = ``sc``'s) walked down in v at c0 = 0 by the
    fixed-v minimiser (``corr``, the route's IpoptCorrector): cold from the landing (a saddle next to
    the fold: the minimiser slides to the fold's stable side, the cup), then warm along ``vs`` (cold
    where a warm solve capped at 6 iterations does not finish). [(v, Result)]; the walk stops at the
    first point that does not converge."""

    pv = parameter(sc, "reduced_volume")
    res = corr.solve(sc, phi, None)
    out = [(pv.start, res)]
    for v in vs:
        if not res.converged:
            break
        s = pv.scene_at(sc, v)
        warm = corr.solve(s, res.phi, (res.lambda_volume, res.lambda_area), feasibility=False)
        res = warm if warm.converged else corr.solve(s, res.phi, None, feasibility=False)
        out.append((v, res))
    return out
