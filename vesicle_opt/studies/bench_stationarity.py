"""The stationarity certificate against the grid (issue 25, Build 2): the round-off floor and the
certified residual in the old norm (relative L2, ``kkt_residual`` / ``kkt_floor``) and in the
natural norm that decides now (``kkt_dual`` / ``kkt_dual_floor``, ``model.metric``), against n.

Cases (Newton-Krylov, method exact, tol 1e-8, second-order check off): ellipse-2d on spectral and
FD (by FFT) grids 64^2 ... 1024^2, and the Table-1 torus (``torus-table1-3d``) on spectral grids
32^3 ... 128^3 (quick: 64^2, 128^2 and 32^3). Each row also says what the old rule (L2 floor < tol,
kkt_residual <= 100 tol) would have decided (``certified_l2``) and what the certificate decides
(``converged``). The floors are the models of ``nk.solve.l2_floor`` (L2, ~ h^-4) and
``verify.kkt.dual_floor`` (natural, ~ h^-2); the fitted growth exponents are in the summary JSON
(``slope_*``: d log floor / d log n). ``main(out, quick)`` writes ``bench_stationarity.csv``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from vesicle_opt import scene
from vesicle_opt.api import solve
from vesicle_opt.io.files import write_json
from vesicle_opt.studies.runner import run_cases
from vesicle_opt.verify.certify import KKT_FACTOR

TOL = 1e-8
EXTRA = ["scene_name", "kind", "n", "h", "tol", "converged", "outcome", "energy", "kkt_residual", "kkt_floor",
         "kkt_dual", "kkt_dual_floor", "certified_l2", "newton", "wall_s"]


def cases(quick: bool) -> list[dict]:
    sizes2 = (64, 128) if quick else (64, 128, 256, 512, 1024)
    sizes3 = (32,) if quick else (32, 48, 64, 96, 128)
    out = [{"scene_name": "ellipse-2d", "kind": k, "n": n} for k in ("spectral", "fd") for n in sizes2]
    out += [{"scene_name": "torus-table1-3d", "kind": "spectral", "n": n} for n in sizes3]
    for c in out:
        c["case"] = f"{c['scene_name']} {c['kind']} {c['n']}"
    return out


def case_rows(case: dict) -> list[dict]:
    sc = scene.load(case["scene_name"], [f"mesh.kind='{case['kind']}'", f"mesh.n={case['n']}", f"solver.tol={TOL}",
                                         "solver.method='exact'", "solver.backend='newton-krylov'",
                                         "solver.second_order=false"])
    t0 = time.perf_counter()
    r = solve(sc)
    e = r.extra
    l2_ok = bool(r.success and e["kkt_floor"] < TOL and r.kkt_residual <= KKT_FACTOR * TOL)
    return [{"scene": case["scene_name"], "method": "exact", "scene_name": case["scene_name"], "kind": case["kind"],
             "n": case["n"], "h": r.disc.h, "tol": TOL, "status": r.status, "converged": r.converged,
             "outcome": str(r.outcome), "energy": r.energy, "kkt_residual": r.kkt_residual, "kkt_floor": e["kkt_floor"],
             "kkt_dual": e["kkt_dual"], "kkt_dual_floor": e["kkt_dual_floor"], "certified_l2": l2_ok,
             "newton": r.iterations, "wall_s": time.perf_counter() - t0}]


def slopes(rows: list[dict]) -> dict:
    """d log floor / d log n per (scene, kind), for both floors (n >= 2 sizes)."""
    out = {}
    for key in {(r["scene_name"], r["kind"]) for r in rows if r.get("kind")}:
        sel = sorted((r for r in rows if (r.get("scene_name"), r.get("kind")) == key and r.get("kkt_dual_floor")),
                     key=lambda r: float(r["n"]))
        if len(sel) < 2:
            continue
        n = np.log([float(r["n"]) for r in sel])
        for floor in ("kkt_floor", "kkt_dual_floor"):
            out[f"slope_{floor} {key[0]} {key[1]}"] = float(np.polyfit(n, np.log([float(r[floor]) for r in sel]), 1)[0])
    return out


def main(out: Path, quick: bool = False) -> int:
    """Rows are appended per case as it finishes (runner); a re-run skips finished cases."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = run_cases("bench_stationarity", cases(quick), case_rows, out / "bench_stationarity.csv", workers=1,
                     extra_columns=EXTRA)
    write_json(out / "bench_stationarity.json", slopes(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/bench_stationarity"), quick="--quick" in sys.argv))
