"""Every ``solver.method`` in its defaults on every bundled scene: exit code, outcome, whole-process
wall time against the ``exact`` run of the same scene (issue 25's targets: every run exits 0;
``continuation`` and ``augmented`` cost at most 2x ``exact``; continuation's extrapolated energy
within 1e-8 of exact's).

Each run is the whole ``vesicle-opt solve SCENE --set solver.method=...`` process in a fresh
interpreter (``subprocess``: start-up, NLP build, solve, checks, outputs written), timed from start
to exit. The methods of a scene are interleaved (``repeats`` rounds of exact, penalty, continuation,
augmented, the order rotated by one each round so that no method always runs first), so a load
change on the shared machine falls on all of them alike; ``wall_median`` is the median of a
method's runs, ``wall_runs`` the runs themselves and ``load_runs`` the 1-minute load average at each
run's start (the times mean little without it; the ratios, measured side by side, mean more);
``cpu_median``, ``cpu_runs`` the same for the process's CPU seconds (user + system, its children's
included: ``resource.getrusage``), which a load change moves far less than the wall.

One row per (scene, method):

* ``exit`` the worst (largest) exit code of its runs (``exits``: all), ``outcome`` the summary's;
* ``energy`` the reported energy (a penalty stage's is biased by O(1/M), Theorem 3.2),
  ``energy_extrapolated`` continuation's value at M = inf (``model.extrapolation``: multiplier-corrected;
  ``energy_extrapolated_plain`` the plain Richardson of the stage energies), ``polish_energy`` its augmented
  polish (exact constraints); ``compared`` names the value ``rel_diff_vs_exact`` uses:
  energy_extrapolated for continuation, energy otherwise;
* ``certified_energy``: the energy of the run's point with exact constraints (exact and augmented:
  energy; continuation: polish_energy; penalty: none), and ``same_point``: whether it equals exact's
  to ``SAME_POINT_RTOL``. A method may end on another KKT point than exact from the same start (the
  problem is non-convex): its cost is then the cost of another answer. The ratio is still reported
  (what the user waits for a certified answer from that scene) and ``same_point`` says so; the 2x
  target is judged on the rows with ``same_point`` (``within_target``: empty where not comparable).

**Like for like where exact ends on a saddle** (``ESCAPE_SCENES``: the Table-1 torus, whose ``exact``
run ends on a saddle, E 330.5325, while continuation and augmented end on a lower certified minimum,
330.1976): the method ``exact_escape`` (``studies._escape``) is ``exact`` taken on to a minimum as a
user of ``exact`` would: while the certified result is a second-order saddle, push along the check's
least eigenvector and solve exact again, all in one process, timed whole. It is fair because it is the
cost of the same answer by the exact method: same scene, same start, same certificate and second-order
check at every solve, and it ends on the point the penalty methods reach (``same_point``, checked,
not assumed); it favours exact if anything (one interpreter start and no ``scene.resolved.toml`` for
two solves). A continuation / augmented row whose point is not exact's but is ``exact_escape``'s is
judged against it: ``reference`` names the run the 2x is judged against, ``ratio_vs_reference``
its ratio (of walls, as the target; ``ratio_cpu_vs_reference`` of CPU seconds beside it), and
``rel_diff_vs_reference`` the ``compared`` value's relative difference from its energy.
``exact_escape`` rows report ``escape_rounds`` (pushes made; 0 where exact was a minimum).

``--quick``: the scenes with a 2D mesh (``Scene.domain`` of two pairs: the 2D scenes and the
axisymmetric meridian), one round. Full: every bundled scene, three rounds (``repeats=`` overrides;
``scenes=``, ``methods=``, ``escape_scenes=`` and ``timeout_s=`` select, for the API).

    vesicle-opt study bench_methods --out DIR [--quick]
"""

from __future__ import annotations

import json
import logging
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

from vesicle_opt.scene import bundled, load
from vesicle_opt.scene.ranges import CHOICES
from vesicle_opt.studies._common import human
from vesicle_opt.studies.runner import run_into
from vesicle_opt.studies._common import num as _num

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

NAME = "bench_methods"
METHODS = CHOICES["solver.method"]  # exact first: the reference of every ratio
TARGET_RATIO = 2.0  # issue 25: continuation and augmented at most 2x exact, whole process
TARGET_EXTRAPOLATION = 1e-8  # issue 25: continuation's extrapolated energy, relative to exact's
# two certified points of the same scene are "the same" when their energies agree to this: the
# certificate (kkt_dual <= 100 tol at tol 1e-8) leaves the energy ~1e-8 off (augmented against exact
# on ellipse-2d: 2e-8, measured); distinct KKT points of the bundled scenes differ by >= 1e-4
SAME_POINT_RTOL = 1e-6
ESCAPE = "exact_escape"  # exact taken on from a saddle to a minimum (module docstring, studies._escape)
ESCAPE_SCENES = ("torus-table1-3d",)  # the bundled scenes whose exact run ends on a saddle (measured)
TIMEOUT_S = 3600.0  # one run's limit (a run past it is recorded with exit "timeout")
EXTRA = ["exit", "exits", "outcome", "wall_median", "wall_runs", "load_runs", "cpu_median", "cpu_runs",
         "ratio_cpu_vs_exact", "energy_extrapolated", "energy_extrapolated_plain", "polish_energy", "compared",
         "rel_diff_vs_exact", "ratio_vs_exact", "certified_energy", "same_point", "within_target", "reference",
         "ratio_vs_reference", "ratio_cpu_vs_reference", "rel_diff_vs_reference", "escape_rounds", "escape_energies",
         "repeats", "second_order", "backend", "reason"]


