"""The cost of vesicle_opt's abstractions: the same FD ellipse problem solved by the bare
hand-written CasADi model (``bare_casadi.py``) and by ``build_nlp`` + ``solve``, interleaved,
``repeats`` times each in fresh processes; medians and their ratio per mesh (issue target: the
toolkit no slower than the bare model, derivative evaluation <= 25% of the solve).

And what a user waits for (issue 14): the whole ``vesicle-opt solve`` process of the spectral
Table-1 torus (64^3; --quick 32^3) against the solve inside it, each run a fresh interpreter
(``subprocess``), ``bare`` (``solver.second_order = false``) and ``default`` (the check on)
interleaved, ``repeats`` each. A row per run: ``whole_process_s`` (start to exit, outputs
written), ``solve_s`` (the summary's ``wall_time_s``), ``certificate_s``, ``whole_over_solve``
(the same run's), ``whole_over_bare_solve`` (over the median bare-run solve: the issue's ratio
for the default run) and their medians per mode, ``load_average`` at the run's start (the
machine is shared: the ratios, measured side by side, mean more than the times).

    vesicle-opt study bench_overhead --out DIR [--quick]
"""

from __future__ import annotations

import json
import logging
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from vesicle_opt import scene
from vesicle_opt.api import solve
from vesicle_opt.studies.bare_casadi import bare_solve
from vesicle_opt.studies.runner import in_fresh_process, run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

EXTRA = ["repeat", "derivative_fraction", "median_wall_time_s", "ratio_to_bare", "mode", "load_average",
         "whole_process_s", "solve_s", "certificate_s", "whole_over_solve", "whole_over_bare_solve",
         "median_whole_process_s", "median_solve_s", "median_whole_over_solve", "median_whole_over_bare_solve"]
CLI_SCENE = "torus-table1-3d"


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


def cli_run(n: int, mode: str, repeat: int) -> dict:
    """One ``vesicle-opt solve`` of the spectral torus in a fresh interpreter (module docstring)."""
    args = [sys.executable, "-m", "vesicle_opt", "solve", CLI_SCENE, "--set", "mesh.kind='spectral'",
            "--set", f"mesh.n={n}", "-q"]
    if mode == "bare":
        args += ["--set", "solver.second_order=false"]
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        done = subprocess.run(args + ["--out", tmp], capture_output=True, text=True)
        whole = time.perf_counter() - t0
        summary = json.loads((Path(tmp) / "summary.json").read_text()) if done.returncode in (0, 1) else {}
    if done.returncode != 0:
        return {"scene": CLI_SCENE, "method": "cli", "mode": mode, "n": n, "repeat": repeat,
                "status": f"exit {done.returncode}: {done.stderr.strip()[-150:]}"}
    return {"scene": CLI_SCENE, "method": "cli", "mode": mode, "n": n, "repeat": repeat,
            "load_average": round(load, 2), "whole_process_s": whole, "solve_s": summary["wall_time_s"],
            "wall_time_s": whole, "certificate_s": summary.get("second_order_time_s"),
            "whole_over_solve": whole / summary["wall_time_s"], "energy": summary["energy"],
            "status": summary["status"], "converged": summary["converged"], "iterations": summary["iterations"]}


def cli_rows(case: dict) -> list[dict]:
    """bare and default CLI runs interleaved (bare, default, bare, ...), with the medians."""
    rows = [cli_run(case["n"], mode, rep) for rep in range(case["repeats"]) for mode in ("bare", "default")]
    ok = [r for r in rows if "whole_process_s" in r]
    bare_solve = statistics.median(r["solve_s"] for r in ok if r["mode"] == "bare") if ok else float("nan")
    for r in ok:
        r["whole_over_bare_solve"] = r["whole_process_s"] / bare_solve
    for mode in ("bare", "default"):
        mine = [r for r in ok if r["mode"] == mode]
        if not mine:
            continue
        med = {k: statistics.median(r[k] for r in mine)
               for k in ("whole_process_s", "solve_s", "whole_over_solve", "whole_over_bare_solve")}
        for r in mine:
            r.update({f"median_{k}": v for k, v in med.items()})
        log.info(f"bench_overhead: CLI {CLI_SCENE} spectral {case['n']}^3 {mode}: whole process "
                 f"{med['whole_process_s']:.2f} s, solve {med['solve_s']:.2f} s, whole / solve "
                 f"{med['whole_over_solve']:.2f}, whole / bare solve {med['whole_over_bare_solve']:.2f} "
                 f"(medians of {len(mine)}, load {mine[0]['load_average']})")
    return rows


def _rows(case: dict) -> list[dict]:
    return cli_rows(case) if case.get("kind") == "cli" else case_rows(case)


def main(out: Path, quick: bool = False) -> int:
    repeats = 2 if quick else 3
    cases = [{"case": f"n={n}", "n": n, "repeats": repeats} for n in ((64,) if quick else (128, 256))]
    cases.append({"case": f"cli spectral n={32 if quick else 64}", "kind": "cli", "n": 32 if quick else 64,
                  "repeats": repeats})
    rows = run_cases("bench_overhead", cases, _rows, Path(out) / "bench_overhead.csv",
                     workers=1, extra_columns=EXTRA)
    for r in rows:
        if r["method"] == "toolkit" and r["repeat"] == "0":
            log.info(f"n={r['n']}: toolkit/bare median wall time = {float(r['ratio_to_bare']):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "results"), quick="--quick" in sys.argv))
