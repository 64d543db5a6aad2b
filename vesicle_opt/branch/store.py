"""``branch.csv``, the snapshots of every point, and the resume after a kill.

Layout of ``out``: ``branch.json`` (what was asked: scene, parameter, end, step; a resume under
other arguments is refused, so nothing computed is overwritten), ``branch.csv`` (one row per
attempt, appended and fsynced as each finishes; a rerun with ``--to`` further in the same
direction extends the run from its last point, ``extends``), ``points/point-NNNN.npz`` (phi, the parameter, the
grid) and ``points/point-NNNN.vtu`` (ParaView), written *before* their row: a row in the file always
has its snapshot. A kill leaves at most a torn last line, which the resume cuts off, so no row is
lost or written twice; snapshots without a row are overwritten by the rerun.

The last column, ``row_crc``, is the CRC-32 of the row's other values (``checksum``; ``wall_time_s``
left out, so a rerun's rows are equal to the first run's): a character changed inside a row (a
swapped digit that still reads as a number) is found on resume and on read-back, and refused with
the line named. A ``branch.csv`` of the previous column set (without it) is resumed: its rows,
checked as before, are rewritten with their checksums.
"""

from __future__ import annotations

import csv
import io
import math
import os
import zlib
from pathlib import Path

import numpy as np

from vesicle_opt.errors import InputError
from vesicle_opt.io import fields, interrupt, outdir, state
from vesicle_opt.io.files import load_npz, save_npz, write_json

COLUMNS = ["point", "branch", "param", "target", "reduced_volume", "c0", "energy", "reduced_energy",
           "lambda_volume", "lambda_area", "dE_dp", "envelope_residual", "second_order",
           "second_order_min_eigenvalue", "event", "topology", "components", "wraps", "converged",
           "accepted", "outcome", "status", "iterations", "solves", "corrector", "arc_condition", "deviation",
           "wall_time_s", "epsilon", "n", "h", "alpha", "beta", "volume", "area", "kkt_residual",
           "arc_step", "arc_theta", "sharp_reduced_energy", "second_order_excluded", "rotation_rayleigh",
           "restarted",
           # the tree of branches (``branch.tree``): the branch a branch left (empty for the root and for
           # a deflated one), its located events (``branch.events``) and the least few eigenvalues
           "parent", "second_order_eigenvalues", "second_order_errors", "index", "detected_at",
           "critical", "critical_eigenvalue", "critical_error", "critical_mode", "located_by", "bracket",
           "f", "c0_reduced",  # f = F/8 pi kappa, c0_reduced = C0 R0 (geometry.literature_units; 3D)
           # why a point failed (verify.failure) and the shape check (verify.shape)
           "reason", "certifiable_tol", "shape", "shape_volume_gap", "bulk_volume_share",
           # the p-free Newton-Krylov corrector (branch.nk_free): GMRES iterations of each bordered Newton step
           "krylov_iterations",
           "row_crc"]  # the row's checksum (module docstring), always last
CHECKSUM = "row_crc"
UNSUMMED = ("wall_time_s", CHECKSUM)  # the values the checksum leaves out (a timing differs between reruns)

INTS = ("point", "branch", "iterations", "solves", "components", "n", "parent", "index", "detected_at", "critical")
BOOLS = ("converged", "accepted", "restarted")
FLOATS = ("target", "reduced_volume", "c0", "energy", "reduced_energy", "lambda_volume", "lambda_area", "dE_dp",
          "envelope_residual", "second_order_min_eigenvalue", "arc_condition", "deviation", "wall_time_s",
          "epsilon", "h", "alpha", "beta", "volume", "area", "kkt_residual", "arc_step", "arc_theta",
          "sharp_reduced_energy", "rotation_rayleigh", "critical_eigenvalue", "critical_error", "f", "c0_reduced",
          "certifiable_tol", "shape_volume_gap", "bulk_volume_share")
ADVICE = "move it away or give another --out (nothing there was changed)"


RECENT_BYTES = 64 << 20  # fields kept in memory after a read, oldest out first (16 of 500 k nodes)


