"""The cost of a warm 3D branch point against the grid: a prolate walk on octant mirror grids, eps ~ h.

Per level (``LEVELS``: eps = 0.14, 0.07, 0.05, 0.035 at eps / h = 2.5, in the octant boxes of
``crossing_3d.octant_box``: 31 k, 98 k, 205 k, 525 k nodes; the work of the eps -> 0 limit, since the
grid follows eps): ``vesicle_opt.branch`` of the octant prolate (c0 = 0, area 4 pi, exact constraints,
tol 1e-8, the second-order check on) from v = 0.71 down in steps of 0.01 (the walk's step control
adjusts them), ``points`` points, in a fresh process. Per point (a row): the CPU seconds of the
process between two points (``time.process_time``: the machine is shared, wall time is reported
beside it and the load average with it), the DCTs done (``mesh.cosine.CosineGrid.transforms``: every
Hessian product, preconditioner application and check iteration costs a fixed number of them, so
this count is the machine-independent work), the Newton steps (``iterations``: the bordered
Newton-Krylov steps of ``branch.nk_free`` plus the certifying fixed-p solve's), the GMRES iterations
(their sum, ``krylov``; the list, ``krylov_iterations``), the preconditioner applications in them
(``pinv``), the second-order check's CPU seconds and its LOBPCG iterations (fine level and the coarse
levels, ``check_iterations``, ``check_coarse_iterations``).

``summary``: per level the median over the warm points (``WARM`` points after the first two: the first
is the cold start, the second the fixed-step natural point) and their CPU seconds over the stretch of
v they walk (``cpu_s_per_v``: the step control sets how far a point goes), and the exponent of each
quantity in the node count, ``np.polyfit`` of log(quantity) on log(nodes) through all levels (and
through the two largest); ``steady`` and ``exponents_steady``: the same over the points after those
(``STEADY_FROM`` on), past the step control's transient at the largest level; ``all_warm`` and
``exponents_all_warm``: over both. Each level is walked ``REPEATS`` times, interleaved (``cases``);
the medians pool the repeats, and ``by_repeat`` / ``exponent_spread`` give each round's own CPU
exponents. ``main(out, quick)`` writes ``bench_branch_3d.csv`` and ``.json``; quick: eps = 0.25, 0.2
(9 k and 13 k nodes, 4 points each, one round; ~2 min). Measured figures: ``docs/guide/large-3d.md``
(three rounds, points 2-9, with the coarse space's assembly on the probed pattern: 0.40, 1.27, 3.06,
11.3 CPU s, nodes^1.18, the commit before it run straight after 0.385, 1.26, 3.32, 11.9 s, nodes^1.22,
the same counts; with the Hessian's Galerkin matrix in the corrector's coarse space: 0.43,
1.38, 3.45, 12.7 CPU s at 31 k, 98 k, 205 k, 525 k nodes, nodes^1.19, the commit before it run straight
after 0.49, 1.57, 4.08, 16.6 s, nodes^1.24, DCTs a point nodes^0.17 against 0.21; a unit of v 41, 136,
346, 1461 s; with ``nk.gmres`` 0.49, 1.60, 4.19, 17.0 s, nodes^1.26, and the previous commit, scipy's GMRES, run straight before it 0.51, 1.72, 4.45,
18.2 s, also 1.26, the same Newton and GMRES counts; with Newton's step along the profile 0.50, 1.67,
4.58, 19.0 s, nodes^1.28, and the plain step 0.54, 1.77, 4.97, 19.7 s, also 1.28, where the day before
it had measured 1.16-1.18 with the same DCTs: the machine's pace at the small levels moves the CPU
exponent by ~0.1; the DCTs a point nodes^0.21 in all of them; a unit of v 47, 158, 421, 2168 s; 0.89,
5.0, 22.7 s a point, nodes^1.70, before the interface band's coarse space; the whole study ~15 min at
load ~1, the 525 k level's cold starts 49-64 CPU s each).
"""

from __future__ import annotations

import logging
import math
import os
import statistics
import time
from pathlib import Path

import numpy as np

from vesicle_opt.branch import branch
from vesicle_opt.branch import krylov_bordered as kb
from vesicle_opt.branch import nk_corrector as nc
from vesicle_opt.mesh.cosine import CosineGrid
from vesicle_opt.scene.schema import from_dict
from vesicle_opt.studies import crossing_3d as cx
from vesicle_opt.studies.runner import in_fresh_process, run_study
from vesicle_opt.verify import lobpcg
from vesicle_opt.studies._common import num as _num

log = logging.getLogger(__name__)

