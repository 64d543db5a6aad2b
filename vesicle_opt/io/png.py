"""The PNG of a field (``io.output.figure_spec`` says what): grid images and cuts as pixel arrays
(``io.raster``, Pillow), a mesh's 2D triangles by matplotlib; ``draw_cut``, one matplotlib panel,
for the studies' own figures.

matplotlib costs ~0.35 s at import and ~0.15 s to draw the three cuts of a 64^3 grid, so grid
fields (every FD and spectral run, and the sampled cuts of a 3D mesh) no longer use it. Drawing
it in a worker process that imported matplotlib while the solve ran was measured and dropped: on
this 2-core machine the worker slowed the solve more than it saved (whole process 3.13-3.37 s
against 2.88-3.04 s drawing here, three interleaved pairs, load 1.4).

Figures: 2D, phi with its zero level and a colorbar (grids: an image; meshes: Gouraud triangles);
3D, three central cuts (x, y, z = the middle plane), in physical coordinates, axis labels, colorbar.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.io import raster


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


def draw(path, spec: dict) -> None:
    """Draw ``spec`` (``figure_spec``) into the PNG file ``path``."""
    if spec["kind"] in ("cuts", "image"):
        raster.draw(path, spec)
        return
    _draw_triangles(path, spec)


def _draw_triangles(path, spec: dict) -> None:
    """A mesh's 2D field (Gouraud triangles) with its zero level, by matplotlib."""
    # third-party, lazy: only a mesh's PNG needs them (~0.35 s at import); a Figure on the Agg
    # canvas, not pyplot (its state machine and backend switching add 0.07 s, not needed for a file)
    import matplotlib.tri as mtri
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(5.6, 5))
    ax = fig.subplots()
    tri = mtri.Triangulation(spec["x"], spec["y"], spec["triangles"])
    image = ax.tripcolor(tri, spec["values"], cmap="RdBu_r", vmin=-1, vmax=1, shading="gouraud")
    ax.tricontour(tri, spec["values"], levels=[0.0], colors="k")
    ax.set_aspect("equal")
    xlabel, ylabel = spec.get("axis_names", ("x", "y"))  # the meridian half-plane: r, z
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(spec["title"], fontsize=9)
    fig.colorbar(image, ax=ax, shrink=0.8, label="phi (+1 inside, -1 outside)")
    fig.tight_layout()
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=100)
