"""``transition_line.csv``, the two fields of every crossing, and the resume after a kill.

Layout of ``out``: ``transition.json`` (what was asked; a resume under other arguments is refused,
nothing there changed), ``transition_line.csv`` (one row per value of the second parameter, in the
order computed: ``branch.transition.plan``; appended and fsynced as each finishes) and
``points/row-NNNN-a.npz`` / ``-b.npz`` (the certified fields of both branches at the crossing, the
``io.fields`` layout), written *before* their row: a row in the file always has its fields. The CSV
is read back through the checked loader (``io.state``): a torn last line (a kill mid-write) is cut
off, anything else refused; so a resumed line loses and duplicates no row.

Columns: the crossing (``target`` = p*, ``value`` = q, ``gap`` = |E_a - E_b| / |E| at the two
certified points, ``predicted`` p*, ``energy``/``reduced_energy``/``f``/``c0_reduced`` of branch a
there, ``converged`` both certified, ``outcome`` (``converged``; ``located_to_gap`` where both are certified but the gap
exceeds ``GAP_ACCEPT``)/``reason``/``certifiable_tol`` as branch rows
have them) and per branch, prefixed ``a_`` / ``b_``, the point's report (``PER_BRANCH``); then
``states`` (``states``: "prolate/oblate" where the crossing is that of the two up-down symmetric
branches) and per branch its form on the meridian (``FORM``, ``verify.updown``: ``form``,
``pole_gap``, ``updown_asymmetry``, ``symmetric``) and its mesh (``band_margin``, ``n_nodes``).
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from vesicle_opt.branch.store import cell_text
from vesicle_opt.branch.transition import BRANCHES, Found, Sample
from vesicle_opt.errors import InputError
from vesicle_opt.io import fields, interrupt, outdir, state
from vesicle_opt.io.files import write_json

LINE = ["row", "direction", "second", "value", "param", "target", "predicted", "gap", "energy", "reduced_energy",
        "f", "c0", "c0_reduced", "converged", "outcome", "reason", "certifiable_tol", "samples", "solves",
        "wall_time_s"]
PER_BRANCH = ["target", "energy", "reduced_energy", "f", "reduced_volume", "lambda_volume", "lambda_area", "dE_dp",
              "dE_dq", "kkt_residual", "converged", "outcome", "status", "reason", "certifiable_tol",
              "second_order", "second_order_min_eigenvalue", "second_order_excluded", "shape", "topology",
              "iterations"]
FORM = ["form", "pole_gap", "updown_asymmetry", "symmetric", "band_margin", "n_nodes"]  # verify.updown, the mesh
COLUMNS = LINE + [f"{x}_{k}" for x in BRANCHES for k in PER_BRANCH] + ["states"] + [
    f"{x}_{k}" for x in BRANCHES for k in FORM]
INTS = ("row", "samples", "solves") + tuple(f"{x}_{k}" for x in BRANCHES for k in ("iterations", "n_nodes"))
BOOLS = ("converged",) + tuple(f"{x}_{k}" for x in BRANCHES for k in ("converged", "symmetric"))
FLOATS = ("value", "target", "predicted", "gap", "energy", "reduced_energy", "f", "c0", "c0_reduced",
          "certifiable_tol", "wall_time_s") + tuple(
    f"{x}_{k}" for x in BRANCHES for k in ("target", "energy", "reduced_energy", "f", "reduced_volume",
                                           "lambda_volume", "lambda_area", "dE_dp", "dE_dq", "kkt_residual",
                                           "certifiable_tol", "second_order_min_eigenvalue", "pole_gap",
                                           "updown_asymmetry", "band_margin"))
GAP_ACCEPT = 1e-6  # a crossing with a larger relative gap is reported as "located_to_gap" (its points are
# certified, but not at one energy: the polish's Newton steps did not close it, so the states jumped)
ADVICE = "move it away or give another --out (nothing there was changed)"


def parse(row: dict) -> dict:
    """A CSV row with numbers and booleans back in their types ('' -> None), by this file's columns."""
    out = {}
    for k, v in row.items():
        if v == "" or v is None:
            out[k] = None
        elif k in BOOLS:
            out[k] = v == "true"
        elif k in INTS:
            out[k] = int(v)
        elif k in FLOATS:
            out[k] = float(v)
        else:
            out[k] = v
    return out


