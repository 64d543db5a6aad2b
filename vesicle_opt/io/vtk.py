"""Files a viewer opens: complete periodic grids (VTK ImageData ``.vti``), meshes (``.vtu`` via
meshio) and ParaView time series (``.pvd``).

A periodic grid of n cells per side stores n nodes per side (x_i = lo + i h, i < n); node n is
node 0 again. ``wrapped`` appends that last row/plane, so the written image covers the whole box
[lo, hi] (a viewer otherwise shows a missing strip of one cell at the far edges). A mirror grid
(``mesh.cosine``: one mirror cell of a symmetric vesicle) is written as the whole vesicle: the
field reflected into the doubled box at its cell-centred nodes (``mirrored``, ``unfold``), so
ParaView needs no Reflect filter. ImageData orders
points x fastest; the grid field F[i, j, k] (first index along x) is written in Fortran order.
The ``.vti`` and ``.pvd`` files are VTK's XML formats: meshio writes unstructured meshes but no
ImageData, so these two small writers are here. The ``.vtu`` of a grid (its cells as
quads/hexahedra, ``write_vtu_grid``) is written here too. Both grid files hold their arrays in the
encoding meshio uses (binary, base64, zlib blocks of 32 KiB, the bytes of the doubles: exact) but
at level ``VTU_ZLIB_LEVEL`` of ISA-L's zlib-format compressor (``isal.isal_zlib``; any zlib
inflates it, VTK and meshio included): meshio's fixed zlib level 6 spent 0.56 s on the 64^3 grid's
17 MB against 0.12 s at zlib level 1 and 0.048 s with ISA-L at level 1, for 4.5 MB of compressed
blocks (zlib 1) against 5.2 MB (ISA-L 1); the ``.vti`` written as ASCII text (the shortest
round-trip repr of each value) took 0.12-0.2 s and 5.4 MB at 64^3 against ~0.01 s binary.
``read_vti`` reads both encodings (files of earlier versions are ASCII).
"""

from __future__ import annotations

import base64
import os
import zlib
from pathlib import Path
from html import escape

import numpy as np
from isal import isal_zlib

VTU_ZLIB_LEVEL = 1  # ISA-L's level 1 (module docstring: 2.5x faster than zlib's level 1, 17% larger)
VTU_BLOCK = 32768  # bytes per compressed block (meshio's and VTK's default)
VTK_CELL_TYPES = {2: ("quad", 9), 3: ("hexahedron", 12)}  # VTK's cell type ids of a grid's cells


def quoteattr(value: str) -> str:
    """An XML attribute value in double quotes, its markup escaped (as ``xml.sax.saxutils.quoteattr``,
    whose module imports urllib.request and http.client: 0.02 s of start-up)."""
    return '"' + escape(value, quote=True) + '"'


def mirrored(disc) -> bool:
    """A mirror grid (``mesh.cosine``: spectral with natural boundaries), whose box is one mirror
    cell of the whole vesicle: its files show the field reflected into the doubled box."""
    return getattr(disc, "kind", None) == "cosine"


def unfold(F: np.ndarray) -> np.ndarray:
    """A mirror grid's field reflected into the doubled box (as ``mesh.cosine.unfold``): per axis
    its mirror image about the face lo put before it, shape 2 n."""
    for axis in range(F.ndim):
        F = np.concatenate([np.flip(F, axis=axis), F], axis=axis)
    return F


def wrapped(disc, phi: np.ndarray) -> np.ndarray:
    """The grid field with its periodic copy appended along every axis (shape n_i + 1); on a
    mirror grid the whole vesicle's field (``unfold``, period 2 n) so completed (shape 2 n_i + 1)."""
    F = np.asarray(phi, float).reshape(disc.grid_shape)
    if mirrored(disc):
        F = unfold(F)
    return np.pad(F, [(0, 1)] * F.ndim, mode="wrap")


