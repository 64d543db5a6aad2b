"""The one ``.npz`` layout of a field (format version 1): ``phi.npz`` of ``solve`` and ``flow``, the
flow's ``snapshots/phi_JJJ.npz`` and the branch's ``points/point-NNNN.npz``.

Every file holds the keys of ``KEYS`` marked "always"; the others where they apply. ``nodes`` are
the coordinates of phi's entries in the order of phi (on periodic grids the flattened C-order grid,
the wrap row/plane excluded), so a field can be read without the scene that made it and resampled
onto another grid of the same box (``model.warm_start``). ``read`` also accepts the files written
before the format had a version (``format_version`` 0: solve's ``phi, nodes[, w]``, flow's ``phi,
nodes, t``, branch points' ``phi, p, grid_shape, box[, mode]``), filling in what it can.

numpy only; atomic writes through ``io.files.save_npz``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from vesicle_opt.errors import InputError, StateFileError
from vesicle_opt.io import state
from vesicle_opt.io.files import save_npz

FORMAT_VERSION = 1
KINDS = ("solve", "flow", "flow-snapshot", "branch-point")

# key -> (in which files, meaning); the docs' file-format page is generated from this table
KEYS: dict[str, tuple[str, str]] = {
    "format_version": ("always", "int, the layout's version (1); files without it are version 0"),
    "kind": ("always", f"str, which output wrote it: {', '.join(KINDS)}"),
    "phi": ("always", "float (n_nodes,), the phase field at the nodes (+1 inside, -1 outside)"),
    "nodes": ("always", "float (n_nodes, dim), the node coordinates, in phi's order"),
    "grid_shape": ("always", "int (dim,), the periodic or mirror grid's shape; empty (shape (0,)) on a mesh"),
    "box": ("always", "float (dim, 2), the box [lo, hi] per axis (one mirror cell on mirror grids)"),
    "mirror_cells": ("always", "int, 2^dim on a mirror grid (phi is one mirror cell of the vesicle, "
                     "centred at the corner lo), else 1"),
    "w": ("solve, mixed formulations", "float (n_nodes,), the auxiliary field w of the mixed form"),
    "t": ("flow, flow-snapshot", "float, the flow's time of phi"),
    "p": ("branch-point", "float, the branch parameter's value at the point (branch.csv's target)"),
    "mode": ("branch-point at a saddle", "float (n_nodes,), the critical eigenvector (M-normalised)"),
    "triangles": ("branch-point on an interface-refined meridian mesh (each point has its own)",
                  "int (3, n_triangles), the mesh's triangles (node indices into nodes)"),
}


def arrays(kind: str, phi: np.ndarray, disc, **extra) -> dict:
    """The arrays of one file of ``kind`` (module docstring); ``extra``: w, t, p, mode, triangles."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    unknown = set(extra) - set(KEYS)
    if unknown:
        raise ValueError(f"keys outside the npz layout: {sorted(unknown)}")
    grid = np.asarray(disc.grid_shape if disc.grid_shape is not None else (), int)
    out = {"format_version": np.int64(FORMAT_VERSION), "kind": np.str_(kind),
           "phi": np.asarray(phi, float), "nodes": np.asarray(disc.nodes, float),
           "grid_shape": grid, "box": np.asarray(disc.box, float),
           "mirror_cells": np.int64(2**disc.dim if getattr(disc, "kind", None) == "cosine" else 1)}
    out.update({k: np.asarray(v, np.int64 if k == "triangles" else float) for k, v in extra.items() if v is not None})
    return out


def write(path: Path, kind: str, phi: np.ndarray, disc, *, compressed: bool = False, **extra) -> None:
    """Write ``arrays(kind, phi, disc, **extra)`` to ``path`` atomically (``io.files.save_npz``);
    ``compressed``: ``np.savez_compressed`` (the flow's files, as before)."""
    data = arrays(kind, phi, disc, **extra)
    if compressed:  # a hidden temporary name: globs of phi_*.npz never see a half-written file
        path = Path(path)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **data)
        os.replace(tmp, path)
    else:
        save_npz(path, **data)


# the typed keys of a field file, checked on every read (io.state.read_npz): dtype kind, ndim
_TYPES = {"format_version": ("i", 0), "kind": ("U", 0), "nodes": ("x", 2), "grid_shape": ("i", 1),
          "box": ("x", 2), "mirror_cells": ("i", 0), "w": ("x", 1), "t": ("n", 0), "p": ("n", 0), "mode": ("x", 1),
          "triangles": ("i", 2)}
ADVICE = "not a field file written by vesicle-opt, or a damaged one (rerun the command that wrote it)"


def read(path: str | Path) -> dict:
    """The arrays of a field file as a dict (0-d arrays as Python scalars, ``kind`` a str), with
    ``format_version`` 0 for files written before the layout had one; InputError naming the path
    when it is missing, and its StateFileError (``io.state.read_npz``) when it is not such a file:
    not an npz, no ``phi``, a key of another type or dimension, or ``nodes`` / ``w`` / ``mode`` of
    another length than phi."""
    path = Path(path)
    if not path.exists():
        raise InputError("path", f"file not found: {path}")
    data = state.read_npz(path, {"phi": ("x", 1)}, ADVICE, "path", optional=_TYPES)
    n = data["phi"].size
    for name in ("nodes", "w", "mode"):
        if name in data and len(data[name]) != n:
            raise StateFileError(path, f"array {name!r} has {len(data[name])} entries, phi {n}; {ADVICE}", "path")
    tri = data.get("triangles")
    if tri is not None and (tri.shape[0] != 3 or (tri.size and (tri.min() < 0 or tri.max() >= n))):
        raise StateFileError(path, f"array 'triangles' of shape {tri.shape} does not index the {n} nodes; {ADVICE}",
                             "path")
    if data.get("kind", KINDS[0]) not in KINDS:
        raise StateFileError(path, f"kind {str(data['kind'])[:40]!r} is none of {', '.join(KINDS)}; {ADVICE}", "path")
    version = int(data.setdefault("format_version", 0))
    if version > FORMAT_VERSION:
        raise InputError("path", f"{path} has npz format_version {version}; this vesicle_opt reads "
                         f"up to {FORMAT_VERSION} (upgrade the package)")
    if version == 0:
        data.setdefault("kind", "branch-point" if "p" in data else "flow" if "t" in data else "solve")
        data.setdefault("mirror_cells", 1)  # unknown then; the field's own cell
    return data