NAME = "bench_branch_3d"
LEVELS = (0.14, 0.07, 0.05, 0.035)
QUICK_LEVELS = (0.25, 0.2)
POINTS = 10  # a cold start, a natural step and eight arclength points, at every level: the medians are
# then over the same points at every level
V_START, V_STEP = 0.71, -0.01
WARM_FROM = 2  # the first warm arclength point (0: the cold start, 1: the natural step)
WARM = 4  # the warm points the summary's medians take (points 2-5, as in earlier releases)
STEADY_FROM = WARM_FROM + WARM  # ``steady``: the points after them (6-9). At 525 k nodes points 2-5 are
# still the step control's transient, adapting the natural step's dv 0.01 (Newton 12 / 10 / 9 / 8, then
# 7-8); at 31 k-205 k nodes the two windows agree
REPEATS = 3  # each level walked three times, interleaved (``cases``): the CPU seconds of one walk vary
# by up to 1.8x between runs at low load with the same DCT counts (31 k nodes, 0.55-0.99 ms a DCT), which
# moved one run's exponent by ~0.1 (1.06-1.25 over points 2-5 in three runs); the medians pool the repeats
# and ``by_repeat`` gives each round's own exponents, their spread
QUANTITIES = ("cpu_s", "transforms", "newton", "krylov", "pinv", "check_cpu_s", "check_transforms")


def scene(epsilon: float):
    """The octant prolate at v = V_START on the mirror grid of ``crossing_3d.octant_box`` at eps."""
    box, n = cx.octant_box(cx.HALF_EXTENT["prolate"], epsilon)
    raw = {"domain": {"box": box, "boundary": "natural"}, "mesh": {"kind": "spectral", "n": n},
           "model": {"epsilon": epsilon}, "constraints": {"reduced_volume": V_START, "area": cx.AREA},
           "initial": {"shape": "ellipsoid", "semi_axes": cx.START_AXES["prolate"], "center": [0.0, 0.0, 0.0]},
           "solver": {"method": "exact", "tol": 1e-8, "backend": "newton-krylov", "max_iter": 500,
                      "second_order": True}}
    return from_dict(raw, f"prolate-octant-eps{epsilon:g}")


class _Meter:
    """Counts and CPU time of the check and of the GMRES preconditioner, per point (instrumented
    by wrapping the corrector's check and ``krylov_bordered.bordered_solve`` for one walk)."""

    def __init__(self):
        self.reset()

    def reset(self):
        self.check_cpu, self.check_transforms, self.check_iterations, self.coarse, self.pinv = 0.0, 0, [], [], 0

    def install(self):
        check, spectrum, solve = nc.NewtonKrylovCorrector.check, lobpcg.spectrum, kb.bordered_solve
        meter = self

        def timed_check(self, *a, **k):
            c0, t0 = time.process_time(), CosineGrid.transforms
            out = check(self, *a, **k)
            meter.check_cpu += time.process_time() - c0
            meter.check_transforms += CosineGrid.transforms - t0
            return out

        def counted_spectrum(*a, **k):
            out = spectrum(*a, **k)
            meter.check_iterations.append(out["iterations"])
            meter.coarse.extend(int(c[1]) for c in out["coarse_iterations"])
            return out

        def counted_solve(hvp, pinv, *a, **k):
            def p(r):
                meter.pinv += 1
                return pinv(r)
            return solve(hvp, p, *a, **k)
        nc.NewtonKrylovCorrector.check = timed_check
        lobpcg.spectrum = counted_spectrum
        kb.bordered_solve = counted_solve


def walk(epsilon: float, points: int) -> list[dict]:
    """One level's walk (module docstring), a row per point."""
    sc = scene(epsilon)
    meter = _Meter()
    meter.install()
    rows: list[dict] = []
    last = [time.process_time(), time.perf_counter(), CosineGrid.transforms]

    def progress(row: dict) -> None:
        c, w, t = time.process_time(), time.perf_counter(), CosineGrid.transforms
        krylov = [int(k) for k in str(row.get("krylov_iterations") or "").split(";") if k]
        rows.append({"scene": sc.name, "method": "exact", "n": "x".join(map(str, sc.mesh.n)),
                     "h": epsilon / 2.5, "energy": row.get("energy"), "iterations": row.get("iterations"),
                     "wall_time_s": w - last[1], "status": row.get("status"), "epsilon": epsilon,
                     "nodes": int(np.prod(sc.mesh.n)), "point": row["point"], "target": row["target"],
                     "corrector": row.get("corrector"), "accepted": row.get("accepted"),
                     "converged": row.get("converged"), "second_order": row.get("second_order"),
                     "reduced_energy": row.get("reduced_energy"), "cpu_s": c - last[0], "transforms": t - last[2],
                     "newton": row.get("iterations"), "krylov": sum(krylov),
                     "krylov_iterations": row.get("krylov_iterations"), "pinv": meter.pinv,
                     "check_cpu_s": meter.check_cpu, "check_transforms": meter.check_transforms,
                     "check_iterations": ";".join(map(str, meter.check_iterations)),
                     "check_coarse_iterations": ";".join(map(str, meter.coarse)),
                     "load_average": os.getloadavg()[0]})
        log.info(f"{NAME}: eps={epsilon:g} point {row['point']} v={row['target']:.4f} {row.get('corrector')} "
                 f"cpu={c - last[0]:.2f}s DCT={t - last[2]} newton={row.get('iterations')} "
                 f"gmres={row.get('krylov_iterations')} check={meter.check_cpu:.2f}s")
        meter.reset()
        last[:] = [time.process_time(), time.perf_counter(), CosineGrid.transforms]
    branch(sc, "reduced_volume", to=0.5, step=V_STEP, max_points=points, switch=False, progress=progress)
    return rows


