"""Shared helpers of the flow studies: build a scene's flow pieces, fields beside the CSV.

The study rows go through ``vesicle_opt.study_runner`` (one appending writer, resumable); the
helpers here save the large fields a case shares with later cases (npz, written atomically so a
kill never leaves a half file) and write the small *derived* CSVs that ``main`` recomputes from
the finished rows on every run.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from vesicle_opt import scene as S
from vesicle_opt.cli import resolve_scene
from vesicle_opt.flows.run import build_model, initial_field, make_scheme


def setup(name: str, sets: list[str]):
    sc = S.load(resolve_scene(name), sets)
    md = build_model(sc)
    return sc, md, make_scheme(sc, md), initial_field(sc, md)


def save_npz(path: Path, **arrays) -> None:
    """``np.savez`` to a process-private temporary file, then ``os.replace`` onto ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    os.replace(tmp, path)


def load_npz(path: Path) -> dict | None:
    """The arrays of ``path`` (0-d arrays as Python scalars), or None when it does not exist."""
    if not Path(path).exists():
        return None
    with np.load(path) as z:
        return {k: (z[k].item() if z[k].ndim == 0 else z[k]) for k in z.files}


def write_derived_csv(path: Path, rows: list[dict], columns: list[str] | None = None) -> None:
    """A derived CSV (recomputed from the study rows each run), replaced atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    keys = columns or list(dict.fromkeys(k for r in rows for k in r))
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


def failed(rows: list[dict]) -> list[dict]:
    """The rows ``study_runner`` recorded for cases that raised (status ``error: ...``)."""
    return [r for r in rows if str(r.get("status", "")).startswith("error")]
