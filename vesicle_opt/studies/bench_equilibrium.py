"""Benchmark of the exact-constraint IPOPT solve: iterations, wall time, derivative-evaluation
time, Hessian nonzeros per row and peak memory against mesh size, for FD, FEM-lumped and
FEM-consistent in 2D (ellipse-2d, 32^2 ... 512^2) and 3D (sphere-3d, 16^3 ... 32^3), beside the bare
hand-written CasADi model of ``bare_casadi.py`` (2D FD). Each case runs in a fresh process so its
peak memory (ru_maxrss) is its own. Rows are appended as they finish; a re-run resumes.

    vesicle-opt study bench_equilibrium --out results [--quick]
"""

from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

from vesicle_opt import scene
from vesicle_opt.api import solve
from vesicle_opt.nlp import build_nlp
from vesicle_opt.studies.bare_casadi import bare_solve
from vesicle_opt.studies.runner import process_pool, run_cases
from vesicle_opt.verify import second_order

EXTRA = ["dim", "discretisation", "n_nodes", "derivative_time_s", "derivative_fraction",
         "hessian_nnz_per_row", "peak_memory_mb", "converged", "second_order", "second_order_time_s",
         "second_order_peak_memory_mb"]


def cases(quick: bool) -> list[dict]:
    out = []
    ns2 = [32, 64] if quick else [32, 64, 128, 256, 512]
    def add(scene, dim, disc, n):
        out.append({"case": f"{scene} {disc} {n}", "scene": scene, "dim": dim,
                    "discretisation": disc, "n": n})
    for n in ns2:
        add("bare-casadi", 2, "fd", n)
        for disc in ("fd", "fem-lumped", "fem-consistent"):
            if disc == "fem-consistent" and n > 128:
                continue  # crawls along the soft rotation mode (README): 128 iterations at 64^2
            add("ellipse-2d", 2, disc, n)
    for n in ([8] if quick else [12, 16, 20, 24, 32]):
        for disc in ("fd", "fem-consistent") if n <= 16 else ("fd",):
            add("sphere-3d", 3, disc, n)
    return out


def run_case(case: dict) -> dict:
    if case.get("scene", case["case"]) == "bare-casadi":
        r = bare_solve(case["n"])
        row = {**case, "n_nodes": case["n"] ** 2, "iterations": r["iterations"],
               "wall_time_s": r["wall_time_s"], "energy": r["energy"], "status": r["status"],
               "converged": r["status"] == "Solve_Succeeded",
               "peak_memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    else:
        kind = {"fd": ["mesh.kind='fd'"], "fem-lumped": ["mesh.kind='fem-p1'", "mesh.mass='lumped'"],
                "fem-consistent": ["mesh.kind='fem-p1'", "mesh.mass='consistent'"]}[case["discretisation"]]
        sc = scene.load(case.get("scene", case["case"]),
                        [f"mesh.n={case['n']}", *kind, "solver.second_order=false"])
        nlp = build_nlp(sc)
        r = solve(nlp)
        row = {**case, "n_nodes": r.n_nodes, "iterations": r.iterations, "wall_time_s": r.wall_time_s,
               "derivative_time_s": r.derivative_time_s,
               "derivative_fraction": r.derivative_time_s / r.wall_time_s,
               "hessian_nnz_per_row": r.hessian_nnz_per_row, "energy": r.energy, "status": r.status,
               "converged": r.converged}
        row["peak_memory_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        if r.converged:  # the second-order check, timed on its own (one sparse LU, SuperLU)
            t0 = time.perf_counter()
            row["second_order"] = second_order.check(nlp, r).verdict
            row["second_order_time_s"] = time.perf_counter() - t0
            row["second_order_peak_memory_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    row["method"] = "exact"
    return row


def case_rows(case: dict) -> list[dict]:
    return [run_case(case)]


def main(out: Path, quick: bool = False) -> int:
    # a fresh process per case, so that each peak memory (ru_maxrss) is the case's own
    pool = process_pool(1, max_tasks_per_child=1)
    with pool:
        rows = run_cases("bench_equilibrium", cases(quick), case_rows, Path(out) / "bench_equilibrium.csv",
                         executor=pool, extra_columns=EXTRA)
    _plot(rows, Path(out) / "bench_equilibrium.png")
    return 0


def _plot(rows: list[dict], path: Path) -> None:
    # local, not at module level: every case's fresh process imports this module, and pyplot there
    # would add ~30 MB to the peak memory (ru_maxrss) the case measures
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    groups: dict[tuple, list] = {}
    for r in rows:
        if r["wall_time_s"] and r.get("n_nodes"):
            groups.setdefault((r["scene"], r["discretisation"]), []).append(
                (int(r["n_nodes"]), float(r["wall_time_s"])))
    for (case, disc), pts in sorted(groups.items()):
        pts.sort()
        ax.loglog(*zip(*pts), "o-", label=f"{case} {disc}")
    ax.set_xlabel("nodes")
    ax.set_ylabel("IPOPT wall time [s]")
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "results"), quick="--quick" in sys.argv)
