"""Benchmark of the large-3D path: time, memory, Newton and CG counts against n (issue 6).

The ``torus-table1-3d`` scene (exact constraints, tol 1e-8, cold torus start, no second-order check:
``bench_certificate`` measures that) on

* ``spectral`` grids with the newton-krylov backend,
* ``fd`` grids with the newton-krylov backend (the FD Laplacian applied by FFT),
* ``fem-p1`` periodic tetrahedral meshes (lumped) with the newton-krylov backend (sparse matrices;
  S^{-1} of the preconditioner by a Chebyshev polynomial, ``precond``) up to 64^3 (measured alone:
  32^3 10 s, 40^3 17 s, 48^3 40 s, 64^3 111 s and 2.4 GB; the sparse LU before needed 300 s at
  32^3), and
* ``fd`` with the IPOPT backend (exact Hessian, MUMPS) where it fits (n <= 16; ~24 s per iteration
  at 32^3 was measured for the core).

Every case runs in a fresh process (spawn), so ``peak_rss_mb`` is that solve's own peak resident
memory (interpreter and libraries included, ~115 MB). The machine is shared, so timings are noisy:
each case is repeated ``repeats`` times and the median wall time is written with the minimum, and
the solver's own CPU time (``solve_cpu_s``, newton-krylov only) shows what an idle core would take.
On Fourier grids each row also has the solve's FFT count (``mesh.spectral.FourierGrid.transforms``),
one transform's time (``transform_ms``: the mean of the solve's own transforms,
``FourierGrid.transform_seconds``; ``transform_alone_ms``: ``bench_certificate.transform_time``
after the solve), the FFT floor (count x transform), the FFT share of the solve and the solve's
ratio to its floor, for the FFT library the row ran (``fft``; ``scipy|pyfftw`` cases interleave both).
``main(out, quick)`` writes ``bench_3d.csv``; quick = a reduced set.
"""

from __future__ import annotations

import logging
import os
import resource
import statistics
import sys
import time
from pathlib import Path

from vesicle_opt import scene
from vesicle_opt.api import solve
from vesicle_opt.mesh.spectral import FourierGrid, fft_available, fft_library, resolve_fft
from vesicle_opt.studies.bench_certificate import transform_time
from vesicle_opt.studies.runner import in_fresh_process, run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)


