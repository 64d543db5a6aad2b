"""Benchmark of the JAX array backend (issue 15): numpy against JAX on one and two devices.

The ``torus-table1-3d`` scene on ``spectral`` grids (exact constraints, tol 1e-8, cold torus start,
the newton-krylov backend; second-order check off: it runs in numpy for every variant) with

* ``numpy``: ``solver.array = 'numpy'`` (scipy FFTs, one worker);
* ``jax-1``: ``solver.array = 'jax'`` on one CPU device;
* ``jax-2``: the grid split along its first axis across two emulated host devices
  (``XLA_FLAGS=--xla_force_host_platform_device_count=2``: two XLA devices sharing the host's cores,
  so this row measures the sharded program's overhead, not a speed-up; real devices are GPUs).

Every run is a fresh spawned process (``runner.in_fresh_process``; the XLA flags are set in the
parent before the spawn, so they precede the child's jax import), so ``peak_rss_mb`` is that solve's
own peak resident memory, interpreter and libraries included; on the CPU the devices' memory is host
memory. The variants are interleaved repeat by repeat and each row carries the median wall time and
its ratio to numpy's median of the same n (``ratio_to_numpy``, > 1: slower than numpy), with the
solver's CPU time (``solve_cpu_s``: both cores' time when XLA runs threads). The first repeat of
a jax variant compiles its programs (``total_wall_cold_s``) into jax's persistent compilation cache
(``out/jax_cache``); the median (and its ratio) is over the later, warm repeats, which read it.
GPU rows (64^3 ... 512^3, one device, ``jax-gpu``) are solved where jax's default device is a GPU
and written as ``not measured`` otherwise (peak device memory is then not in ``peak_rss_mb``).
``main(out, quick)`` writes ``bench_jax.csv``; quick = 32^3, one repeat.
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
from vesicle_opt.studies.runner import in_fresh_process, run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

VARIANTS = ("numpy", "jax-1", "jax-2")
GPU_SIZES = (64, 128, 256, 512)


def _compile_cache(path: str) -> None:
    """jax's persistent compilation cache in ``path`` (every program, however short its compile)."""
    import jax  # noqa: PLC0415 (in the child process only: jax is optional and imported on use)
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def _case(variant: str, n: int, cache: str | None = None) -> dict:
    array = "numpy" if variant == "numpy" else "jax"
    if array == "jax" and cache:
        _compile_cache(cache)
    sc = scene.load("torus-table1-3d", ["mesh.kind='spectral'", f"mesh.n={n}", "solver.backend='newton-krylov'",
                                        f"solver.array='{array}'", "solver.second_order=false"])
    t0 = time.perf_counter()
    r = solve(sc)
    total = time.perf_counter() - t0
    # E* at the exact constraints to first order (lam = dE*/d(alpha, beta)): E itself moves by the
    # lam . c that the stopping test's |c| <= 0.1 tol leaves, differently on every round-off path
    at_constraints = r.energy - r.lambda_volume * r.volume_residual - r.lambda_area * r.area_residual
    return {"variant": variant, "n": n, "n_nodes": r.n_nodes, "energy": r.energy, "status": r.status,
            "energy_at_constraints": at_constraints,
            "converged": r.converged, "kkt_residual": r.kkt_residual, "newton": r.iterations,
            "cg": r.extra.get("cg_iterations"), "devices": r.extra.get("devices", 1),
            "platform": r.extra.get("platform", "cpu"), "solve_wall_s": r.wall_time_s,
            "solve_cpu_s": r.extra.get("cpu_time_s"), "total_wall_s": total,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _run(variant: str, n: int, cache: str) -> dict:
    """One fresh process; the device count is fixed by XLA_FLAGS before the child imports jax."""
    flags = os.environ.get("XLA_FLAGS")
    os.environ["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={2 if variant == 'jax-2' else 1}"
    try:
        return in_fresh_process(_case, variant, n, cache)
    finally:
        if flags is None:
            os.environ.pop("XLA_FLAGS")
        else:
            os.environ["XLA_FLAGS"] = flags


EXTRA = ["variant", "n_nodes", "converged", "kkt_residual", "newton", "cg", "devices", "platform",
         "solve_wall_s", "solve_cpu_s", "total_wall_s", "peak_rss_mb", "repeats", "total_wall_median_s",
         "total_wall_min_s", "total_wall_cold_s", "ratio_to_numpy", "energy_rel_to_numpy", "energy_at_constraints", "at_constraints_rel_to_numpy",
         "load_1min"]


def case_rows(case: dict) -> list[dict]:
    """``repeats`` rounds of the three variants at one n, interleaved; one row per variant."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")  # one BLAS thread in the children (as bench_3d)
    n, runs = case["n"], {v: [] for v in VARIANTS}
    loads = []
    for _ in range(case["repeats"]):
        for v in VARIANTS:
            loads.append(os.getloadavg()[0])
            runs[v].append(_run(v, n, case["cache"]))
    # the first repeat compiles (cold); later repeats read jax's persistent cache (warm)
    warm = {v: runs[v][1:] or runs[v] for v in VARIANTS}
    med = {v: statistics.median(r["total_wall_s"] for r in warm[v]) for v in VARIANTS}
    e_np, ec_np = runs["numpy"][-1]["energy"], runs["numpy"][-1]["energy_at_constraints"]
    rows = []
    for v in VARIANTS:
        row = dict(runs[v][-1])
        walls = [r["total_wall_s"] for r in warm[v]]
        row.update({"scene": "torus-table1-3d", "method": "exact", "iterations": row["newton"],
                    "wall_time_s": med[v], "repeats": case["repeats"], "total_wall_median_s": med[v],
                    "total_wall_min_s": min(walls), "total_wall_cold_s": runs[v][0]["total_wall_s"],
                    "ratio_to_numpy": med[v] / med["numpy"],
                    "energy_rel_to_numpy": abs(row["energy"] - e_np) / abs(e_np),
                    "at_constraints_rel_to_numpy": abs(row["energy_at_constraints"] - ec_np) / abs(ec_np),
                    "peak_rss_mb": max(r["peak_rss_mb"] for r in runs[v]),
                    "load_1min": statistics.median(loads)})
        log.info(f"bench_jax: n={n:3d} {v:6s} E={row['energy']:.9f} newton={row['newton']} cg={row['cg']} "
              f"wall(median of warm repeats)={med[v]:.2f}s cold={row['total_wall_cold_s']:.2f}s ratio={row['ratio_to_numpy']:.2f} "
              f"rss={row['peak_rss_mb']:.0f}MB load={row['load_1min']:.1f}")
        rows.append(row)
    return rows


def _backend() -> str:
    import jax  # noqa: PLC0415 (in the child process only: jax is optional and must not be imported here)
    return jax.default_backend()


def gpu_rows(case: dict) -> list[dict]:
    """A GPU size: solved on the default jax device when that is a GPU, else ``not measured``."""
    if in_fresh_process(_backend) != "gpu":
        return [{"scene": "torus-table1-3d", "method": "exact", "variant": "jax-gpu", "n": case["n"],
                 "status": "not measured (no GPU visible to jax)", "platform": "gpu"}]
    row = in_fresh_process(_case, "jax-1", case["n"], case.get("cache"))
    row.update({"scene": "torus-table1-3d", "method": "exact", "variant": "jax-gpu", "repeats": 1,
                "wall_time_s": row["total_wall_s"], "iterations": row["newton"]})
    return [row]


def main(out: Path, quick: bool = False, repeats: int | None = None, sizes=None) -> int:
    """Rows are appended per n as it finishes (runner); a re-run skips finished cases."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    repeats = repeats or (1 if quick else 3)
    sizes = sizes or ((32,) if quick else (32, 64))
    cache = str(out / "jax_cache")
    todo = [{"case": f"cpu {n}", "n": n, "repeats": repeats, "cache": cache} for n in sizes]
    run_cases("bench_jax", todo, case_rows, out / "bench_jax.csv", workers=1, extra_columns=EXTRA)
    if not quick:
        gpu = [{"case": f"gpu {n}", "n": n} for n in GPU_SIZES]
        run_cases("bench_jax", gpu, gpu_rows, out / "bench_jax.csv", workers=1, extra_columns=EXTRA)
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/bench_jax"), quick="--quick" in sys.argv))
