"""Writers of a result: summary.json, phi.npz, VTK files (meshio ``.vtu``; ``io.vtk``: ``.vti``, ``.pvd``),
the phi = 0 surface of 3D grids (``io.surface``) and a PNG of the level set (``io.png``: grids by
Pillow, ``io.raster``; a mesh's 2D triangles by matplotlib); the atomic json/npz files are ``io.files``.

Nothing non-finite is ever written: ``Result.summary`` maps NaN/inf to null, and fields with
non-finite values are refused here rather than written. meshio loads only when a mesh's .vtu is
written (a grid's .vtu is ``io.vtk``'s, a surface.ply ``io.surface``'s), matplotlib (~0.35 s) only
for a mesh's 2D PNG and scipy.interpolate only for the PNG cuts of a 3D mesh.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vesicle_opt.io import fields, meridian, png
from vesicle_opt.io import surface as zero_level
from vesicle_opt.io import vtk
from vesicle_opt.io.files import package_version, write_json


def _grid_field(disc, phi: np.ndarray) -> np.ndarray | None:
    if disc.grid_shape is None:
        return None
    return phi.reshape(disc.grid_shape)


def write_vtk(path: Path, disc, phi: np.ndarray) -> None:
    """phi on the mesh (FEM; meshio) or on the complete periodic grid with its cells (FD, spectral;
    ``vtk.write_vtu_grid``) for ParaView: the grid's wrap row/plane is appended (``vtk.wrapped``), so
    the cells cover the box."""
    if disc.mesh is None:
        vtk.write_vtu_grid(path, disc, {"phi": np.asarray(phi, float)})
        return
    import meshio  # third-party, lazy (module docstring): only meshes' .vtu files need it
    values = disc.unfold @ phi if disc.unfold is not None else phi
    points = disc.mesh.p.T
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    cells = [("triangle" if disc.mesh_dim == 2 else "tetra", disc.mesh.t.T)]
    meshio.write(str(path), meshio.Mesh(points, cells, point_data={"phi": np.asarray(values, float)}))


def write_field(out: Path, stem: str, disc, phi: np.ndarray) -> str:
    """The viewer file of one field: ``stem.vti`` on periodic grids (complete ImageData), ``stem.vtu``
    on meshes; returns the file name."""
    if disc.grid_shape is not None:
        vtk.write_vti(out / f"{stem}.vti", disc, {"phi": phi})
        return f"{stem}.vti"
    write_vtk(out / f"{stem}.vtu", disc, phi)
    return f"{stem}.vtu"


def _coords(box, shape, axis: int) -> np.ndarray:
    lo, hi = box[axis]
    return np.linspace(lo, hi, shape[axis], endpoint=False)


AXES = "xyz"


def _drawn_grid(disc, phi: np.ndarray) -> tuple[np.ndarray, tuple]:
    """(field, box its nodes lo + j (hi - lo) / n span) of a grid as drawn: on a mirror grid the
    whole vesicle, reflected into the doubled box at its cell-centred nodes (``vtk.unfold``), so
    that the central cuts pass through the vesicle's centre (the box's corner lo)."""
    F = _grid_field(disc, phi)
    if not vtk.mirrored(disc):
        return F, disc.box
    h = [(hi - lo) / k for (lo, hi), k in zip(disc.box, disc.grid_shape)]
    return vtk.unfold(F), tuple((2 * lo - hi + d / 2, hi + d / 2) for (lo, hi), d in zip(disc.box, h))


def figure_spec(disc, phi: np.ndarray, title: str = "") -> dict:
    """What ``png.draw`` draws for phi, as plain arrays and strings (the mesh-dependent part, apart
    from the drawing): 2D, the field (grids) or its triangles (meshes); 3D, the three central cuts
    (mirror grids: of the whole vesicle, ``_drawn_grid``)."""
    box = disc.box
    if disc.mesh_dim == 2:  # the meridian half-plane of an axisymmetric scene too (r, z)
        if disc.grid_shape is not None:
            F, box = _drawn_grid(disc, phi)
            return {"kind": "image", "field": F, "lo": (box[0][0], box[1][0]),
                    "hi": (box[0][1], box[1][1]), "title": title}
        vals = disc.unfold @ phi if disc.unfold is not None else phi
        return {"kind": "triangles", "x": disc.mesh.p[0], "y": disc.mesh.p[1], "triangles": disc.mesh.t.T,
                "values": np.asarray(vals, float), "title": title,
                "axis_names": ("r", "z") if disc.axisymmetric else ("x", "y")}
    if disc.grid_shape is not None:
        F, box = _drawn_grid(disc, phi)
        mid = [k // 2 for k in F.shape]
        cuts = [F[mid[0], :, :], F[:, mid[1], :], F[:, :, mid[2]]]
        at = [_coords(box, F.shape, d)[mid[d]] for d in range(3)]
    else:
        cuts = [_sample_cut(disc, phi, axis) for axis in range(3)]
        at = [0.5 * (box[d][0] + box[d][1]) for d in range(3)]
    others = [[d for d in range(3) if d != axis] for axis in range(3)]
    return {"kind": "cuts", "cuts": [np.ascontiguousarray(c) for c in cuts],
            "lo": [(box[o[0]][0], box[o[1]][0]) for o in others], "hi": [(box[o[0]][1], box[o[1]][1]) for o in others],
            "labels": [f"{AXES[axis]} = {at[axis]:.3g}" for axis in range(3)],
            "axis_names": [(AXES[o[0]], AXES[o[1]]) for o in others], "endpoint": disc.grid_shape is None,
            "title": title}


def write_png(path: Path, disc, phi: np.ndarray, title: str = "") -> None:
    """2D: phi with its zero level set; 3D: three central cuts (x, y, z = the box's middle plane), in
    physical coordinates, with axis labels and a colorbar of phi (``png.draw`` of ``figure_spec``)."""
    png.draw(path, figure_spec(disc, phi, title))


def _sample_cut(disc, phi, axis: int, n: int = 64) -> np.ndarray:
    box = disc.box
    other = [d for d in range(3) if d != axis]
    g = [np.linspace(*box[d], n) for d in other]
    A, B = np.meshgrid(*g, indexing="ij")
    pts = np.zeros((n * n, 3))
    pts[:, axis] = 0.5 * (box[axis][0] + box[axis][1])
    pts[:, other[0]], pts[:, other[1]] = A.ravel(), B.ravel()
    from scipy.interpolate import griddata  # third-party, lazy: only for the PNG's cuts of a mesh
    return griddata(disc.nodes, phi, pts, method="nearest").reshape(n, n)


def write_surface_files(out: Path, disc, phi: np.ndarray, summary: dict) -> dict:
    """3D grids: ``surface.ply`` (the phi = 0 surface, marching cubes) and its area and volume beside
    the phase-field ``area`` and ``volume`` of ``summary`` (``io.surface.report``); the meridian
    half-plane: ``meridian.csv`` (the phi = 0 curve) and ``surface.ply`` (its surface of revolution,
    ``io.meridian``), reported the same way; {} otherwise."""
    if disc.axisymmetric:
        curves = meridian.meridian_curves(disc, phi)
        meridian.write_meridian(out / "meridian.csv", curves)
        surf = meridian.revolve(curves)
    else:
        surf = zero_level.zero_surface(disc, phi)
    if surf is None:
        return {}
    zero_level.write_surface(out / "surface.ply", surf)
    return zero_level.report(surf, summary.get("area"), summary.get("volume"))


def write_result(out: Path, scene, disc, result) -> dict:
    """Write everything a solve produced into ``out``; returns the summary dict.

    ``summary.json``, ``phi.npz``, ``phi.vtu`` (every mesh; periodic grids complete, wrap included),
    ``phi.vti`` (periodic grids: ImageData), ``phi.png``, and for 3D grids and the meridian
    half-plane ``surface.ply`` with ``surface_area`` / ``surface_volume`` in the summary (and
    ``meridian.csv`` there: ``write_surface_files``)."""
    out.mkdir(parents=True, exist_ok=True)
    summary = {**result.summary(scene.name), "version": package_version()}
    finite = np.all(np.isfinite(result.phi))
    if finite:
        # written one after the other: the .npz and .vtu in a thread beside the PNG and the .vti text
        # were measured no faster on this 2-core machine (2.96-3.15 s against 2.93-2.95 s a process);
        # the npz layout is io.fields' (format version), uncompressed: doubles barely compress (1.0 s vs 0.13 s)
        fields.write(out / "phi.npz", "solve", result.phi, disc, w=result.w)
        write_vtk(out / "phi.vtu", disc, result.phi)
        if disc.grid_shape is not None:
            vtk.write_vti(out / "phi.vti", disc, {"phi": result.phi})
        write_png(out / "phi.png", disc, result.phi, title=f"{scene.name}: E = {result.energy:.6g}")
        summary.update(write_surface_files(out, disc, result.phi, summary))
    summary["fields_written"] = bool(finite)
    write_json(out / "summary.json", summary)
    return summary
