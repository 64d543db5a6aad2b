"""The PNG of a field, drawn by matplotlib from plain arrays (``io.output.figure_spec`` says what).

matplotlib costs ~0.35 s at import and ~0.15 s to draw the three cuts of a 64^3 grid. Drawing it
in a worker process that imported matplotlib while the solve ran was measured and dropped: on this
2-core machine the worker slowed the solve more than it saved (whole process 3.13-3.37 s against
2.88-3.04 s drawing here, three interleaved pairs, load 1.4).

Figures: 2D, phi with its zero level and a colorbar (grids: an image; meshes: Gouraud triangles);
3D, three central cuts (x, y, z = the middle plane), in physical coordinates, axis labels, colorbar.
"""

from __future__ import annotations

import numpy as np


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
    # third-party, lazy: only a PNG needs them (~0.35 s at import); a Figure on the Agg canvas, not
    # pyplot (its state machine and backend switching add 0.07 s and are not needed for one file)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    if spec["kind"] == "cuts":
        # a fixed layout: matplotlib's constrained layout measured 0.35 s of a 0.78 s PNG at 64^3
        fig = Figure(figsize=(13, 4.2))
        axes = fig.subplots(1, 3)
        fig.subplots_adjust(left=0.04, right=0.9, bottom=0.12, top=0.85, wspace=0.28)
        for ax, cut, lo, hi, label, (xl, yl) in zip(axes, spec["cuts"], spec["lo"], spec["hi"], spec["labels"],
                                                    spec["axis_names"]):
            image = draw_cut(ax, cut, lo, hi, label, endpoint=spec["endpoint"])
            ax.set_xlabel(xl)
            ax.set_ylabel(yl)
        fig.suptitle(spec["title"], fontsize=10)
        fig.colorbar(image, cax=fig.add_axes((0.92, 0.17, 0.012, 0.63)), label="phi")
    else:
        fig = Figure(figsize=(5.6, 5))
        ax = fig.subplots()
        if spec["kind"] == "image":
            image = draw_cut(ax, spec["field"], spec["lo"], spec["hi"])
        else:  # "triangles"
            import matplotlib.tri as mtri
            tri = mtri.Triangulation(spec["x"], spec["y"], spec["triangles"])
            image = ax.tripcolor(tri, spec["values"], cmap="RdBu_r", vmin=-1, vmax=1, shading="gouraud")
            ax.tricontour(tri, spec["values"], levels=[0.0], colors="k")
        ax.set_aspect("equal")
        ax.set_xlabel("x")
        ax.set_ylabel("y")
        ax.set_title(spec["title"], fontsize=9)
        fig.colorbar(image, ax=ax, shrink=0.8, label="phi (+1 inside, -1 outside)")
        fig.tight_layout()
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=100)
