"""Warm branch points on an interface-refined meridian mesh: CPU and wall seconds per point, three
generations of the start and the second-order check, interleaved (docs/guide/axisymmetric.md, "Cost").

The prolate branch at c0 = 0 from v = 0.8 down in steps of ``DV`` on one refined mesh (h = eps/2,
``LEVELS`` halvings, band 8 eps, walls 12 eps from the sharp shape; R0 = 1), each point through the
front door warm from the points before it, solved three times on the same target from the same points:

* ``old``: the secant in the NLP vector x (2 x_1 - x_0) and the second-order check's LU of the whole
  bordered matrix (``verify.shift_invert.factorise`` switched off), scipy's default ARPACK ncv,
  MUMPS's default ordering;
* ``schur``: ``nlp.predict.interface_secant`` and the Schur-complement check by SuperLU's LU of
  H - sM (``factorise(ldl_first=False)``), scipy's default ncv, MUMPS's default ordering;
* ``new``: the parabola through the last three points (``nlp.predict.interface_extrapolation``),
  MUMPS ordered by QAMD (``nlp.reuse.ORDERING``), and the Schur-complement check by the LDL^T kept
  per pattern (``verify.ldl``, where the extra ``ldl`` loads) with ncv ``second_order.NCV``, numpy's
  BLAS on one thread in the solve and the check (``api.REFINED_BLAS_THREADS``, ``second_order.check``;
  the other modes run on all of them, the check as ``second_order._check``).

(The Hessian functions and pattern cached per solver, ``nlp.reuse.derivatives``, serve all three.)
The walk goes on from the ``new`` point. A row per solve: ``mode``, ``reduced_volume``, ``cpu_s``
(``time.process_time``: far less load-sensitive than wall on a shared machine), ``wall_time_s``
(the whole front-door call), ``ipopt_wall_s``, ``check_wall_s``, ``iterations``, ``verdict``,
``min_eigenvalue`` and ``error_bound`` (the check's least eigenvalue and its error bound, mu_ref
units), ``load_average`` (1 min, at the end of the solve) and the medians per mode in
``median_cpu_s`` / ``median_wall_s`` on the last row of each mode. On each ``new`` row,
``min_eigenvalue_lu``: the ``schur`` check (SuperLU, default ncv) of the same point, after the timed
solve: the two factorisations' least eigenvalues differ by round-off only (``eigenvalue_gap`` =
|difference| / error_bound). Full: eps = 0.02 (20.3 k nodes), 6 points a mode; quick: eps = 0.1
(1.5 k nodes), 2 points.

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

from vesicle_opt import api
from vesicle_opt.api import solve
from vesicle_opt.io.meridian import phase_field_of
from vesicle_opt.mesh import discretize
from vesicle_opt.nlp import reuse
from vesicle_opt.nlp.ipopt import IpoptOptions
from vesicle_opt.nlp.predict import interface_extrapolation, interface_secant
from vesicle_opt.scene import from_dict
from vesicle_opt.sharp import axisymmetric as sharp
from vesicle_opt.studies.runner import run_cases
from vesicle_opt.verify import second_order, shift_invert

LEVELS, DV, V0 = 4, 0.0025, 0.8
MODES = ("old", "schur", "new")
EXTRA = ["mode", "reduced_volume", "cpu_s", "ipopt_wall_s", "check_wall_s", "verdict", "load_average",
         "median_cpu_s", "median_wall_s", "min_eigenvalue", "error_bound", "min_eigenvalue_lu", "eigenvalue_gap"]


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


def _setting(mode: str) -> None:
    """The check of ``mode`` (module docstring), through the module attributes the front door reads."""
    real = _REAL["factorise"]
    shift_invert.factorise = {"old": lambda *args, **kw: None,  # the bordered LU instead
                              "schur": lambda *args, **kw: real(*args, ldl_first=False)}.get(mode, real)
    second_order.NCV = _REAL["ncv"] if mode == "new" else None
    reuse.ORDERING = _REAL["ordering"] if mode == "new" else ()  # a solver of its own (``reuse.parametric``)
    api.REFINED_BLAS_THREADS = _REAL["threads"] if mode == "new" else None


def _start(mode: str, walk: list):
    a, b = walk[-2:]
    if mode == "old":
        x = 2 * b.x - a.x
        return dataclasses.replace(b, x=x, phi=x[:b.disc.n_nodes])
    if mode == "schur" or len(walk) < 3 or walk[-3].disc is not b.disc:
        return interface_secant(a, b)
    return interface_extrapolation(walk[-3:])


def _lu_check(captured: dict) -> float:
    """The ``schur`` check's least eigenvalue (mu_ref units) on the point the last check saw."""
    try:
        _setting("schur")
        return _REAL["check"](*captured["args"], **captured["kw"]).relative_min_eigenvalue
    finally:
        _setting("new")


