"""Shared helpers of the flow studies: build a scene's flow pieces, CSV writing."""

from __future__ import annotations

import csv
from pathlib import Path

from vesicle_opt import scene as S
from vesicle_opt.cli import resolve_scene
from vesicle_opt.flows.run import build_model, initial_field, make_scheme


def setup(name: str, sets: list[str]):
    sc = S.load(resolve_scene(name), sets)
    md = build_model(sc)
    return sc, md, make_scheme(sc, md), initial_field(sc, md)


def write_csv(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