RESULT_KEYS = ("stopped",)  # keys of branch.json written at the end (not part of what was asked)


def extends(old: dict, new: dict) -> bool:
    """``new`` asks for the run ``old`` (branch.json) with ``to`` further in the same direction
    (the sign of the first step); its own step may differ (its default depends on ``to``)."""
    same = all(old.get(k) == new.get(k) for k in set(old) | set(new) if k not in ("to", "step"))
    try:
        return same and (float(new["to"]) - float(old["to"])) * float(old["step"]) > 0
    except (KeyError, TypeError, ValueError):  # a branch.json without a numeric to / step: another run's
        return False


def cell_text(v) -> str:
    """A value as a CSV cell holds it: '' for None and non-finite numbers, true/false, repr of floats."""
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        return repr(float(v)) if math.isfinite(v) else ""
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return str(v)


TEXT = ("second_order_eigenvalues", "second_order_errors", "critical_mode", "krylov_iterations", CHECKSUM)
# ';'-joined numbers, a file name, the checksum's hex digits (never parsed as a number)


def checksum(texts: dict) -> str:
    """The ``row_crc`` of a row given as its CSV texts: CRC-32 (hex) of the values of COLUMNS but
    ``UNSUMMED``, in order, joined by the unit separator (no value holds it)."""
    data = "\x1f".join(texts.get(k) or "" for k in COLUMNS if k not in UNSUMMED)
    return f"{zlib.crc32(data.encode('utf-8')):08x}"


def texts(row: dict) -> dict:
    """A row's CSV texts (``_text`` of each column), its checksum filled in."""
    out = {k: cell_text(row.get(k)) for k in COLUMNS if k != CHECKSUM}
    return {**out, CHECKSUM: checksum(out)}


def parse(row: dict) -> dict:
    """A CSV row with numbers and booleans back in their types ('' -> None)."""
    out = {}
    for k, v in row.items():
        if v == "" or v is None:
            out[k] = None
        elif k in TEXT:
            out[k] = v
        elif v in ("true", "false"):
            out[k] = v == "true"
        else:
            try:
                out[k] = int(v) if k in INTS else float(v)
            except ValueError:
                out[k] = v
    return out


def check_row(row: dict, index: int) -> str | None:
    """What is wrong with a row of branch.csv (its types; the points numbered 0, 1, ...): the rule
    of a resume (``Store``) and of a read-back (``readback.load_branch``)."""
    if row["point"] != str(index):
        return f"point = {row['point'][:40]!r}, expected {index} (the rows are the points in order)"
    why = state.typed_row(row, INTS, FLOATS, BOOLS)
    if why is None and CHECKSUM in row and row[CHECKSUM] != checksum(row):
        why = f"{CHECKSUM} = {row[CHECKSUM][:12]!r} does not match the row's values (a changed character)"
    return why


