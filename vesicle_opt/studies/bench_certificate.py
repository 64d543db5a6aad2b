"""Benchmark of the second-order certificate against the solve it certifies (issue "Speed where users
wait", item 1): time and peak memory ratios, the FFT count and FFT share of each.

The ``torus-table1-3d`` scene (exact constraints, newton-krylov) on spectral grids and on a periodic
lumped P1 mesh. Each case runs ``repeats`` times, interleaved, each run in two fresh processes:

* ``bare``: the front door with ``solver.second_order = false`` (its peak resident memory is the
  bare solve's);
* ``certified``: the front door with the check on (the default), as a user runs it; the check's
  wall time is the front door's ``second_order_time_s``, its peak memory the certified run's.

A row holds the medians over the repeats: ``solve_s`` (the bare runs' solver wall time),
``certificate_s``, ``certificate_ratio`` = certificate / solve (median of the per-repeat ratios, each
the check over the solve it followed in the same process),
``memory_ratio`` = certified peak / bare peak, the verdict with its eigenvalue, error bound and
iterations, and on Fourier grids the FFT counts (``mesh.spectral.FourierGrid.transforms``) of the
solve and of the certificate and their FFT shares (count x the time of one transform of that grid,
measured in the same process, over the wall time). The load average is written beside each row:
the machine is shared, so the ratios, measured side by side, mean more than the times.
``main(out, quick)`` writes ``bench_certificate.csv``; quick = small grids.
"""

from __future__ import annotations

import logging

import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from vesicle_opt import scene
from vesicle_opt.api import solve
from vesicle_opt.mesh.spectral import FourierGrid, fft_library, resolve_fft
from vesicle_opt.studies.runner import in_fresh_process, run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

TRANSFORM_REPEATS = 20  # one transform's time: the median of this many rfftn / irfftn pairs


def _scene(kind: str, n: int, second_order: bool, fft: str = "auto"):
    return scene.load("torus-table1-3d", [f"mesh.kind='{kind}'", f"mesh.n={n}", "solver.backend='newton-krylov'",
                                          f"solver.second_order={'true' if second_order else 'false'}",
                                          f"solver.fft='{fft}'"])


def transform_time(disc) -> float:
    """Seconds of one real FFT of this grid (half an rfftn + irfftn pair), median of repeats."""
    f = getattr(disc, "fourier", None)
    if f is None:
        return float("nan")
    v = np.random.default_rng(0).standard_normal(f.size)
    times = []
    for _ in range(TRANSFORM_REPEATS):
        t0 = time.perf_counter()
        f.ifft(f.fft(v))
        times.append((time.perf_counter() - t0) / 2)
    FourierGrid.transforms -= 2 * TRANSFORM_REPEATS
    return statistics.median(times)


def _run(kind: str, n: int, certified: bool, fft: str = "auto") -> dict:
    """One fresh-process run of the front door (module docstring)."""
    sc = _scene(kind, n, certified, fft)
    f0 = FourierGrid.transforms
    t0 = time.perf_counter()
    r = solve(sc)
    out = {"solve_s": r.wall_time_s, "front_door_s": time.perf_counter() - t0, "converged": r.converged,
           "energy": r.energy, "fft_total": FourierGrid.transforms - f0, "fft_library": resolve_fft(fft)}
    if certified and r.converged:
        e = r.extra
        out.update({"certificate_s": e["second_order_time_s"], "verdict": e["second_order"],
                    "min_eigenvalue": e["second_order_min_eigenvalue"],
                    "error_bound": e.get("second_order_error_bound", float("nan")),
                    "iterations": e.get("second_order_iterations"), "reason": e.get("second_order_reason", "")})
    with fft_library(fft):
        out["transform_s"] = transform_time(r.disc)
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def cases(quick: bool) -> list[tuple[str, int, int]]:
    """(kind, n, repeats)."""
    if quick:
        return [("spectral", 32, 1), ("fem-p1", 16, 1)]
    return [("spectral", 64, 3), ("spectral", 96, 3), ("spectral", 128, 3), ("fem-p1", 48, 1)]


EXTRA = ["kind", "n", "repeats", "load_average", "converged", "solve_s", "certificate_s", "certificate_ratio",
         "bare_peak_mb", "certified_peak_mb", "memory_ratio", "verdict", "min_eigenvalue", "error_bound",
         "iterations", "reason", "fft_library", "fft_solve", "fft_certificate", "transform_ms", "fft_share_solve",
         "fft_share_certificate"]


