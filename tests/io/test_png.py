"""The PNG of ``io.output.write_png`` (``figure_spec`` drawn by ``io.png.draw``) is the figure of the
former single function, pixel for pixel: drawn here by an independent copy of that code."""

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.image import imread

import vesicle_opt as vo
from vesicle_opt.io import output
from vesicle_opt.mesh import discretize


def test_three_cuts_of_a_grid_as_before(tmp_path):
    d = discretize(vo.load_scene("torus-table1-3d", ["mesh.n=12"]))
    x = d.nodes
    phi = np.sin(x[:, 0]) + 0.5 * np.cos(2 * x[:, 1]) + x[:, 2] - 0.3
    output.write_png(tmp_path / "new.png", d, phi, title="t")
    F = phi.reshape(d.grid_shape)
    fig = Figure(figsize=(13, 4.2))
    axes = fig.subplots(1, 3)
    fig.subplots_adjust(left=0.04, right=0.9, bottom=0.12, top=0.85, wspace=0.28)
    lo = [b[0] for b in d.box]
    hi = [b[1] for b in d.box]
    for axis, ax in enumerate(axes):
        cut = np.take(F, 6, axis=axis)
        o = [k for k in range(3) if k != axis]
        xs = [np.linspace(lo[k], hi[k], 12, endpoint=False) for k in o]
        h = [0.5 * (v[1] - v[0]) for v in xs]
        image = ax.imshow(cut.T, origin="lower", cmap="RdBu_r", vmin=-1, vmax=1,
                          extent=[xs[0][0] - h[0], xs[0][-1] + h[0], xs[1][0] - h[1], xs[1][-1] + h[1]])
        ax.contour(xs[0], xs[1], cut.T, levels=[0.0], colors="k")
        ax.set_title(f"{'xyz'[axis]} = {lo[axis] + 6 * (hi[axis] - lo[axis]) / 12:.3g}", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("xyz"[o[0]])
        ax.set_ylabel("xyz"[o[1]])
    fig.suptitle("t", fontsize=10)
    fig.colorbar(image, cax=fig.add_axes((0.92, 0.17, 0.012, 0.63)), label="phi")
    FigureCanvasAgg(fig)
    fig.savefig(tmp_path / "old.png", dpi=100)
    assert np.array_equal(imread(tmp_path / "new.png"), imread(tmp_path / "old.png"))
