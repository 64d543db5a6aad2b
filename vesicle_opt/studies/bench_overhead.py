"""The cost of vesicle_opt's abstractions: the same FD ellipse problem solved by the bare
hand-written CasADi model (``bare_casadi.py``) and by ``build_nlp`` + ``solve``, interleaved,
``repeats`` times each in fresh processes; medians and their ratio per mesh (issue target: the
toolkit no slower than the bare model, derivative evaluation <= 25% of the solve).

    vesicle-opt study bench_overhead --out DIR [--quick]
"""

from __future__ import annotations

import logging
import statistics
import sys
from pathlib import Path

from vesicle_opt import scene
from vesicle_opt.api import solve
from vesicle_opt.studies.bare_casadi import bare_solve
from vesicle_opt.studies.runner import in_fresh_process, run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

EXTRA = ["repeat", "derivative_fraction", "median_wall_time_s", "ratio_to_bare"]


def _one(case: dict) -> dict:
    if case["method"] == "bare":
        r = bare_solve(case["n"])
        return {**case, "scene": "ellipse-2d", "wall_time_s": r["wall_time_s"],
                "iterations": r["iterations"], "energy": r["energy"], "status": r["status"]}
    sc = scene.load("ellipse-2d", [f"mesh.n={case['n']}", "solver.second_order=false"])
    r = solve(sc)
    return {**case, "scene": "ellipse-2d", "wall_time_s": r.wall_time_s, "iterations": r.iterations,
            "energy": r.energy, "status": r.status,
            "derivative_fraction": r.derivative_time_s / r.wall_time_s}


def case_rows(case: dict) -> list[dict]:
    """Interleave bare and toolkit solves, each in its own fresh process."""
    rows = [in_fresh_process(_one, {"method": method, "n": case["n"], "repeat": rep})
            for rep in range(case["repeats"]) for method in ("bare", "toolkit")]
    med = {m: statistics.median(r["wall_time_s"] for r in rows if r["method"] == m) for m in ("bare", "toolkit")}
    for r in rows:
        r["median_wall_time_s"] = med[r["method"]]
        r["ratio_to_bare"] = med[r["method"]] / med["bare"]
    return rows


def main(out: Path, quick: bool = False) -> int:
    cases = [{"case": f"n={n}", "n": n, "repeats": 2 if quick else 3} for n in ((64,) if quick else (128, 256))]
    rows = run_cases("bench_overhead", cases, case_rows, Path(out) / "bench_overhead.csv",
                     workers=1, extra_columns=EXTRA)
    for r in rows:
        if r["method"] == "toolkit" and r["repeat"] == "0":
            log.info(f"n={r['n']}: toolkit/bare median wall time = {float(r['ratio_to_bare']):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "results"), quick="--quick" in sys.argv))
