"""Atomic files: summary.json and npz (checkpoints, fields shared by study cases). numpy only."""

from __future__ import annotations

import json
import math
import os
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np


def package_version() -> str:
    """The installed vesicle_opt version (``summary.json``'s ``version``; ``vesicle-opt --version``)."""
    try:
        return version("vesicle_opt")
    except PackageNotFoundError:  # a source tree on sys.path without an install
        return "unknown"


def json_safe(x):
    """``x`` with every non-finite float as None (JSON null): ``write_json`` refuses NaN, which a
    summary uses for "too few levels to extrapolate"."""
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    return x


def write_json(path: Path, data: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")
    tmp.replace(path)  # atomic: a kill never leaves half a summary


def save_npz(path: Path, **arrays) -> None:
    """``np.savez`` to a process-private temporary file, then ``os.replace`` onto ``path``: a kill
    leaves the previous file intact, never half a file (checkpoints, fields shared by study cases)."""
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
