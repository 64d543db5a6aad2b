"""Files a viewer opens: complete periodic grids (VTK ImageData ``.vti``), meshes (``.vtu`` via
meshio) and ParaView time series (``.pvd``).

A periodic grid of n cells per side stores n nodes per side (x_i = lo + i h, i < n); node n is
node 0 again. ``wrapped`` appends that last row/plane, so the written image covers the whole box
[lo, hi] (a viewer otherwise shows a missing strip of one cell at the far edges). ImageData orders
points x fastest; the grid field F[i, j, k] (first index along x) is written in Fortran order.
The ``.vti`` and ``.pvd`` files are plain XML (VTK's XML formats, ASCII data): meshio writes
unstructured meshes but no ImageData, so these two small writers are here.
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np


def wrapped(disc, phi: np.ndarray) -> np.ndarray:
    """The grid field with its periodic copy appended along every axis (shape n_i + 1)."""
    F = np.asarray(phi, float).reshape(disc.grid_shape)
    return np.pad(F, [(0, 1)] * F.ndim, mode="wrap")


def grid_geometry(disc) -> tuple[np.ndarray, np.ndarray]:
    """(origin, spacing) of a periodic grid: the box's lower corner and h = (hi - lo) / n per axis."""
    lo = np.array([b[0] for b in disc.box], float)
    hi = np.array([b[1] for b in disc.box], float)
    return lo, (hi - lo) / np.array(disc.grid_shape, float)


def _atomic_text(path: Path, text: str) -> None:
    tmp = Path(path).with_name(f"{Path(path).name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    tmp.replace(path)


def write_vti(path: Path, disc, fields: dict[str, np.ndarray]) -> None:
    """Nodal fields of a periodic grid as a complete ImageData file (2D grids as one z-layer)."""
    arrays = {name: wrapped(disc, f) for name, f in fields.items()}
    shape = next(iter(arrays.values())).shape
    origin, spacing = grid_geometry(disc)
    if len(shape) == 2:
        origin, spacing, shape = np.append(origin, 0.0), np.append(spacing, 1.0), shape + (1,)
    extent = " ".join(f"0 {k - 1}" for k in shape)
    body = []
    for name, F in arrays.items():
        values = " ".join(repr(float(v)) for v in F.ravel(order="F"))
        body.append(f'        <DataArray type="Float64" Name={quoteattr(name)} format="ascii">{values}</DataArray>')
    text = ('<?xml version="1.0"?>\n'
            '<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian">\n'
            f'  <ImageData WholeExtent="{extent}" Origin="{" ".join(map(repr, map(float, origin)))}" '
            f'Spacing="{" ".join(map(repr, map(float, spacing)))}">\n'
            f'    <Piece Extent="{extent}">\n'
            f'      <PointData Scalars={quoteattr(next(iter(arrays)))}>\n' + "\n".join(body) + "\n"
            '      </PointData>\n      <CellData/>\n    </Piece>\n  </ImageData>\n</VTKFile>\n')
    _atomic_text(path, text)


def write_pvd(path: Path, entries: list[tuple[float, str]]) -> None:
    """A ParaView collection: one DataSet per (time, file relative to ``path``'s folder), in order."""
    rows = "\n".join(f'    <DataSet timestep="{t!r}" part="0" file={quoteattr(f)}/>' for t, f in entries)
    _atomic_text(path, '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                 + rows + "\n  </Collection>\n</VTKFile>\n")


def read_vti(path: Path) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """(fields as arrays indexed [i, j(, k)], origin, spacing) of a ``write_vti`` file (ASCII only)."""
    import xml.etree.ElementTree as ET  # a reader for tests and users; the writer needs none of it
    root = ET.parse(path).getroot()
    img = root.find("ImageData")
    ext = [int(v) for v in img.get("WholeExtent").split()]
    shape = tuple(ext[2 * d + 1] - ext[2 * d] + 1 for d in range(3))
    fields = {a.get("Name"): np.array(a.text.split(), float).reshape(shape, order="F")
              for a in img.iter("DataArray")}
    return fields, np.array(img.get("Origin").split(), float), np.array(img.get("Spacing").split(), float)