def row_of(i: int, direction: str, found: Found, second: str, param: str) -> dict:
    """The CSV row of one crossing (module docstring)."""
    row = {"row": i, "direction": direction, "second": second, "value": found.q, "param": param,
           "target": found.p, "predicted": found.predicted, "gap": found.gap, "converged": found.converged,
           "samples": found.samples, "solves": found.solves, "wall_time_s": found.wall,
           "c0": found.q if second == "c0" else None}
    for x in BRANCHES:
        s = found.points.get(x)
        if s is None:
            continue
        rep = {**s.row, "target": s.p, "energy": s.energy, "converged": s.converged, "dE_dp": s.dE_dp,
               "dE_dq": s.dE_dq, "lambda_volume": None if s.lam is None else s.lam[0],
               "lambda_area": None if s.lam is None else s.lam[1]}
        row.update({f"{x}_{k}": rep.get(k) for k in PER_BRANCH + FORM})
    a = found.points.get("a")
    if a is not None and found.p is not None:
        row.update({"energy": a.energy, "reduced_energy": a.row.get("reduced_energy", a.energy),
                    "f": a.row.get("f"), "c0_reduced": a.row.get("c0_reduced")})
    row["states"] = states(found)
    if found.converged and (found.gap or 0.0) <= GAP_ACCEPT:
        row["outcome"] = "converged"
    elif found.converged:  # both certified, but not at one energy: the location is as good as the gap
        a, b = found.points["a"], found.points["b"]
        slope = None if a.dE_dp is None or b.dE_dp is None else abs(a.dE_dp - b.dE_dp)
        dv = "" if not slope else f"; {param} uncertain by ~{abs(a.energy - b.energy) / slope:.2g}"
        row["outcome"] = "located_to_gap"
        row["reason"] = (f"|E_a - E_b| / |E| = {found.gap:.2g} after the Newton polish (> {GAP_ACCEPT:g}): a state "
                         f"changed between the samples{dv}")
    else:
        bad = next((found.points[x] for x in BRANCHES if x in found.points and not found.points[x].converged), None)
        row["outcome"] = (bad.row.get("outcome") if bad is not None else None) or "no_crossing"
        row["reason"] = found.reason
    tols = [found.points[x].row.get("certifiable_tol") for x in BRANCHES if x in found.points]
    tols = [t for t in tols if t is not None]
    row["certifiable_tol"] = max(tols) if tols else None
    return row


def states(found: Found) -> str | None:
    """The two states at a crossing in words, "a/b" (``verify.updown``): each its form (prolate,
    oblate, cup), "asymmetric" before it where it is not up-down symmetric, "torus" where its
    meridian does not reach the axis at two poles; None off the meridian mesh. The line is the
    prolate/oblate line D(c0) only where this reads "prolate/oblate"."""
    words = []
    for x in BRANCHES:
        s = found.points.get(x)
        if s is None or not s.converged or "symmetric" not in s.row:
            return None
        form = s.row.get("form") or ("torus" if s.row.get("pole_gap") is None else "other")
        words.append(form if s.row["symmetric"] else f"asymmetric {form}")
    return "/".join(words)


