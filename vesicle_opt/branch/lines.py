"""Lines in two parameters by sweeps: the folds of a diagram (``branch.tree``) as a second parameter
moves, and the energy crossing of two branches.

For each value q of the second parameter (e.g. the reduced volume of a c0 diagram) the diagram at q
is built (or resumed) in its own directory, ``<out>/<second>=<q>/``, and its located folds
(``branch.events``: on the chord with p free, or the parabola's vertex) are the points of the fold
line (p_fold(q), E(q)); ``crossing_line`` takes two diagrams per q and locates where the
reduced energies of their first branches cross (``branch.crossing``: cubic splines and brentq).
This is a sweep, not a continuation of the fold in two parameters: each point is located as on one
branch, to that branch's tolerance, and the line is only as fine as ``values``.

``fold_line.csv``: ``second, value, param, target, energy, reduced_energy, branch, located_by,
detected_at, critical_eigenvalue, critical_error``, one row per located fold, in the order of
``values``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Callable

from vesicle_opt.branch.crossing import crossing
from vesicle_opt.branch.events import FOLD
from vesicle_opt.branch.params import PARAMS, parameter
from vesicle_opt.branch.run import branch
from vesicle_opt.errors import InputError

LINE_COLUMNS = ["second", "value", "param", "target", "energy", "reduced_energy", "branch", "located_by",
                "detected_at", "critical_eigenvalue", "critical_error"]


def fold_line(diagram_at: Callable[[float], list[dict]], values, second: str = "q", param: str = "p") -> list[dict]:
    """The located folds of ``diagram_at(q)`` (its rows) for each q in ``values`` (module docstring)."""
    out = []
    for q in values:
        for r in diagram_at(float(q)):
            if r.get("corrector") == "locate" and r.get("event") == FOLD:
                out.append({"second": second, "value": float(q), "param": param,
                            **{k: r.get(k) for k in LINE_COLUMNS[3:]}})
    return out


def crossing_line(diagram_a: Callable[[float], list[dict]], diagram_b: Callable[[float], list[dict]],
                  values, key: str = "reduced_energy") -> list[dict]:
    """Where the first branches (id 0) of two diagrams cross, for each q: {value, target, energy}
    (None where they do not cross in the overlap of their ranges)."""
    out = []
    for q in values:
        a, b = ([r for r in d(float(q)) if r["accepted"] and r["branch"] == 0] for d in (diagram_a, diagram_b))
        x = crossing([r["target"] for r in a], [r[key] for r in a], [r["target"] for r in b], [r[key] for r in b])
        out.append({"value": float(q), "target": None if x is None else x["reduced_volume"],
                    "energy": None if x is None else x["reduced_energy"]})
    return out


def check_line(param: str, second: str | None, values) -> list[float]:
    """The second parameter and its values, checked before any work (InputError naming the flag)."""
    if second is None:
        if values:
            raise InputError("--second", "missing: --values needs the second parameter it gives values of")
        return []
    if second not in PARAMS or second == param:
        raise InputError("--second", f"must be one of {', '.join(p for p in PARAMS if p != param)} "
                         f"(not the branch's --param {param}), got {second!r}")
    vals = [float(v) for v in (values or [])]
    if len(vals) < 2 or not all(math.isfinite(v) for v in vals):
        raise InputError("--values", f"give at least two finite values of {second}, got {values!r}")
    if second == "reduced_volume" and not all(0 < v <= 1 for v in vals):
        raise InputError("--values", f"allowed range 0 < reduced_volume <= 1, got {vals!r}")
    return vals


def sweep(scene, param: str, to: float, step, second: str, values, out, **kw) -> list[dict]:
    """``branch.run.branch`` at each value of ``second`` (its own directory under ``out``, resumed
    there) and the fold line of the diagrams, written to ``out/fold_line.csv``."""
    vals = check_line(param, second, values)
    sec = parameter(scene, second)

    def diagram_at(q):
        sub = None if out is None else Path(out) / f"{second}={q:.6g}"
        return list(branch(sec.scene_at(scene, q), param, to, step, sub, **kw).rows)
    rows = fold_line(diagram_at, vals, second, param)
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        with open(Path(out) / "fold_line.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, LINE_COLUMNS, extrasaction="ignore", lineterminator="\n")
            w.writeheader()
            w.writerows({k: ("" if v is None else v) for k, v in r.items()} for r in rows)
    return rows
