"""``branch.csv``, the snapshots of every point, and the resume after a kill.

Layout of ``out``: ``branch.json`` (what was asked: scene, parameter, end, step; a resume under
other arguments is refused, so nothing computed is overwritten), ``branch.csv`` (one row per
attempt, appended and fsynced as each finishes; a rerun with ``--to`` further in the same
direction extends the run from its last point, ``extends``), ``points/point-NNNN.npz`` (phi, the parameter, the
grid) and ``points/point-NNNN.vtu`` (ParaView), written *before* their row: a row in the file always
has its snapshot. A kill leaves at most a torn last line, which the resume cuts off, so no row is
lost or written twice; snapshots without a row are overwritten by the rerun.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

import numpy as np

from vesicle_opt.errors import InputError
from vesicle_opt.io import fields
from vesicle_opt.io.files import load_npz, save_npz, write_json

COLUMNS = ["point", "branch", "param", "target", "reduced_volume", "c0", "energy", "reduced_energy",
           "lambda_volume", "lambda_area", "dE_dp", "envelope_residual", "second_order",
           "second_order_min_eigenvalue", "event", "topology", "components", "wraps", "converged",
           "accepted", "outcome", "status", "iterations", "solves", "corrector", "arc_condition", "deviation",
           "wall_time_s", "epsilon", "n", "h", "alpha", "beta", "volume", "area", "kkt_residual",
           "arc_step", "arc_theta", "sharp_reduced_energy", "second_order_excluded", "rotation_rayleigh",
           "restarted"]


RESULT_KEYS = ("stopped",)  # keys of branch.json written at the end (not part of what was asked)


def extends(old: dict, new: dict) -> bool:
    """``new`` asks for the run ``old`` (branch.json) with ``to`` further in the same direction
    (the sign of the first step); its own step may differ (its default depends on ``to``)."""
    same = all(old.get(k) == new.get(k) for k in set(old) | set(new) if k not in ("to", "step"))
    return same and (float(new["to"]) - float(old["to"])) * float(old["step"]) > 0


def _text(v) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        return repr(float(v)) if math.isfinite(v) else ""
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return str(v)


def parse(row: dict) -> dict:
    """A CSV row with numbers and booleans back in their types ('' -> None)."""
    out = {}
    for k, v in row.items():
        if v == "" or v is None:
            out[k] = None
        elif v in ("true", "false"):
            out[k] = v == "true"
        else:
            try:
                out[k] = int(v) if k in ("point", "branch", "iterations", "solves", "components", "n") else float(v)
            except ValueError:
                out[k] = v
    return out


class Store:
    """The files of one branch run (module docstring). ``out`` None: rows kept in memory only."""

    def __init__(self, out: Path | None, meta: dict, snapshots: bool = True):
        self.out = None if out is None else Path(out)
        self.snapshots = snapshots and self.out is not None
        self._rows: list[dict] = []
        self._fields: dict[int, np.ndarray] = {}
        self._modes: dict[int, np.ndarray] = {}
        self.meta = meta
        if self.out is None:
            return
        try:
            (self.out / "points").mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError("--out", f"cannot use {str(out)!r} as the output directory "
                             f"({exc.strerror or exc})") from None
        meta_path = self.out / "branch.json"
        if meta_path.exists():
            old = {k: v for k, v in json.loads(meta_path.read_text()).items() if k not in RESULT_KEYS}
            if old != meta and extends(old, meta):  # --to further on: the same branch goes on
                meta = {**meta, "step": old["step"]}  # with its own first step (step control unchanged)
                write_json(meta_path, meta)
            elif old != meta:
                diff = sorted(k for k in set(old) | set(meta) if old.get(k) != meta.get(k))
                raise InputError("--out", f"{self.out} holds a branch run with other {', '.join(diff)}; "
                                 "give another directory, or a --to further in the same direction "
                                 "(nothing there was changed)")
        else:
            write_json(meta_path, meta)
        self.meta = meta  # what this run does (an extension keeps the stored first step)
        self._rows = self._repair()

    @property
    def csv_path(self) -> Path:
        return self.out / "branch.csv"

    def _repair(self) -> list[dict]:
        path = self.csv_path
        if not path.exists() or path.stat().st_size == 0:
            path.write_text(",".join(COLUMNS) + "\n")
            return []
        text = path.read_text()
        if not text.endswith("\n"):  # a kill mid-write: the torn line is cut off
            text = text[: text.rfind("\n") + 1]
            tmp = path.with_name(path.name + ".tmp")
            tmp.write_text(text)
            os.replace(tmp, path)
        return [parse(r) for r in csv.DictReader(io.StringIO(text))]

    def finish(self, stopped: dict) -> None:
        """Record in branch.json why each branch stopped (``{"0": "reached", ...}``)."""
        if self.out is None:
            return
        path = self.out / "branch.json"
        meta = json.loads(path.read_text())
        meta["stopped"] = {str(k): v for k, v in stopped.items()}
        write_json(path, meta)

    def rows(self) -> list[dict]:
        return list(self._rows)

    def phi(self, point: int) -> np.ndarray:
        if point in self._fields:
            return self._fields[point]
        data = load_npz(self.out / "points" / f"point-{point:04d}.npz")
        if data is None:
            raise InputError("--out", f"{self.out}: the snapshot of point {point} is missing; "
                             "the run cannot resume there (give another directory)")
        return np.asarray(data["phi"], float)

    def mode(self, point: int) -> np.ndarray | None:
        """The critical eigenvector stored with a saddle point (None when none was)."""
        if self.out is None:
            return self._modes.get(point)
        data = load_npz(self.out / "points" / f"point-{point:04d}.npz")
        return None if data is None or "mode" not in data else np.asarray(data["mode"], float)

    def seed(self, branch: int) -> dict | None:
        return None if self.out is None else load_npz(self.out / "points" / f"seed-{branch}.npz")

    def save_seed(self, branch: int, p: float, phi: np.ndarray) -> None:
        if self.out is not None:
            save_npz(self.out / "points" / f"seed-{branch}.npz", p=p, phi=phi)

    def append(self, row: dict, result=None) -> None:
        """Write the snapshot of ``row['point']`` (when there is a finite field), then the row."""
        point = int(row["point"])
        if result is not None and np.all(np.isfinite(result.phi)):
            mu = row.get("second_order_min_eigenvalue")
            mode = result.history.get("second_order_mode") if mu is not None and mu < 0 else None
            extra = {} if mode is None else {"mode": np.asarray(mode, float)}
            if self.out is None:
                self._fields[point] = np.asarray(result.phi, float)
                if mode is not None:
                    self._modes[point] = extra["mode"]
            else:
                disc = result.disc  # the npz layout of io.fields (format version)
                fields.write(self.out / "points" / f"point-{point:04d}.npz", "branch-point", result.phi, disc,
                             p=row["target"], **extra)
                if self.snapshots:
                    _write_vtk(self.out / "points" / f"point-{point:04d}.vtu", disc, result.phi)
        self._rows.append(parse({k: _text(row.get(k)) for k in COLUMNS}))
        if self.out is None:
            return
        buf = io.StringIO()
        csv.DictWriter(buf, COLUMNS, extrasaction="ignore", lineterminator="\n").writerow(
            {k: _text(row.get(k)) for k in COLUMNS})
        with open(self.csv_path, "a", newline="") as fh:
            fh.write(buf.getvalue())
            fh.flush()
            os.fsync(fh.fileno())


def _write_vtk(path: Path, disc, phi) -> None:
    # io.output loads meshio and matplotlib: only when snapshots are written (module-local import
    # on purpose, so that an in-memory branch does not pay ~0.4 s for them)
    from vesicle_opt.io.output import write_vtk
    write_vtk(path, disc, phi)