class Store:
    """The files of one branch run (module docstring). ``out`` None: rows kept in memory only."""

    def __init__(self, out: Path | None, meta: dict, snapshots: bool = True):
        self.out = None if out is None else Path(out)
        self.snapshots = snapshots and self.out is not None
        self._rows: list[dict] = []
        self._fields: dict[int, np.ndarray] = {}
        self._modes: dict[int, np.ndarray] = {}
        self._recent: dict[int, np.ndarray] = {}  # fields read back (the tree rereads them)
        self.meta = meta
        if self.out is None:
            return
        outdir.make(out, "points")
        meta_path = self.out / "branch.json"
        old = None  # the stored run's arguments (none: a new run)
        if meta_path.exists():
            old = {k: v for k, v in state.read_json(meta_path, ADVICE).items()  # checked (io.state)
                   if k not in RESULT_KEYS}
            if old != meta and extends(old, meta):  # --to further on: the same branch goes on
                meta = {**meta, "step": old["step"]}  # with its own first step (step control unchanged)
            elif old != meta:
                diff = sorted(k for k in set(old) | set(meta) if old.get(k) != meta.get(k))
                raise InputError("--out", f"{self.out} holds a branch run with other {', '.join(diff)}; "
                                 "give another directory, or a --to further in the same direction "
                                 "(nothing there was changed)")
        self.meta = meta  # what this run does (an extension keeps the stored first step)
        self._rows = self._repair()  # checked before branch.json is written (a new run, or an extension)
        if not meta_path.exists() or old != meta:
            write_json(meta_path, meta)
        self._note()

    def _note(self) -> None:
        """Where the run is, for an interrupt's message (``io.interrupt``): it resumes from here."""
        interrupt.note(f"at point {len(self._rows)} of the branch ({len(self._rows)} rows in {self.csv_path})",
                       resume=True)

    @property
    def csv_path(self) -> Path:
        return self.out / "branch.csv"

    def _repair(self) -> list[dict]:
        """The rows of branch.csv, read through the checked loader (``io.state``): a torn last line
        cut off (the file rewritten without it), anything else refused before any work."""
        path = self.csv_path
        found = state.read_csv(path, lambda h: None if h in (COLUMNS, COLUMNS[:-1]) else f"{len(h)} columns, "
                               f"the first {(h or [''])[0][:30]!r}", check_row, ADVICE)
        if found is None:
            path.write_text(",".join(COLUMNS) + "\n")
            return []
        header, rows, repaired = found
        if header != COLUMNS:  # the previous column set: the rows (checked) rewritten with their checksums
            buf = io.StringIO()
            writer = csv.DictWriter(buf, COLUMNS, lineterminator="\n")
            writer.writeheader()
            rows = [{**r, CHECKSUM: checksum(r)} for r in rows]
            writer.writerows(rows)
            repaired = buf.getvalue()
        if repaired is not None:  # a kill mid-write: the torn line is cut off (or the column added)
            tmp = path.with_name(path.name + ".tmp")
            tmp.write_text(repaired)
            os.replace(tmp, path)
        return [parse(r) for r in rows]

    def finish(self, stopped: dict) -> None:
        """Record in branch.json why each branch stopped (``{"0": "reached", ...}``)."""
        if self.out is None:
            return
        # self.meta is what branch.json holds (written, or checked equal, in __init__), less any
        # earlier "stopped": no re-read of the file is needed
        write_json(self.out / "branch.json", {**self.meta, "stopped": {str(k): v for k, v in stopped.items()}})

    def rows(self) -> list[dict]:
        return list(self._rows)

    def phi(self, point: int) -> np.ndarray:
        if point in self._fields:
            return self._fields[point]
        if point in self._recent:  # the snapshot of a recorded row does not change
            return self._recent[point]
        data = load_npz(self.out / "points" / f"point-{point:04d}.npz")
        if data is None:
            raise InputError("--out", f"{self.out}: the snapshot of point {point} is missing; "
                             "the run cannot resume there (give another directory)")
        phi = np.asarray(data["phi"], float)
        if point < len(self._rows):
            self._recent[point] = phi
            while sum(v.nbytes for v in self._recent.values()) > RECENT_BYTES:
                self._recent.pop(next(iter(self._recent)))
        return phi

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

    def append(self, row: dict, result=None, mode: np.ndarray | None = None) -> None:
        """Write the snapshot of ``row['point']`` (when there is a finite field; with ``mode``, or
        the check's least eigenvector at a saddle, as ``mode``), then the row."""
        point = int(row["point"])
        if result is not None and np.all(np.isfinite(result.phi)):
            mu = row.get("second_order_min_eigenvalue")
            if mode is None:
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
        line = texts(row)
        self._rows.append(parse(line))
        if self.out is None:
            return
        buf = io.StringIO()
        csv.DictWriter(buf, COLUMNS, extrasaction="ignore", lineterminator="\n").writerow(line)
        with interrupt.deferred(), open(self.csv_path, "a", newline="") as fh:  # a row is written whole
            fh.write(buf.getvalue())
            fh.flush()
            os.fsync(fh.fileno())
        self._note()


def _write_vtk(path: Path, disc, phi) -> None:
    # io.output loads meshio and matplotlib: only when snapshots are written (module-local import
    # on purpose, so that an in-memory branch does not pay ~0.4 s for them)
    from vesicle_opt.io.output import write_vtk
    write_vtk(path, disc, phi)