def case_rows(case: dict) -> list[dict]:
    os.environ.setdefault("OMP_NUM_THREADS", "1")  # the child's BLAS (as bench_3d)
    return [{**r, "repeat": case.get("repeat", 0)} for r in in_fresh_process(walk, case["epsilon"], case["points"])]


def cases(quick: bool, repeats: int = REPEATS) -> list[dict]:
    """Every level's walk ``repeats`` times, interleaved (round r walks every level before round r + 1:
    a slow spell of the shared machine then falls on all levels of a round, not on one level)."""
    levels = QUICK_LEVELS if quick else LEVELS
    return [{"case": f"eps{e:g}" + (f"-r{r}" if r else ""), "epsilon": e, "repeat": r,
             "points": 4 if quick else POINTS} for r in range(1 if quick else repeats) for e in levels]


def exponents(nodes, values) -> float:
    """The slope of log(values) against log(nodes) (``np.polyfit``, degree 1); NaN with < 2 levels."""
    x, y = np.log(np.asarray(nodes, float)), np.log(np.asarray(values, float))
    ok = np.isfinite(x) & np.isfinite(y)
    return float(np.polyfit(x[ok], y[ok], 1)[0]) if ok.sum() >= 2 else math.nan


def _per_v(rows: list[dict], epsilon: float, warm: list[dict]) -> float:
    """The warm points' CPU seconds over the stretch of v they walk (from the point before the first
    warm one to the last): the cost of a unit of branch, which the step sizes enter (NaN without it)."""
    cpu = span = 0.0
    for rep in {_repeat(r) for r in warm}:  # each repeat's stretch of v (the repeats walk the same v)
        mine = [r for r in warm if _repeat(r) == rep]
        by_point = {int(_num(r.get("point"))): r for r in rows
                    if _num(r.get("epsilon")) == epsilon and _repeat(r) == rep}
        first, last = min(int(_num(r["point"])) for r in mine), max(int(_num(r["point"])) for r in mine)
        if first - 1 not in by_point:
            return math.nan
        span += abs(_num(by_point[last].get("target")) - _num(by_point[first - 1].get("target")))
        cpu += sum(_num(r.get("cpu_s")) for r in mine)
    return cpu / span if span > 0 else math.nan


def _repeat(row: dict) -> int:
    """The row's repeat (0 where the CSV has no such column: rows of earlier releases)."""
    x = _num(row.get("repeat"))
    return 0 if not math.isfinite(x) else int(x)


def _window(rows: list[dict], epsilon: float, first: int, last: float) -> dict | None:
    """The medians over a level's accepted points first <= point < last (of every repeat), their CPU
    seconds a unit of v and the load (None without such points)."""
    pts = [r for r in rows if _num(r.get("epsilon")) == epsilon and first <= _num(r.get("point")) < last
           and str(r.get("accepted")) in ("True", "true")]
    if not pts:
        return None
    return {"nodes": int(_num(pts[0]["nodes"])), "warm_points": len(pts),
            **{q: statistics.median(_num(r.get(q)) for r in pts) for q in QUANTITIES},
            "cpu_s_per_v": _per_v(rows, epsilon, pts),
            "load_average": statistics.median(_num(r.get("load_average")) for r in pts)}


def _fits(levels: dict) -> dict:
    nodes = [v["nodes"] for v in levels.values()]
    return {q: exponents(nodes, [v[q] for v in levels.values()]) for q in (*QUANTITIES, "cpu_s_per_v")}


