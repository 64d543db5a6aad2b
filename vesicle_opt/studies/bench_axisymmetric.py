"""Warm branch points on an interface-refined meridian mesh: CPU and wall seconds per point, old
against new start and second-order check, interleaved (docs/guide/axisymmetric.md, "Cost").

The prolate branch at c0 = 0 from v = 0.8 down in steps of ``DV`` on one refined mesh (h = eps/2,
``LEVELS`` halvings, band 8 eps, walls 12 eps from the sharp shape; R0 = 1), each point through the
front door warm from the two before it, solved twice on the same target from the same two points:

* ``old``: the secant in the NLP vector x (2 x_1 - x_0) and the second-order check's LU of the whole
  bordered matrix (``verify.shift_invert.factorise`` switched off);
* ``new``: ``nlp.predict.interface_secant`` and the Schur-complement check (``verify.shift_invert``).

The walk goes on from the ``new`` point. A row per solve: ``mode``, ``reduced_volume``, ``cpu_s``
(``time.process_time``: far less load-sensitive than wall on a shared machine), ``wall_time_s``
(the whole front-door call), ``ipopt_wall_s``, ``check_wall_s``, ``iterations``, ``verdict``,
``load_average`` (1 min, at the end of the solve) and the medians per mode in ``median_cpu_s`` /
``median_wall_s`` on the last row of each mode. Full: eps = 0.02 (20.3 k nodes), 6 points a mode;
quick: eps = 0.1 (1.5 k nodes), 2 points.

    vesicle-opt study bench_axisymmetric --out DIR [--quick]
"""

from __future__ import annotations

import dataclasses
import math
import os
import statistics
import sys
import time
from pathlib import Path

from vesicle_opt.api import solve
from vesicle_opt.io.meridian import phase_field_of
from vesicle_opt.mesh import discretize
from vesicle_opt.nlp.predict import interface_secant
from vesicle_opt.scene import from_dict
from vesicle_opt.sharp import axisymmetric as sharp
from vesicle_opt.studies.runner import run_cases
from vesicle_opt.verify import shift_invert

LEVELS, DV, V0 = 4, 0.0025, 0.8
EXTRA = ["mode", "reduced_volume", "cpu_s", "ipopt_wall_s", "check_wall_s", "verdict", "load_average",
         "median_cpu_s", "median_wall_s"]


def _scene_maker(eps: float, levels: int):
    side = eps / 2 * 2**levels  # the box's square cells, halved `levels` times: h = eps / 2
    r, z = sharp.branch([V0], "prolate", 16, second_order=False)[0].meridian(2048)
    pad = 12 * eps
    R = math.ceil((r.max() + pad) / side) * side
    Z = math.ceil((max(abs(z.min()), z.max()) + pad) / side) * side
    box, n = [[0.0, R], [-Z, Z]], [round(R / side), round(2 * Z / side)]

    def scene(v):
        return from_dict({"domain": {"box": box, "boundary": "natural"},
                          "mesh": {"kind": "axisymmetric", "n": n, "refine": "interface", "levels": levels},
                          "model": {"epsilon": eps}, "constraints": {"reduced_volume": v, "area": 4 * math.pi},
                          "initial": {"shape": "sphere", "radius": 1.0}, "solver": {"method": "exact"}},
                         name=f"bench_axisymmetric-v{v:g}")
    return scene, (r, z)


def _walk(case: dict) -> list[dict]:
    eps, points = case["epsilon"], case["points"]
    scene, (r, z) = _scene_maker(eps, case["levels"])
    first = scene(V0)
    a = solve(first, x0=phase_field_of(r, z, discretize(first).nodes, eps))
    a = solve(first, x0=a)  # on the band about its own interface
    b = solve(scene(V0 - DV), x0=a)
    real = shift_invert.factorise
    rows = []
    try:
        for k in range(2, points + 2):
            v = V0 - k * DV
            for mode in ("old", "new"):
                if mode == "old":
                    shift_invert.factorise = lambda *args, **kw: None  # the bordered LU instead
                    x = 2 * b.x - a.x
                    start = dataclasses.replace(b, x=x, phi=x[:b.disc.n_nodes])
                else:
                    shift_invert.factorise = real
                    start = interface_secant(a, b)
                c0, w0 = time.process_time(), time.perf_counter()
                res = solve(scene(v), x0=start)
                cpu, wall = time.process_time() - c0, time.perf_counter() - w0
                rows.append({"scene": "prolate-meridian", "method": "exact", "n": res.disc.n_nodes, "h": eps / 2,
                             "energy": res.energy, "iterations": res.iterations, "wall_time_s": wall,
                             "status": res.outcome, "mode": mode, "reduced_volume": v, "cpu_s": cpu,
                             "ipopt_wall_s": res.wall_time_s, "check_wall_s": res.extra.get("second_order_time_s"),
                             "verdict": res.extra.get("second_order"), "load_average": os.getloadavg()[0]})
            a, b = b, res
    finally:
        shift_invert.factorise = real
    for mode in ("old", "new"):
        mine = [r for r in rows if r["mode"] == mode]
        mine[-1].update(median_cpu_s=statistics.median(r["cpu_s"] for r in mine),
                        median_wall_s=statistics.median(r["wall_time_s"] for r in mine))
    return rows


def main(out: Path, quick: bool = False) -> int:
    case = {"case": "quick" if quick else "full", "epsilon": 0.1 if quick else 0.02,
            "levels": 2 if quick else LEVELS, "points": 2 if quick else 6}
    run_cases("bench_axisymmetric", [case], _walk, Path(out) / "bench_axisymmetric.csv", extra_columns=EXTRA)
    return 0


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "results"), quick="--quick" in sys.argv)