def scene_dims() -> dict[str, int]:
    """Bundled scene name -> its mesh's dimension (the box's pairs: 2 on the axisymmetric meridian)."""
    out = {}
    for name in bundled.names():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # near-bound warnings: the scenes' documented state
            out[name] = load(name).domain.dim
    return out


def one_run(scene: str, method: str, timeout_s: float = TIMEOUT_S) -> dict:
    """One whole ``vesicle-opt solve`` process (``ESCAPE``: ``studies._escape``'s): exit code, wall
    seconds, load at start, the summary."""
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        if method == ESCAPE:
            args = [sys.executable, "-m", "vesicle_opt.studies._escape", scene, tmp]
        else:
            args = [sys.executable, "-m", "vesicle_opt", "solve", scene, "--set", f"solver.method='{method}'", "-q",
                    "--out", tmp]
        t0, c0 = time.perf_counter(), _child_cpu()
        try:
            done = subprocess.run(args, capture_output=True, text=True, timeout=timeout_s)
            code, err = done.returncode, done.stderr
        except subprocess.TimeoutExpired:
            code, err = "timeout", f"past {timeout_s:g} s"
        wall, cpu = time.perf_counter() - t0, _child_cpu() - c0
        path = Path(tmp) / "summary.json"
        summary = json.loads(path.read_text()) if path.is_file() else {}
    return {"exit": code, "wall": wall, "cpu": cpu, "load": load, "summary": summary,
            "stderr": err.strip().splitlines()[-1][:200] if err.strip() else ""}


def _child_cpu() -> float:
    """CPU seconds (user + system) of this process's waited-for children so far."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def interleaved(scene: str, methods, repeats: int, run=one_run, **kw) -> dict[str, list[dict]]:
    """``repeats`` rounds over ``methods``, each round's order rotated by one (module docstring)."""
    runs: dict[str, list[dict]] = {m: [] for m in methods}
    for k in range(repeats):
        order = list(methods[k % len(methods):]) + list(methods[:k % len(methods)])
        for m in order:
            r = run(scene, m, **kw)
            runs[m].append(r)
            log.info(f"{NAME}: {scene} {m} round {k + 1}/{repeats}: exit {r['exit']}, "
                     f"{r['summary'].get('outcome', '-')}, {r['wall']:.2f} s (load {r['load']:.2f})")
    return runs


def _worst(codes: list) -> object:
    """The worst exit code: a timeout, else the largest."""
    return "timeout" if "timeout" in codes else max(codes)