class LineStore:
    """The files of one transition line (module docstring); ``out`` None: rows in memory only."""

    def __init__(self, out: Path | None, meta: dict, disc, second: str, param: str, mesh_of=None):
        self.out, self.meta, self.disc, self.second, self.param = (None if out is None else Path(out)), meta, disc, \
            second, param
        self.mesh_of = mesh_of  # (nodes, triangles) -> the discretisation of a point with its own mesh
        self._rows: list[dict] = []
        self._phi: dict = {}
        self._disc: dict = {}
        if self.out is None:
            return
        outdir.make(out, "points")
        meta_path = self.out / "transition.json"
        if meta_path.exists():
            old = state.read_json(meta_path, ADVICE)
            if old != meta:
                diff = sorted(k for k in set(old) | set(meta) if old.get(k) != meta.get(k))
                raise InputError("--out", f"{self.out} holds a transition line with other {', '.join(diff)}; "
                                 "give another directory (nothing there was changed)")
        self._last = -1
        self._rows = self._read()
        if not meta_path.exists():
            write_json(meta_path, meta)

    @property
    def csv_path(self) -> Path:
        return self.out / "transition_line.csv"

    def _read(self) -> list[dict]:
        path = self.csv_path
        found = state.read_csv(path, lambda h: None if h == COLUMNS else f"{len(h)} columns, the first "
                               f"{(h or [''])[0][:30]!r}", self._check_row, ADVICE)
        if found is None:
            path.write_text(",".join(COLUMNS) + "\n")
            return []
        _, rows, repaired = found
        if repaired is not None:  # a kill mid-write: the torn line is cut off
            tmp = path.with_name(path.name + ".tmp")
            tmp.write_text(repaired)
            os.replace(tmp, path)
        return [parse(r) for r in rows]

    def _check_row(self, row: dict, index: int) -> str | None:
        """Typed columns, and ``row`` (the plan index) increasing: a direction that stopped leaves
        its later indices out."""
        why = state.typed_row(row, INTS, FLOATS, BOOLS)
        if why is None and (row["row"] == "" or int(row["row"]) <= self._last):
            return f"row = {row['row'][:40]!r}, expected an index above {self._last} (the rows in order)"
        if why is None:
            self._last = int(row["row"])
        return why

    def rows(self) -> list[dict]:
        return list(self._rows)

    def _path(self, i: int, x: str) -> Path:
        return self.out / "points" / f"row-{i:04d}-{x}.npz"

    def phi(self, i: int, x: str) -> np.ndarray:
        return self.field(i, x)[1]

    def field(self, i: int, x: str) -> tuple[object | None, np.ndarray]:
        """(its own mesh or None: the line's ``disc``, phi) of branch x at row i."""
        if self.out is None:
            return self._disc.get((i, x)), self._phi[(i, x)]
        path = self._path(i, x)
        if not path.exists():
            raise InputError("--out", f"{self.out}: the field of row {i} ({x}) is missing; the line cannot "
                             "resume there (give another directory)")
        if (i, x) not in self._disc:
            data = fields.read(path)
            tri = data.get("triangles")
            self._disc[(i, x)] = None if tri is None or self.mesh_of is None else self.mesh_of(data["nodes"], tri)
            self._phi[(i, x)] = np.asarray(data["phi"], float)
        return self._disc[(i, x)], self._phi[(i, x)]

    def plotted(self, i: int, x: str):
        """The phase figure's field of branch x at row i: phi, or (its mesh, phi)."""
        disc, phi = self.field(i, x)
        return phi if disc is None else (disc, phi)

    def found(self, i: int, r: dict) -> Found:
        """The crossing of a recorded (certified) row, with both fields: the next predictor's data."""
        pts = {}
        for x in BRANCHES:
            lam = None if r.get(f"{x}_lambda_volume") is None else (r[f"{x}_lambda_volume"], r[f"{x}_lambda_area"])
            disc, phi = self.field(i, x)
            pts[x] = Sample(r["target"], r["value"], phi, r[f"{x}_energy"], True, lam,
                            r.get(f"{x}_dE_dp"), r.get(f"{x}_dE_dq"), {}, disc)
        return Found(r["value"], r["target"], pts, r["predicted"], r["samples"], r["solves"], r["wall_time_s"])

    def append(self, i: int, direction: str, found: Found) -> dict:
        """Write both fields (a certified crossing's), then the row; the row, parsed."""
        row = row_of(i, direction, found, self.second, self.param)
        text = {k: cell_text(row.get(k)) for k in COLUMNS}
        if found.converged:
            for x in BRANCHES:
                s = found.points[x]
                if self.out is None:
                    self._phi[(i, x)], self._disc[(i, x)] = np.asarray(s.phi, float), s.disc
                else:  # a point on its own mesh: with its triangles (``mesh_of`` rebuilds it)
                    fields.write(self._path(i, x), "branch-point", s.phi, s.disc or self.disc, p=found.p,
                                 triangles=None if s.disc is None else s.disc.mesh.t)
        self._rows.append(parse(text))
        if self.out is not None:
            buf = io.StringIO()
            csv.DictWriter(buf, COLUMNS, lineterminator="\n").writerow(text)
            with interrupt.deferred(), open(self.csv_path, "a", newline="") as fh:  # a row is written whole
                fh.write(buf.getvalue())
                fh.flush()
                os.fsync(fh.fileno())
        return self._rows[-1]
