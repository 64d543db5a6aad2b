"""The PNG drawn by the worker process (``io.png.Painter``) is the PNG drawn in-process, pixel for
pixel; a worker that fails leaves the figure to this process; one sent nothing just ends."""

import subprocess
import sys

import numpy as np
from matplotlib.image import imread

import vesicle_opt as vo
from vesicle_opt.io import output, png
from vesicle_opt.mesh import discretize


def _field(name, n):
    d = discretize(vo.load_scene(name, [f"mesh.n={n}"]))
    x = d.nodes
    return d, np.sin(x[:, 0]) + 0.5 * np.cos(2 * x[:, 1]) + (x[:, 2] if d.dim == 3 else 0.0) - 0.3


def test_worker_draws_the_same_pixels(tmp_path):
    for name, n in (("torus-table1-3d", 12), ("ellipse-2d", 16)):
        d, phi = _field(name, n)
        output.write_png(tmp_path / "here.png", d, phi, title="t")
        with png.Painter() as painter:
            output.write_png(tmp_path / "worker.png", d, phi, title="t", painter=painter)
            painter.finish()
            assert painter.proc is None  # the worker ended, its figure written
        assert np.array_equal(imread(tmp_path / "here.png"), imread(tmp_path / "worker.png"))


def test_a_failing_worker_leaves_the_figure_to_this_process(tmp_path, caplog):
    d, phi = _field("ellipse-2d", 16)
    painter = png.Painter()
    painter.proc = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.buffer.read(8); "
                                     "print('boom', file=sys.stderr); sys.exit(3)"],
                                    stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    output.write_png(tmp_path / "phi.png", d, phi, title="t", painter=painter)
    painter.finish()
    output.write_png(tmp_path / "here.png", d, phi, title="t")
    assert np.array_equal(imread(tmp_path / "phi.png"), imread(tmp_path / "here.png"))
    assert "PNG worker failed (boom)" in caplog.text


def test_a_worker_sent_nothing_just_ends(tmp_path):
    with png.Painter() as painter:
        proc = painter.proc
    assert painter.proc is None and proc.returncode == 0 and not list(tmp_path.iterdir())