def _walk(case: dict) -> list[dict]:
    eps, points = case["epsilon"], case["points"]
    scene, (r, z) = _scene_maker(eps, case["levels"])
    first = scene(V0)
    a = solve(first, x0=phase_field_of(r, z, discretize(first).nodes, eps))
    a = solve(first, x0=a)  # on the band about its own interface
    walk = [a, solve(scene(V0 - DV), x0=a)]
    walk.append(solve(scene(V0 - 2 * DV), x0=interface_secant(*walk)))  # three points: the parabola's start
    _REAL.update(factorise=shift_invert.factorise, ncv=second_order.NCV, check=second_order.check,
                 ordering=reuse.ORDERING, threads=api.REFINED_BLAS_THREADS)
    captured: dict = {}

    def capture(*args, **kw):  # the check's arguments, for ``min_eigenvalue_lu``; old modes: all BLAS threads
        captured.update(args=args, kw=kw)
        return (_REAL["check"] if captured["mode"] == "new" else second_order._check)(*args, **kw)
    rows = []
    try:
        second_order.check = capture
        for mode in MODES:  # each ordering's IPOPT solver built before the timed solves
            _setting(mode)
            reuse.parametric(walk[-1].scene, walk[-1].disc, IpoptOptions.from_scene(walk[-1].scene), True)
        for k in range(3, points + 3):
            v = V0 - k * DV
            for mode in MODES:
                _setting(mode)
                start = _start(mode, walk)
                captured.clear()
                captured["mode"] = mode
                c0, w0 = time.process_time(), time.perf_counter()
                res = solve(scene(v), x0=start)
                cpu, wall = time.process_time() - c0, time.perf_counter() - w0
                so = res.extra.get("second_order_min_eigenvalue")
                row = {"scene": "prolate-meridian", "method": "exact", "n": res.disc.n_nodes, "h": eps / 2,
                       "energy": res.energy, "iterations": res.iterations, "wall_time_s": wall,
                       "status": res.outcome, "mode": mode, "reduced_volume": v, "cpu_s": cpu,
                       "ipopt_wall_s": res.wall_time_s, "check_wall_s": res.extra.get("second_order_time_s"),
                       "verdict": res.extra.get("second_order"), "load_average": os.getloadavg()[0],
                       "min_eigenvalue": so, "error_bound": res.extra.get("second_order_error_bound")}
                if mode == "new" and "args" in captured and so is not None:
                    row["min_eigenvalue_lu"] = lu = _lu_check(captured)
                    row["eigenvalue_gap"] = abs(so - lu) / row["error_bound"] if row["error_bound"] else None
                rows.append(row)
            walk.append(res)
    finally:
        _setting("new")
        shift_invert.factorise, second_order.check = _REAL["factorise"], _REAL["check"]
    for mode in MODES:
        mine = [r for r in rows if r["mode"] == mode]
        mine[-1].update(median_cpu_s=statistics.median(r["cpu_s"] for r in mine),
                        median_wall_s=statistics.median(r["wall_time_s"] for r in mine))
    return rows


_REAL: dict = {}  # the module attributes the modes replace, as found (``_walk``)


def main(out: Path, quick: bool = False) -> int:
    case = {"case": "quick" if quick else "full", "epsilon": 0.1 if quick else 0.02,
            "levels": 2 if quick else LEVELS, "points": 2 if quick else 6}
    run_cases("bench_axisymmetric", [case], _walk, Path(out) / "bench_axisymmetric.csv", extra_columns=EXTRA)
    return 0


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "results"), quick="--quick" in sys.argv)
