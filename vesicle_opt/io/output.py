"""Writers of a result: summary.json, phi.npz, a VTK file (meshio) and a PNG of the level set
(matplotlib); the atomic json/npz files are ``io.files``.

Nothing non-finite is ever written: ``Result.summary`` maps NaN/inf to null, and fields with
non-finite values are refused here rather than written. meshio loads with this module only (not
with ``import vesicle_opt``), matplotlib (~0.4 s) and scipy.interpolate only when a PNG is drawn.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from vesicle_opt.io.files import write_json


def _grid_field(disc, phi: np.ndarray) -> np.ndarray | None:
    if disc.grid_shape is None:
        return None
    return phi.reshape(disc.grid_shape)


def write_vtk(path: Path, disc, phi: np.ndarray) -> None:
    """phi on the mesh (FEM) or as a point cloud of grid nodes with its cells (FD) for ParaView."""
    if disc.mesh is not None:
        values = disc.unfold @ phi if disc.unfold is not None else phi
        cell = "triangle" if disc.dim == 2 else "tetra"
        points = disc.mesh.p.T
        cells = [(cell, disc.mesh.t.T)]
    else:  # FD grid: structured quads/hexahedra of the periodic grid without the wrap-around cells
        shape = disc.grid_shape
        idx = np.arange(disc.n_nodes).reshape(shape)
        if disc.dim == 2:
            c = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
            cells = [("quad", c)]
        else:
            s = (slice(None, -1), slice(1, None))
            corners = [idx[s[i], s[j], s[k]] for i, j, k in
                       [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]]
            cells = [("hexahedron", np.stack(corners, axis=-1).reshape(-1, 8))]
        points, values = disc.nodes, phi
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    meshio.write(str(path), meshio.Mesh(points, cells, point_data={"phi": np.asarray(values, float)}))


def write_png(path: Path, disc, phi: np.ndarray, title: str = "") -> None:
    """2D: phi with its zero level set; 3D: three central cut views (x=0, y=0, z=0 planes)."""
    import matplotlib  # third-party, lazy: only a PNG needs it (~0.4 s at import)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    box = disc.box
    if disc.dim == 2:
        fig, ax = plt.subplots(figsize=(5, 5))
        if disc.grid_shape is not None:
            draw_cut(ax, _grid_field(disc, phi), (box[0][0], box[1][0]), (box[0][1], box[1][1]))
        else:
            tri = mtri.Triangulation(disc.mesh.p[0], disc.mesh.p[1], disc.mesh.t.T)
            vals = disc.unfold @ phi if disc.unfold is not None else phi
            ax.tripcolor(tri, vals, cmap="RdBu_r", vmin=-1, vmax=1, shading="gouraud")
            ax.tricontour(tri, vals, levels=[0.0], colors="k")
        ax.set_aspect("equal")
        ax.set_title(title)
    else:
        fig, axes = plt.subplots(1, 3, figsize=(12, 4))
        if disc.grid_shape is not None:
            F = _grid_field(disc, phi)
            mid = [k // 2 for k in disc.grid_shape]
            cuts = [F[mid[0], :, :], F[:, mid[1], :], F[:, :, mid[2]]]
        else:
            cuts = [_sample_cut(disc, phi, axis) for axis in range(3)]
        for ax, cut, name in zip(axes, cuts, ["x = mid", "y = mid", "z = mid"]):
            ax.imshow(cut.T, origin="lower", cmap="RdBu_r", vmin=-1, vmax=1)
            ax.contour(cut.T, levels=[0.0], colors="k")
            ax.set_title(f"{title} {name}")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def draw_cut(ax, cut: np.ndarray, lo: tuple, hi: tuple, title: str = "") -> None:
    """A 2D section of phi (first index along x) on a periodic grid over [lo, hi) with its zero level."""
    ax.imshow(cut.T, origin="lower", extent=[lo[0], hi[0], lo[1], hi[1]], cmap="RdBu_r", vmin=-1, vmax=1)
    xs = [np.linspace(a, b, k, endpoint=False) for a, b, k in zip(lo, hi, cut.shape)]
    ax.contour(xs[0], xs[1], cut.T, levels=[0.0], colors="k")
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")


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


def write_result(out: Path, scene, disc, result) -> dict:
    """Write everything a solve produced into ``out``; returns the summary dict."""
    out.mkdir(parents=True, exist_ok=True)
    summary = result.summary(scene.name)
    finite = np.all(np.isfinite(result.phi))
    if finite:
        arrays = {"phi": result.phi, "nodes": disc.nodes}
        if result.w is not None:
            arrays["w"] = result.w
        np.savez(out / "phi.npz", **arrays)  # uncompressed: doubles barely compress (1.0 s vs 0.13 s)
        write_vtk(out / "phi.vtu", disc, result.phi)
        write_png(out / "phi.png", disc, result.phi, title=f"{scene.name}: E = {result.energy:.6g}")
    summary["fields_written"] = bool(finite)
    write_json(out / "summary.json", summary)
    return summary