def rows_of(scene: str, runs: dict[str, list[dict]]) -> list[dict]:
    """One row per method from its runs (module docstring); the ratios and differences are against
    the scene's ``exact`` runs when they are among them."""
    med = {m: statistics.median(r["wall"] for r in rs) for m, rs in runs.items() if rs}
    cpu = {m: statistics.median(r.get("cpu", math.nan) for r in rs) for m, rs in runs.items() if rs}
    last = {m: rs[-1]["summary"] for m, rs in runs.items() if rs}
    def energy_of(m):  # a reference's energy, where all its runs exited 0
        return _num(last[m].get("energy")) if m in runs and all(r["exit"] == 0 for r in runs[m]) else math.nan

    def same_as(cert, ref):
        return abs(cert - ref) <= SAME_POINT_RTOL * abs(ref) if math.isfinite(cert) and math.isfinite(ref) else None

    e_ref, e_esc = energy_of("exact"), energy_of(ESCAPE)
    e_ref_of = {"exact": e_ref, ESCAPE: e_esc}
    rows = []
    for m, rs in runs.items():
        s = last[m]
        compared = "energy_extrapolated" if m == "continuation" else "energy"
        value = _num(s.get(compared))
        certified = {"exact": s.get("energy"), "augmented": s.get("energy"), ESCAPE: s.get("energy"),
                     "continuation": s.get("polish_energy")}.get(m) if s.get("converged") else None
        cert = _num(certified)
        same = same_as(cert, e_ref)
        ratio = med[m] / med["exact"] if "exact" in med else math.nan
        codes = [r["exit"] for r in rs]
        within, reference, ratio_ref = None, None, math.nan
        if m in ("continuation", "augmented"):  # judged against the exact run that ends on its point
            if same:
                reference, ratio_ref = "exact", ratio
            elif same_as(cert, e_esc) and ESCAPE in med:
                reference, ratio_ref = ESCAPE, med[m] / med[ESCAPE]
        if reference is not None:
            within = ratio_ref <= TARGET_RATIO and all(c == 0 for c in codes)
        rows.append({"scene": scene, "method": m, "exit": _worst(codes), "exits": " ".join(map(str, codes)),
                     "outcome": s.get("outcome", "no summary"), "status": s.get("status"),
                     "reason": s.get("reason") or (rs[-1]["stderr"] if rs[-1]["exit"] != 0 else None),
                     "wall_median": med[m], "wall_time_s": med[m],
                     "wall_runs": " ".join(f"{r['wall']:.3f}" for r in rs),
                     "cpu_median": cpu[m], "cpu_runs": " ".join(f"{r.get('cpu', math.nan):.3f}" for r in rs),
                     "ratio_cpu_vs_exact": cpu[m] / cpu["exact"] if "exact" in cpu else math.nan,
                     "load_runs": " ".join(f"{r['load']:.2f}" for r in rs), "repeats": len(rs),
                     "energy": s.get("energy"), "energy_extrapolated": s.get("energy_extrapolated"),
                     "energy_extrapolated_plain": s.get("energy_extrapolated_plain"),
                     "polish_energy": s.get("polish_energy"), "compared": compared,
                     "rel_diff_vs_exact": abs(value - e_ref) / abs(e_ref) if math.isfinite(value) else math.nan,
                     "ratio_vs_exact": ratio, "certified_energy": certified, "same_point": same,
                     "within_target": within, "reference": reference, "ratio_vs_reference": ratio_ref,
                     "ratio_cpu_vs_reference": cpu[m] / cpu[reference] if reference else math.nan,
                     "rel_diff_vs_reference": abs(value - e_ref_of[reference]) / abs(e_ref_of[reference])
                     if reference and math.isfinite(value) else math.nan,
                     "escape_rounds": s.get("escape_rounds"), "escape_energies": s.get("escape_energies"),
                     "M": s.get("M"), "iterations": s.get("iterations"),
                     "volume_residual": s.get("volume_residual"), "area_residual": s.get("area_residual"),
                     "lambda_volume": s.get("lambda_volume"), "lambda_area": s.get("lambda_area"),
                     "second_order": s.get("second_order"), "backend": s.get("backend")})
    return rows


def case_rows(case: dict) -> list[dict]:
    runs = interleaved(case["scene"], case["methods"], case["repeats"], timeout_s=case["timeout_s"])
    return rows_of(case["scene"], runs)


def cases(quick: bool, scenes=None, methods=None, repeats=None, timeout_s=None, escape_scenes=None) -> list[dict]:
    """One case per scene (its methods interleaved inside it, so the CSV resumes scene by scene);
    ``exact_escape`` joins them on ``escape_scenes`` (default ``ESCAPE_SCENES``) where exact runs."""
    if scenes is None:
        dims = scene_dims()
        scenes = [s for s in dims if dims[s] == 2] if quick else list(dims)
    methods = tuple(methods or METHODS)
    escape = ESCAPE_SCENES if escape_scenes is None else tuple(escape_scenes)
    repeats = int(repeats or (1 if quick else 3))
    return [{"case": s, "scene": s, "repeats": repeats, "timeout_s": float(timeout_s or TIMEOUT_S),
             "methods": methods + ((ESCAPE,) if s in escape and "exact" in methods and ESCAPE not in methods else ())}
            for s in scenes]


def main(out, quick: bool = False, scenes=None, methods=None, repeats=None, timeout_s=None,
         executor=None, escape_scenes=None) -> int:
    """Rows per scene as it finishes (``run_into``: resumable). Returns 0 when every run exited 0
    and every comparable continuation / augmented row is within the 2x target, 1 otherwise."""
    case_list = cases(quick, scenes, methods, repeats, timeout_s, escape_scenes)
    out, rows, good = run_into(NAME, case_list, case_rows, out, executor=executor, workers=1, extra_columns=EXTRA)
    for r in good:
        log.info(f"{NAME}: {r['scene']} {r['method']}: exit {r['exit']}, {r['outcome']}, wall "
                 f"{_num(r['wall_median']):.2f} s (runs {r['wall_runs']}; load {r['load_runs']}), CPU "
                 f"{_num(r['cpu_median']):.2f} s, "
                 f"{_num(r['ratio_vs_exact']):.2f}x exact, {r['compared']} {human(_num(r.get(r['compared'])))} "
                 f"(rel. diff {human(_num(r['rel_diff_vs_exact']))}), same point {r['same_point'] or '-'}"
                 + (f", {_num(r['ratio_vs_reference']):.2f}x {r['reference']}" if r.get("reference") else ""))
    failed = [r for r in rows if str(r.get("exit")) != "0" or r.get("within_target") == "False"]
    return 0 if rows and len(good) == len(rows) and not failed else 1


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/bench_methods"), quick="--quick" in sys.argv))