def case_rows(case: dict) -> list[dict]:
    os.environ.setdefault("OMP_NUM_THREADS", "1")  # as bench_3d: the children's BLAS, set before they start
    load = os.getloadavg()[0]
    bare, cert = [], []
    for _ in range(case["repeats"]):  # interleaved: bare, certified, bare, certified, ...
        bare.append(in_fresh_process(_run, case["kind"], case["n"], False))
        cert.append(in_fresh_process(_run, case["kind"], case["n"], True))
    med = statistics.median
    c = cert[-1]
    ratios = [ce["certificate_s"] / ce["solve_s"] for ce in cert if "certificate_s" in ce]
    tr = med([b["transform_s"] for b in bare])
    solve_s = med([b["solve_s"] for b in bare])
    cert_s = med([ce["certificate_s"] for ce in cert if "certificate_s" in ce]) if ratios else float("nan")
    bare_peak, cert_peak = med([b["peak_rss_mb"] for b in bare]), med([ce["peak_rss_mb"] for ce in cert])
    # the solve's path is deterministic: the certified run's extra transforms are the check's
    fft_solve = bare[-1]["fft_total"]
    fft_cert = c["fft_total"] - fft_solve if "certificate_s" in c else None
    row = {"scene": "torus-table1-3d", "method": "exact", "kind": case["kind"], "n": case["n"],
           "repeats": case["repeats"], "load_average": round(load, 1),
           "converged": all(b["converged"] for b in bare + cert), "energy": c["energy"],
           "status": "converged" if all(b["converged"] for b in bare + cert) else "not converged",
           "solve_s": solve_s, "wall_time_s": solve_s, "certificate_s": cert_s,
           "certificate_ratio": med(ratios) if ratios else float("nan"),
           "bare_peak_mb": bare_peak, "certified_peak_mb": cert_peak, "memory_ratio": cert_peak / bare_peak,
           "verdict": c.get("verdict"), "min_eigenvalue": c.get("min_eigenvalue"),
           "error_bound": c.get("error_bound"), "iterations": c.get("iterations"), "reason": c.get("reason"),
           "fft_library": c["fft_library"], "fft_solve": fft_solve, "fft_certificate": fft_cert, "transform_ms": 1e3 * tr,
           "fft_share_solve": fft_solve * tr / solve_s if np.isfinite(tr) else float("nan"),
           "fft_share_certificate": (fft_cert * tr / cert_s) if np.isfinite(tr) and ratios else float("nan")}
    log.info(f"bench_certificate: {row['kind']:8s} n={row['n']:3d} solve={solve_s:.2f}s cert={cert_s:.2f}s "
          f"ratio={row['certificate_ratio']:.2f} mem={row['memory_ratio']:.2f} {row['verdict']} "
          f"mu={row['min_eigenvalue']} err={row['error_bound']} load={load:.1f}")
    return [row]


def main(out: Path, quick: bool = False, repeats: int | None = None) -> int:
    """Rows are appended per case as it finishes (runner); a re-run skips finished cases."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    todo = [{"case": f"{kind} {n}", "kind": kind, "n": n, "repeats": repeats or r} for kind, n, r in cases(quick)]
    run_cases("bench_certificate", todo, case_rows, out / "bench_certificate.csv", workers=1, extra_columns=EXTRA)
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/bench_certificate"), quick="--quick" in sys.argv))


def fft_libraries(n: int, repeats: int = 15) -> dict:
    """One rfftn + irfftn pair on an n^3 float64 grid, one thread: scipy.fft against pyFFTW (the
    optional extra ``fftw``; planned once with FFTW_MEASURE and reused, as a solver would), medians
    of ``repeats`` interleaved pairs; {} for pyfftw when it is not installed."""
    import scipy.fft as sfft
    v = np.random.default_rng(0).standard_normal((n, n, n))
    out = {"n": n}
    try:
        import pyfftw  # optional extra, third-party: only this comparison uses it
    except ImportError:
        pyfftw = None
    if pyfftw is not None:
        a = pyfftw.empty_aligned((n, n, n), dtype="float64")
        fwd = pyfftw.builders.rfftn(a, threads=1, planner_effort="FFTW_MEASURE")
        b = pyfftw.empty_aligned(fwd.output_shape, dtype="complex128")
        bwd = pyfftw.builders.irfftn(b, s=(n, n, n), threads=1, planner_effort="FFTW_MEASURE")
    ts, tf = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sfft.irfftn(sfft.rfftn(v, workers=1), s=v.shape, workers=1)
        ts.append(time.perf_counter() - t0)
        if pyfftw is not None:
            t0 = time.perf_counter()
            a[...] = v
            b[...] = fwd()
            bwd()
            tf.append(time.perf_counter() - t0)
    out["scipy_pair_ms"] = 1e3 * statistics.median(ts)
    if tf:
        out["pyfftw_pair_ms"] = 1e3 * statistics.median(tf)
        out["pyfftw_speedup"] = out["scipy_pair_ms"] / out["pyfftw_pair_ms"]
    return out
