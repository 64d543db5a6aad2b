"""Warm starts: a field phi of an earlier solve carried onto this discretisation.

A start comes as a ``phi.npz`` written by ``vesicle-opt solve`` / ``flow`` (``initial.shape =
"file"`` or ``x0=path``), an earlier ``Result`` (its ``phi`` and ``disc``), or a plain array of
nodal values. On the same mesh it is used as it is. When both meshes are periodic tensor grids of
the same box (FD, Fourier spectral, periodic P1: nodes x_j = lo + j h in C order) and only the
number of cells differs, the field is carried over by its trigonometric interpolant (Fourier
interpolation along each axis, ``mesh.spectral.resample``): exact for band-limited fields and
spectrally accurate for a resolved tanh profile (Section 5's grids). Anything else (another box,
an unstructured mesh, natural boundaries) is refused with one line naming both shapes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vesicle_opt.errors import InputError
from vesicle_opt.mesh.base import grid_points
from vesicle_opt.mesh.spectral import resample as fourier_resample  # noqa: F401 (re-exported)


def grid_of(nodes: np.ndarray, box) -> tuple[int, ...] | None:
    """The cell counts n of a periodic tensor grid lo + j (L/n) over ``box`` in C order whose
    nodes these are, or None when they are not such a grid."""
    nodes = np.asarray(nodes, float)
    if nodes.ndim != 2 or nodes.shape[1] != len(box):
        return None
    shape = []
    for d, (lo, hi) in enumerate(box):
        n = len(np.unique(np.round((nodes[:, d] - lo) / (hi - lo), 9)))
        shape.append(n)
    if int(np.prod(shape)) != nodes.shape[0]:
        return None
    axes = [lo + (hi - lo) / n * np.arange(n) for (lo, hi), n in zip(box, shape)]
    expected = grid_points(axes)
    scale = max(hi - lo for lo, hi in box)
    if not np.allclose(nodes, expected, rtol=0, atol=1e-9 * scale):
        return None
    return tuple(shape)


def _describe(nodes, n_values: int) -> str:
    """'24x24 grid' when the nodes form a tensor grid (of any box), else 'N nodes'."""
    nodes = np.asarray(nodes, float)
    if nodes.ndim == 2:
        shape = [len(np.unique(np.round(nodes[:, d], 9))) for d in range(nodes.shape[1])]
        if int(np.prod(shape)) == nodes.shape[0] == n_values:
            return "x".join(map(str, shape)) + " grid"
    return f"{n_values} nodes"


def carry(phi: np.ndarray, nodes: np.ndarray | None, disc, key: str, origin: str) -> np.ndarray:
    """phi (nodal values at ``nodes``, None: unknown) on ``disc``: as is on the same mesh,
    Fourier-resampled between periodic grids of the same box, else InputError naming both shapes."""
    phi = np.asarray(phi, float).ravel()
    if not np.all(np.isfinite(phi)):
        raise InputError(key, f"{origin} contains non-finite values")
    here = "x".join(map(str, disc.grid_shape)) + " grid" if disc.grid_shape else f"{disc.n_nodes} nodes"
    if phi.size == disc.n_nodes and (nodes is None or np.shape(nodes) == disc.nodes.shape
                                     and np.allclose(nodes, disc.nodes, rtol=0, atol=1e-9)):
        return phi
    src = None if nodes is None or disc.grid_shape is None else grid_of(nodes, disc.box)
    if src is None or grid_of(disc.nodes, disc.box) != tuple(disc.grid_shape):
        there = f"{phi.size} values" if nodes is None else _describe(nodes, phi.size)
        raise InputError(key, f"{origin} holds a field on {there}, this mesh is a {here}: a start "
                         f"from another mesh is resampled only between periodic grids of the same box")
    if phi.size != int(np.prod(src)):
        raise InputError(key, f"{origin} holds {phi.size} values for its {'x'.join(map(str, src))} grid")
    return fourier_resample(phi, src, disc.grid_shape)


def load_warm_start(path: str | Path, disc, key: str = "initial.file") -> np.ndarray:
    """phi from a phi.npz of an earlier solve, carried onto ``disc`` (module docstring)."""
    try:
        with np.load(path) as data:
            phi = np.asarray(data["phi"], float)
            nodes = np.asarray(data["nodes"], float) if "nodes" in data.files else None
    except FileNotFoundError:
        raise InputError(key, f"file not found: {path}") from None
    except Exception as exc:  # zip/pickle/key errors of a corrupt or foreign file, a directory
        raise InputError(key, f"{path} is not a phi.npz written by vesicle-opt ({type(exc).__name__})") from None
    return carry(phi, nodes, disc, key, str(path))


def start_field(x0, disc, key: str = "x0") -> np.ndarray | None:
    """A warm start given to the Python API (``solve(..., x0=)``, ``flow(..., x0=)``) as phi on
    ``disc``: None, a path to a phi.npz, an earlier Result / FlowResult (its ``phi`` on its own
    ``disc`` or ``model.disc``), or an array of nodal values (returned as given, for the caller's
    own size checks: an NLP vector is longer than phi)."""
    if x0 is None:
        return None
    if isinstance(x0, (str, Path)):
        return load_warm_start(x0, disc, key)
    src = getattr(x0, "disc", None) or getattr(getattr(x0, "model", None), "disc", None)
    if hasattr(x0, "phi") and src is not None:
        return carry(x0.phi, src.nodes, disc, key, "the earlier result")
    try:
        return np.asarray(x0.phi if hasattr(x0, "phi") else x0, float).ravel()
    except (TypeError, ValueError):
        raise InputError(key, f"expected a field (array of nodal values), a phi.npz path or a Result, got "
                         f"{type(x0).__name__}") from None