WINDOWS = {"warm": (WARM_FROM, STEADY_FROM), "steady": (STEADY_FROM, math.inf), "all_warm": (WARM_FROM, math.inf)}
SUMMARY_KEYS = {"warm": ("levels", "exponents"), "steady": ("steady", "exponents_steady"),
                "all_warm": ("all_warm", "exponents_all_warm")}  # a window's medians and fits in the JSON


def summary(rows: list[dict], case_list: list[dict]) -> dict:
    """Per level the medians over the warm points (``WARM`` of them from ``WARM_FROM``) and, in
    ``steady``, over the points after them, in ``all_warm`` over both (``WINDOWS``); the repeats
    pooled; the exponents in the node count (docstring), and each repeat's own (``_by_repeat``)."""
    eps = list(dict.fromkeys(c["epsilon"] for c in case_list))  # the levels, once each (cases repeat them)
    out: dict = {}
    for name, (first, last) in WINDOWS.items():
        found = {e: w for e in eps if (w := _window(rows, e, first, last)) is not None}
        medians, fits = SUMMARY_KEYS[name]
        if found or name == "warm":
            out[medians] = {f"{e:g}": v for e, v in found.items()}
        if len(found) >= 2:
            out[fits] = _fits(found)
            if name == "warm":
                top = sorted(found.values(), key=lambda v: v["nodes"])[-2:]
                out["exponents_two_largest"] = {q: exponents([v["nodes"] for v in top], [v[q] for v in top])
                                                for q in QUANTITIES}
    out.update(_by_repeat(rows, case_list))
    return out


def _by_repeat(rows: list[dict], case_list: list[dict]) -> dict:
    """Each repeat's own CPU exponent in each window (``WINDOWS``) and, over the repeats, their least,
    median and largest (``exponent_spread``): how far one run's exponent can be trusted. Empty with
    fewer than two repeats."""
    reps = sorted({_repeat(r) for r in rows})
    if len(reps) < 2:
        return {}
    levels = sorted({c["epsilon"] for c in case_list}, reverse=True)
    each: dict = {}
    for rep in reps:
        mine = [r for r in rows if _repeat(r) == rep]
        fits = {}
        for name, (first, last) in WINDOWS.items():
            ws = [w for e in levels if (w := _window(mine, e, first, last)) is not None]
            fits[name] = exponents([w["nodes"] for w in ws], [w["cpu_s"] for w in ws]) if len(ws) >= 2 else math.nan
        each[str(rep)] = fits
    spread = {}
    for name in WINDOWS:
        xs = sorted(x for f in each.values() if math.isfinite(x := f[name]))
        if xs:
            spread[name] = {"min": xs[0], "median": statistics.median(xs), "max": xs[-1], "repeats": len(xs)}
    return {"by_repeat": each, "exponent_spread": spread}


EXTRA = ["repeat", "epsilon", "nodes", "point", "target", "corrector", "accepted", "converged", "second_order",
         "reduced_energy", "cpu_s", "transforms", "newton", "krylov", "krylov_iterations", "pinv", "check_cpu_s",
         "check_transforms", "check_iterations", "check_coarse_iterations", "load_average"]


def main(out: Path, quick: bool = False) -> int:
    """Rows appended per level as it finishes (resumable); the summary with the exponents."""
    out = Path(out)
    todo = cases(quick)
    rows, info = run_study(NAME, todo, case_rows, summary, out, extra_columns=EXTRA)
    for e, v in info.get("levels", {}).items():
        log.info(f"{NAME}: eps={e} nodes={v['nodes']} median warm point: cpu {v['cpu_s']:.2f}s, "
                 f"DCT {v['transforms']:.0f}, newton {v['newton']:.0f}, gmres {v['krylov']:.0f}, "
                 f"check {v['check_cpu_s']:.2f}s; cpu per unit of v {v['cpu_s_per_v']:.0f}s")
    for e, v in info.get("steady", {}).items():
        log.info(f"{NAME}: eps={e} median point after them: cpu {v['cpu_s']:.2f}s, newton {v['newton']:.0f}, "
                 f"gmres {v['krylov']:.0f}, check {v['check_cpu_s']:.2f}s; "
                 f"cpu per unit of v {v['cpu_s_per_v']:.0f}s")
    for name, v in info.get("exponent_spread", {}).items():
        log.info(f"{NAME}: cpu exponent over the {v['repeats']} repeats, {name} window: min {v['min']:.2f}, "
                 f"median {v['median']:.2f}, max {v['max']:.2f}")
    for key in ("exponents", "exponents_steady", "exponents_all_warm"):
        if key in info:
            log.info(f"{NAME}: {key} in the node count: " +
                     ", ".join(f"{q} {x:.2f}" for q, x in info[key].items()))
    return 0 if all(str(r.get("converged")) in ("True", "true") for r in rows) and rows else 1
