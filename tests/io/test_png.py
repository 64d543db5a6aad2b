"""The PNG of ``io.output.write_png`` (``figure_spec`` drawn by ``io.png.draw``; grids by
``io.raster`` with Pillow): checked against matplotlib, which shares no code with it: the colormap
is matplotlib's RdBu_r, every sample's pixel block has phi's colour, and the black zero level lies
only where phi changes sign."""

import numpy as np
import pytest
from matplotlib import colormaps
from PIL import Image

import vesicle_opt as vo
from vesicle_opt.io import output, raster
from vesicle_opt.mesh import discretize


def test_colormap_is_matplotlibs_rdbu_r():
    values = np.linspace(-1.2, 1.2, 2001)
    ours = raster.colors(values).astype(int)
    theirs = colormaps["RdBu_r"]((values + 1) / 2, bytes=True)[:, :3].astype(int)
    assert np.abs(ours - theirs).max() <= 1  # 1 byte: float-to-byte rounding of the same 256-level table


def _check_panels(path, spec):
    """Each sample away from the zero level shows its colour at its pixel centre; each black pixel of
    a panel lies in a sample block next to a sign change."""
    rgb = np.asarray(Image.open(path).convert("RGB")).astype(int)
    panels, size = raster.layout(spec)
    assert rgb.shape == (size[1], size[0], 3)
    for p in panels:
        C = p.cut
        sign = np.sign(C)
        pad = np.pad(sign, 1, mode="edge")
        uniform = np.all([pad[1 + a:1 + a + C.shape[0], 1 + b:1 + b + C.shape[1]] == sign
                          for a in (-1, 0, 1) for b in (-1, 0, 1)], axis=0)
        checked = 0
        for i, j in zip(*np.nonzero(uniform)):
            px, py = p.to_pixel(p.axes[0][i], p.axes[1][j])
            assert np.abs(rgb[int(py), int(px)] - raster.colors(C[i, j])).max() == 0
            checked += 1
        assert checked > C.size // 4
        box = rgb[p.top:p.top + p.size[1], p.left:p.left + p.size[0]]
        ys, xs = np.nonzero(box.sum(axis=2) == 0)
        assert len(ys) > 0  # a zero level is drawn
        ii = np.clip(((xs + 0.5) / p.scale / p.step[0]).astype(int), 0, C.shape[0] - 1)
        jj = np.clip(((p.size[1] - ys - 0.5) / p.scale / p.step[1]).astype(int), 0, C.shape[1] - 1)
        assert not uniform[ii, jj].any()  # black only beside a sign change


@pytest.mark.parametrize("name, n", [("torus-table1-3d", 12), ("ellipse-2d", 16)])
def test_grid_figure_shows_phi_and_its_zero_level(tmp_path, name, n):
    d = discretize(vo.load_scene(name, [f"mesh.n={n}"]))
    x = d.nodes
    phi = np.tanh(np.sin(x[:, 0]) + 0.5 * np.cos(2 * x[:, 1]) + (x[:, 2] if d.dim == 3 else 0.0) - 0.3)
    output.write_png(tmp_path / "phi.png", d, phi, title="t")
    _check_panels(tmp_path / "phi.png", output.figure_spec(d, phi, "t"))
