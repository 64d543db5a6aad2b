"""Benchmark of the large-3D path: time, memory, Newton and CG counts against n (issue 6).

The ``torus-table1-3d`` scene (exact constraints, tol 1e-8, cold torus start) on

* ``spectral`` grids with the newton-krylov backend,
* ``fd`` grids with the newton-krylov backend (the FD Laplacian applied by FFT),
* ``fem-p1`` periodic tetrahedral meshes (lumped) with the newton-krylov backend (sparse matrices,
  pyamg preconditioner), and
* ``fd`` with the IPOPT backend (exact Hessian, MUMPS) where it fits (n <= 16; ~24 s per iteration
  at 32^3 was measured for the core).

Every case runs in a fresh process (spawn), so ``peak_rss_mb`` is that solve's own peak resident
memory (interpreter and libraries included, ~115 MB). The machine is shared, so timings are noisy:
each case is repeated ``repeats`` times and the median wall time is written with the minimum, and
the solver's own CPU time (``solve_cpu_s``, newton-krylov only) shows what an idle core would take.
``main(out, quick)`` writes ``bench_3d.csv``; quick = a reduced set.
"""

from __future__ import annotations

import csv
import multiprocessing as mp
import statistics
from pathlib import Path


def _case(kind: str, n: int, backend: str) -> dict:
    import os
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import resource
    import time

    from vesicle_opt import scene
    from vesicle_opt.cli import resolve_scene
    from vesicle_opt.solve import solve
    sc = scene.load(resolve_scene("torus-table1-3d"),
                    [f"mesh.kind='{kind}'", f"mesh.n={n}", f"solver.backend='{backend}'"])
    t0 = time.perf_counter()
    r = solve(sc)
    total = time.perf_counter() - t0
    return {"kind": kind, "n": n, "backend": backend, "n_nodes": r.n_nodes, "energy": r.energy,
            "status": r.status, "converged": r.converged, "kkt_residual": r.kkt_residual,
            "kkt_dual": r.extra.get("kkt_dual"), "newton": r.iterations,
            "cg": r.extra.get("cg_iterations"), "levels": r.extra.get("levels"),
            "solve_wall_s": r.wall_time_s, "solve_cpu_s": r.extra.get("cpu_time_s"), "total_wall_s": total,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def cases(quick: bool) -> list[tuple[str, int, str]]:
    if quick:
        return [("spectral", 16, "newton-krylov"), ("spectral", 32, "newton-krylov"),
                ("fd", 16, "newton-krylov"), ("fd", 32, "newton-krylov"), ("fem-p1", 16, "newton-krylov"),
                ("fd", 12, "ipopt")]
    out = [("spectral", n, "newton-krylov") for n in (16, 24, 32, 48, 64, 96)]
    out += [("fd", n, "newton-krylov") for n in (16, 24, 32, 48, 64)]
    out += [("fem-p1", n, "newton-krylov") for n in (16, 24)]
    out += [("fd", n, "ipopt") for n in (12, 16)]
    return out


def main(out: Path, quick: bool = False, repeats: int | None = None) -> int:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    repeats = repeats or (1 if quick else 3)
    ctx = mp.get_context("spawn")
    rows = []
    for kind, n, backend in cases(quick):
        reps = 1 if backend == "ipopt" or kind == "fem-p1" else repeats
        runs = []
        for _ in range(reps):
            with ctx.Pool(1, maxtasksperchild=1) as pool:
                runs.append(pool.apply(_case, (kind, n, backend)))
        row = dict(runs[-1])
        walls = [r["total_wall_s"] for r in runs]
        row.update({"repeats": reps, "total_wall_median_s": statistics.median(walls),
                    "total_wall_min_s": min(walls), "peak_rss_mb": max(r["peak_rss_mb"] for r in runs)})
        rows.append(row)
        print(f"bench_3d: {kind:8s} n={n:3d} {backend:13s} E={row['energy']:.6f} conv={row['converged']} "
              f"newton={row['newton']} cg={row['cg']} wall(median of {reps})={row['total_wall_median_s']:.2f}s "
              f"rss={row['peak_rss_mb']:.0f}MB", flush=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(out / "bench_3d.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    return 0


if __name__ == "__main__":
    import sys
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/bench_3d"), quick="--quick" in sys.argv))
