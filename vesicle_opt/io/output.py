"""Writers of a result: summary.json, phi.npz, VTK files (meshio ``.vtu``; ``io.vtk``: ``.vti``, ``.pvd``),
the phi = 0 surface of 3D grids (``io.surface``) and a PNG of the level set (matplotlib); the
atomic json/npz files are ``io.files``.

Nothing non-finite is ever written: ``Result.summary`` maps NaN/inf to null, and fields with
non-finite values are refused here rather than written. meshio loads only when a mesh's .vtu or
a surface file is written (a grid's .vtu is ``io.vtk``'s), matplotlib (~0.35 s) and
scipy.interpolate only when a PNG is drawn.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

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
    cells = [("triangle" if disc.dim == 2 else "tetra", disc.mesh.t.T)]
    meshio.write(str(path), meshio.Mesh(points, cells, point_data={"phi": np.asarray(values, float)}))


def write_field(out: Path, stem: str, disc, phi: np.ndarray) -> str:
    """The viewer file of one field: ``stem.vti`` on periodic grids (complete ImageData), ``stem.vtu``
    on meshes; returns the file name."""
    if disc.grid_shape is not None:
        vtk.write_vti(out / f"{stem}.vti", disc, {"phi": phi})
        return f"{stem}.vti"
    write_vtk(out / f"{stem}.vtu", disc, phi)
    return f"{stem}.vtu"


def _coords(disc, axis: int) -> np.ndarray:
    lo, hi = disc.box[axis]
    return np.linspace(lo, hi, disc.grid_shape[axis], endpoint=False)


AXES = "xyz"


def write_png(path: Path, disc, phi: np.ndarray, title: str = "") -> None:
    """2D: phi with its zero level set; 3D: three central cuts (x, y, z = the box's middle plane), in
    physical coordinates, with axis labels and a colorbar of phi."""
    # third-party, lazy: only a PNG needs them (~0.35 s at import); a Figure on the Agg canvas, not
    # pyplot (its state machine and backend switching add 0.07 s and are not needed for one file)
    import matplotlib.tri as mtri
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    box = disc.box
    if disc.dim == 2:
        fig = Figure(figsize=(5.6, 5))
        ax = fig.subplots()
        if disc.grid_shape is not None:
            image = draw_cut(ax, _grid_field(disc, phi), (box[0][0], box[1][0]), (box[0][1], box[1][1]))
        else:
            tri = mtri.Triangulation(disc.mesh.p[0], disc.mesh.p[1], disc.mesh.t.T)
            vals = disc.unfold @ phi if disc.unfold is not None else phi
            image = ax.tripcolor(tri, vals, cmap="RdBu_r", vmin=-1, vmax=1, shading="gouraud")
            ax.tricontour(tri, vals, levels=[0.0], colors="k")
        ax.set_aspect("equal")
        ax.set_xlabel("x")
        ax.set_ylabel("y")
        ax.set_title(title, fontsize=9)
        fig.colorbar(image, ax=ax, shrink=0.8, label="phi (+1 inside, -1 outside)")
    else:
        # a fixed layout: matplotlib's constrained layout measured 0.35 s of a 0.78 s PNG at 64^3
        fig = Figure(figsize=(13, 4.2))
        axes = fig.subplots(1, 3)
        fig.subplots_adjust(left=0.04, right=0.9, bottom=0.12, top=0.85, wspace=0.28)
        if disc.grid_shape is not None:
            F = _grid_field(disc, phi)
            mid = [k // 2 for k in disc.grid_shape]
            cuts = [F[mid[0], :, :], F[:, mid[1], :], F[:, :, mid[2]]]
            at = [_coords(disc, d)[mid[d]] for d in range(3)]
        else:
            cuts = [_sample_cut(disc, phi, axis) for axis in range(3)]
            at = [0.5 * (box[d][0] + box[d][1]) for d in range(3)]
        for axis, (ax, cut) in enumerate(zip(axes, cuts)):
            other = [d for d in range(3) if d != axis]
            lo, hi = (box[other[0]][0], box[other[1]][0]), (box[other[0]][1], box[other[1]][1])
            image = draw_cut(ax, cut, lo, hi, f"{AXES[axis]} = {at[axis]:.3g}",
                             endpoint=disc.grid_shape is None)
            ax.set_xlabel(AXES[other[0]])
            ax.set_ylabel(AXES[other[1]])
        fig.suptitle(title, fontsize=10)
        fig.colorbar(image, cax=fig.add_axes((0.92, 0.17, 0.012, 0.63)), label="phi")
    if disc.dim == 2:
        fig.tight_layout()
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=100)


def draw_cut(ax, cut: np.ndarray, lo: tuple, hi: tuple, title: str = "", *, endpoint: bool = False):
    """A 2D section of phi (first index along x) over [lo, hi) (a periodic grid; ``endpoint``: samples
    including hi) with its zero level, in physical coordinates; returns the image (for a colorbar)."""
    xs = [np.linspace(a, b, k, endpoint=endpoint) for a, b, k in zip(lo, hi, cut.shape)]
    half = [0.5 * (x[1] - x[0]) for x in xs]  # pixels centred on the samples
    image = ax.imshow(cut.T, origin="lower", cmap="RdBu_r", vmin=-1, vmax=1,
                      extent=[xs[0][0] - half[0], xs[0][-1] + half[0], xs[1][0] - half[1], xs[1][-1] + half[1]])
    ax.contour(xs[0], xs[1], cut.T, levels=[0.0], colors="k")
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")
    return image


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
    the phase-field ``area`` and ``volume`` of ``summary`` (``io.surface.report``); {} otherwise."""
    surf = zero_level.zero_surface(disc, phi)
    if surf is None:
        return {}
    zero_level.write_surface(out / "surface.ply", surf)
    return zero_level.report(surf, summary.get("area"), summary.get("volume"))


def write_result(out: Path, scene, disc, result) -> dict:
    """Write everything a solve produced into ``out``; returns the summary dict.

    ``summary.json``, ``phi.npz``, ``phi.vtu`` (every mesh; periodic grids complete, wrap included),
    ``phi.vti`` (periodic grids: ImageData), ``phi.png``, and for 3D grids ``surface.ply`` with
    ``surface_area`` / ``surface_volume`` in the summary (``write_surface_files``)."""
    out.mkdir(parents=True, exist_ok=True)
    summary = {**result.summary(scene.name), "version": package_version()}
    finite = np.all(np.isfinite(result.phi))
    if finite:
        arrays = {"phi": result.phi, "nodes": disc.nodes}
        if result.w is not None:
            arrays["w"] = result.w

        def field_files():
            np.savez(out / "phi.npz", **arrays)  # uncompressed: doubles barely compress (1.0 s vs 0.13 s)
            write_vtk(out / "phi.vtu", disc, result.phi)
            if disc.grid_shape is not None:
                vtk.write_vti(out / "phi.vti", disc, {"phi": result.phi})
        # the field files in a second thread while this one draws the PNG and the surface: their
        # zlib, file writes and numpy copies release the GIL (64^3: 0.30 s of the 0.75 s of output
        # overlap); matplotlib stays in one thread; an error of either is raised here
        with ThreadPoolExecutor(max_workers=1) as pool:
            files = pool.submit(field_files)
            write_png(out / "phi.png", disc, result.phi, title=f"{scene.name}: E = {result.energy:.6g}")
            summary.update(write_surface_files(out, disc, result.phi, summary))
            files.result()
    summary["fields_written"] = bool(finite)
    write_json(out / "summary.json", summary)
    return summary