def _case(kind: str, n: int, backend: str, fft: str = "auto") -> dict:
    sc = scene.load("torus-table1-3d",
                    [f"mesh.kind='{kind}'", f"mesh.n={n}", f"solver.backend='{backend}'", f"solver.fft='{fft}'",
                     "solver.second_order=false"])  # the solve alone: the check has bench_certificate
    f0, s0 = FourierGrid.transforms, FourierGrid.transform_seconds
    t0 = time.perf_counter()
    r = solve(sc)
    total = time.perf_counter() - t0
    ffts = FourierGrid.transforms - f0
    # one transform's time: the mean of the solve's own transforms, timed where they ran (a
    # transform timed after the solve, on a loaded machine, put the floor above the solve itself)
    one = (FourierGrid.transform_seconds - s0) / ffts if ffts else float("nan")  # NaN on meshes
    with fft_library(fft):
        alone = transform_time(r.disc)
    floor = ffts * one
    return {"fft_count": ffts, "transform_ms": 1e3 * one, "transform_alone_ms": 1e3 * alone, "fft_floor_s": floor,
            "fft_share": floor / r.wall_time_s, "solve_over_fft_floor": r.wall_time_s / floor if floor else float("nan"),
            "kind": kind, "n": n, "backend": backend, "fft": resolve_fft(fft), "n_nodes": r.n_nodes, "energy": r.energy,
            "status": r.status, "converged": r.converged, "kkt_residual": r.kkt_residual,
            "kkt_dual": r.extra.get("kkt_dual"), "newton": r.iterations,
            "cg": r.extra.get("cg_iterations"), "levels": r.extra.get("levels"),
            "solve_wall_s": r.wall_time_s, "solve_cpu_s": r.extra.get("cpu_time_s"), "total_wall_s": total,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def cases(quick: bool) -> list[tuple]:
    """(kind, n, backend[, fft]): fft = the FFT library (``solver.fft``, default auto; the row
    names the one that ran)."""
    if quick:
        return [("spectral", 16, "newton-krylov"), ("spectral", 32, "newton-krylov"),
                ("fd", 16, "newton-krylov"), ("fd", 32, "newton-krylov"), ("fem-p1", 16, "newton-krylov"),
                ("fd", 12, "ipopt")]
    out = [("spectral", n, "newton-krylov") for n in (16, 24, 32, 48, 64, 96)]
    if fft_available("pyfftw"):  # the optional FFT against scipy's, interleaved (issue 14)
        out += [("spectral", n, "newton-krylov", "scipy|pyfftw") for n in (64, 96)]
    out += [("fd", n, "newton-krylov") for n in (16, 24, 32, 48, 64)]
    out += [("fem-p1", n, "newton-krylov") for n in (16, 24, 32, 40, 48, 64)]
    out += [("fd", n, "ipopt") for n in (12, 16)]
    return out


EXTRA = ["fft", "fft_count", "transform_ms", "transform_alone_ms", "fft_floor_s", "fft_share", "solve_over_fft_floor", "kind", "backend", "n_nodes", "converged", "kkt_residual", "kkt_dual", "newton", "cg",
         "levels", "solve_wall_s", "solve_cpu_s", "total_wall_s", "peak_rss_mb", "repeats",
         "total_wall_median_s", "total_wall_min_s", "solve_wall_median_s", "solve_over_fft_floor_median",
         "solve_ratio_to_scipy"]


def _row(case: dict, runs: list[dict]) -> dict:
    row = dict(runs[-1])
    walls = [r["total_wall_s"] for r in runs]
    row.update({"scene": "torus-table1-3d", "method": "exact", "iterations": row["newton"],
                "wall_time_s": statistics.median(walls), "repeats": case["repeats"],
                "total_wall_median_s": statistics.median(walls), "total_wall_min_s": min(walls),
                "solve_wall_median_s": statistics.median(r["solve_wall_s"] for r in runs),
                "solve_over_fft_floor_median": statistics.median(r["solve_over_fft_floor"] for r in runs),
                "peak_rss_mb": max(r["peak_rss_mb"] for r in runs)})
    log.info(f"bench_3d: {row['kind']:8s} n={row['n']:3d} {row['backend']:13s} fft={row['fft']} "
             f"E={row['energy']:.6f} conv={row['converged']} newton={row['newton']} cg={row['cg']} "
             f"wall(median of {case['repeats']})={row['total_wall_median_s']:.2f}s "
             f"solve/floor={row['solve_over_fft_floor_median']:.2f} rss={row['peak_rss_mb']:.0f}MB")
    return row


def case_rows(case: dict) -> list[dict]:
    """``repeats`` fresh-process runs of one (kind, n, backend); one row with the median. A case whose
    fft is "scipy|pyfftw" runs both libraries interleaved (scipy, pyfftw, scipy, ...) and gives a row
    each, the pyfftw row with ``solve_ratio_to_scipy`` (median of the per-pair solve-time ratios)."""
    # one BLAS thread in the fresh processes: set here, in the parent, because a child has loaded
    # numpy (importing this module to unpickle _case) before _case runs
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    libraries = case.get("fft", "auto").split("|")
    runs = {lib: [] for lib in libraries}
    for _ in range(case["repeats"]):
        for lib in libraries:
            runs[lib].append(in_fresh_process(_case, case["kind"], case["n"], case["backend"], lib))
    rows = [_row(case, runs[lib]) for lib in libraries]
    if len(libraries) == 2:
        ratios = [b["solve_wall_s"] / a["solve_wall_s"] for a, b in zip(*runs.values())]
        rows[1]["solve_ratio_to_scipy"] = statistics.median(ratios)
        log.info(f"bench_3d: {libraries[1]} / {libraries[0]} solve time, median of {len(ratios)} "
                 f"interleaved pairs: {rows[1]['solve_ratio_to_scipy']:.3f}")
    return rows


def main(out: Path, quick: bool = False, repeats: int | None = None) -> int:
    """Rows are appended per case as it finishes (runner); a re-run skips finished cases."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    repeats = repeats or (1 if quick else 3)
    todo = [{"case": " ".join(map(str, c)), "kind": c[0], "n": c[1], "backend": c[2],
             "fft": c[3] if len(c) > 3 else "auto",
             "repeats": 1 if c[2] == "ipopt" or c[0] == "fem-p1" else repeats}
            for c in cases(quick)]
    run_cases("bench_3d", todo, case_rows, out / "bench_3d.csv", workers=1, extra_columns=EXTRA)
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/bench_3d"), quick="--quick" in sys.argv))