def grid_geometry(disc) -> tuple[np.ndarray, np.ndarray]:
    """(origin, spacing) of a periodic grid: the box's lower corner and h = (hi - lo) / n per axis;
    of a mirror grid's ``wrapped`` field: its cell-centred nodes 2 lo - hi + h/2 + j h."""
    lo = np.array([b[0] for b in disc.box], float)
    hi = np.array([b[1] for b in disc.box], float)
    h = (hi - lo) / np.array(disc.grid_shape, float)
    return (2 * lo - hi + h / 2, h) if mirrored(disc) else (lo, h)


def _atomic_text(path: Path, text: str) -> None:
    tmp = Path(path).with_name(f"{Path(path).name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    tmp.replace(path)


def write_vti(path: Path, disc, fields: dict[str, np.ndarray]) -> None:
    """Nodal fields of a periodic grid as a complete ImageData file (2D grids as one z-layer), the
    arrays binary (``_binary_array``, module docstring)."""
    arrays = {name: wrapped(disc, f) for name, f in fields.items()}
    shape = next(iter(arrays.values())).shape
    origin, spacing = grid_geometry(disc)
    if len(shape) == 2:
        origin, spacing, shape = np.append(origin, 0.0), np.append(spacing, 1.0), shape + (1,)
    extent = " ".join(f"0 {k - 1}" for k in shape)
    body = "".join("        " + _binary_array(name, F.ravel(order="F")) for name, F in arrays.items())
    text = ('<?xml version="1.0"?>\n'
            '<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" header_type="UInt32" '
            'compressor="vtkZLibDataCompressor">\n'
            f'  <ImageData WholeExtent="{extent}" Origin="{" ".join(map(repr, map(float, origin)))}" '
            f'Spacing="{" ".join(map(repr, map(float, spacing)))}">\n'
            f'    <Piece Extent="{extent}">\n'
            f'      <PointData Scalars={quoteattr(next(iter(arrays)))}>\n' + body +
            '      </PointData>\n      <CellData/>\n    </Piece>\n  </ImageData>\n</VTKFile>\n')
    _atomic_text(path, text)


def write_pvd(path: Path, entries: list[tuple[float, str]]) -> None:
    """A ParaView collection: one DataSet per (time, file relative to ``path``'s folder), in order."""
    rows = "\n".join(f'    <DataSet timestep="{t!r}" part="0" file={quoteattr(f)}/>' for t, f in entries)
    _atomic_text(path, '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                 + rows + "\n  </Collection>\n</VTKFile>\n")


def _read_binary_array(text: str, dtype: str) -> np.ndarray:
    """The values of one ``_binary_array`` (compressed, UInt32 header): the header's first base64
    run holds (blocks, block size, last size, compressed sizes), the second the zlib blocks."""
    text = text.strip()
    nblocks = int(np.frombuffer(base64.b64decode(text[:8])[:4], "<u4")[0])
    head_chars = 4 * -(-4 * (3 + nblocks) // 3)  # base64 length of the (3 + blocks) UInt32 header
    header = np.frombuffer(base64.b64decode(text[:head_chars]), "<u4")
    data = base64.b64decode(text[head_chars:])
    chunks, at = [], 0
    for size in header[3:3 + nblocks]:
        chunks.append(zlib.decompress(data[at:at + int(size)]))
        at += int(size)
    return np.frombuffer(b"".join(chunks), dtype)


def read_vti(path: Path) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """(fields as arrays indexed [i, j(, k)], origin, spacing) of a ``write_vti`` file (binary, or
    ASCII as earlier versions wrote)."""
    import xml.etree.ElementTree as ET  # a reader for tests and users; the writer needs none of it
    root = ET.parse(path).getroot()
    img = root.find("ImageData")
    ext = [int(v) for v in img.get("WholeExtent").split()]
    shape = tuple(ext[2 * d + 1] - ext[2 * d] + 1 for d in range(3))
    fields = {}
    for a in img.iter("DataArray"):
        if a.get("format") == "binary":
            values = _read_binary_array(a.text, "<f8")
        else:
            values = np.array(a.text.split(), float)
        fields[a.get("Name")] = values.reshape(shape, order="F")
    return fields, np.array(img.get("Origin").split(), float), np.array(img.get("Spacing").split(), float)


def grid_cells(disc) -> tuple[np.ndarray, np.ndarray]:
    """(points, cells) of a periodic grid completed by its wrap row/plane: (n+1)^d points (3D
    coordinates), n^d quads (2D) or hexahedra (3D) as rows of point indices in VTK's corner order."""
    shape = tuple((2 * k if mirrored(disc) else k) + 1 for k in disc.grid_shape)
    origin, spacing = grid_geometry(disc)
    axes = [origin[d] + spacing[d] * np.arange(k) for d, k in enumerate(shape)]
    points = np.stack(np.meshgrid(*axes, indexing="ij", copy=False), axis=-1).reshape(-1, disc.dim)  # written once
    if disc.dim == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    # int32 connectivity where it fits: half the bytes to compress (VTK reads either)
    size = int(np.prod(shape))
    idx = np.arange(size, dtype=np.int32 if size < 2**31 else np.int64).reshape(shape)
    s = (slice(None, -1), slice(1, None))
    if disc.dim == 2:
        corners = [idx[s[i], s[j]] for i, j in [(0, 0), (1, 0), (1, 1), (0, 1)]]
    else:
        corners = [idx[s[i], s[j], s[k]] for i, j, k in
                   [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]]
    return points, np.stack(corners, axis=-1).reshape(-1, len(corners))


_VTU_TYPES = {np.dtype("float64"): "Float64", np.dtype("int32"): "Int32", np.dtype("int64"): "Int64",
              np.dtype("uint8"): "UInt8"}


def _binary_array(name: str, data: np.ndarray, components: int | None = None) -> str:
    """One DataArray in VTK's compressed binary encoding: base64 of the UInt32 header (blocks,
    block size, last block's size, each compressed size), then base64 of the zlib blocks."""
    raw = np.ascontiguousarray(data).astype(data.dtype.newbyteorder("<"), copy=False).tobytes()
    blocks = [isal_zlib.compress(raw[i:i + VTU_BLOCK], VTU_ZLIB_LEVEL) for i in range(0, len(raw), VTU_BLOCK)]
    last = len(raw) - (len(blocks) - 1) * VTU_BLOCK if blocks else 0
    header = np.array([len(blocks), VTU_BLOCK, last] + [len(b) for b in blocks], dtype="<u4")
    ncomp = f' NumberOfComponents="{components}"' if components else ""
    return (f'<DataArray type="{_VTU_TYPES[data.dtype]}" Name={quoteattr(name)}{ncomp} format="binary">'
            + base64.b64encode(header.tobytes()).decode() + base64.b64encode(b"".join(blocks)).decode()
            + "</DataArray>\n")


def write_vtu_grid(path: Path, disc, fields: dict[str, np.ndarray]) -> None:
    """Nodal fields of a periodic grid on its complete cells (``grid_cells``) as a VTK XML
    UnstructuredGrid (the encoding of the module docstring; meshio and VTK read it)."""
    points, cells = grid_cells(disc)
    name, vtk_type = VTK_CELL_TYPES[disc.dim]
    offsets = np.arange(1, len(cells) + 1, dtype=cells.dtype) * cells.shape[1]
    data = "".join(_binary_array(k, wrapped(disc, f).ravel()) for k, f in fields.items())
    text = ('<?xml version="1.0"?>\n'
            '<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian" '
            'compressor="vtkZLibDataCompressor">\n<UnstructuredGrid>\n'
            f'<Piece NumberOfPoints="{len(points)}" NumberOfCells="{len(cells)}">\n'
            '<Points>\n' + _binary_array("Points", points, 3) + '</Points>\n<Cells>\n'
            + _binary_array("connectivity", cells.ravel()) + _binary_array("offsets", offsets)
            + _binary_array("types", np.full(len(cells), vtk_type, np.uint8)) + '</Cells>\n'
            f'<PointData Scalars={quoteattr(next(iter(fields)))}>\n' + data
            + '</PointData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n')
    _atomic_text(path, text)
