"""Shared helpers of the flow studies: build a scene's flow pieces, fields beside the CSV.

The study rows go through ``vesicle_opt.studies.runner`` (one appending writer, resumable); the
helpers here save the large fields a case shares with later cases (npz, written atomically so a
kill never leaves a half file) and write the small *derived* CSVs that ``main`` recomputes from
the finished rows on every run. Shared fields go through ``vesicle_opt.io.files.save_npz`` /
``load_npz`` (atomic).
"""

from __future__ import annotations

import logging
import csv
import os
from pathlib import Path

from vesicle_opt import scene as S
from vesicle_opt.flows.api import build_model, initial_field, make_scheme

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)


def setup(name: str, sets: list[str]):
    sc = S.load(name, sets)
    md = build_model(sc)
    return sc, md, make_scheme(sc, md), initial_field(sc, md)


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


def report_failures(rows: list[dict]) -> bool:
    """Print the rows ``runner`` recorded for cases that raised (status ``error: ...``);
    True when there is one (the study then returns 1)."""
    bad = [r for r in rows if str(r.get("status", "")).startswith("error")]
    for r in bad:
        log.info(f"{r['case']}: {r['status']}")
    return bool(bad)
