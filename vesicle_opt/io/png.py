"""The PNG of a field: what is drawn (``figure_spec``, numpy only) apart from drawing it (``draw``,
matplotlib), so that a second process can draw it (``Painter``).

matplotlib costs ~0.35 s at import and ~0.15 s to draw the three cuts of a 64^3 grid, a third of
a converged 64^3 spectral solve's overhead. ``Painter.start()`` launches ``python -I -c`` running
this file (it imports nothing of the package: numpy and matplotlib only), which imports matplotlib
while the solve runs and then draws the figure it is sent (a pickle of ``figure_spec``'s plain
arrays on its stdin) into the file named. ``Painter.finish()`` waits for it; if it could not start,
failed or sent nothing back, the figure is drawn in this process instead (the same ``draw``), so a
PNG is always written or an error raised, exactly as without the worker.

Figures: 2D, phi with its zero level and a colorbar (grids: an image; meshes: Gouraud triangles);
3D, three central cuts (x, y, z = the middle plane), in physical coordinates, axis labels, colorbar.
"""

from __future__ import annotations

import logging
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)  # a worker that failed (the PNG is then drawn here)

AXES = "xyz"
WAIT_S = 120.0  # at most this long for the worker's PNG (drawing takes ~0.2 s) before drawing here


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


def _serve() -> int:
    """The worker: matplotlib imported first (while the parent solves), then one figure drawn."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: F401  (warm the imports)
    from matplotlib.figure import Figure  # noqa: F401
    size = sys.stdin.buffer.read(8)
    if len(size) < 8:  # the parent had nothing to draw (a failed solve, an error): nothing to do
        return 0
    path, spec = pickle.loads(sys.stdin.buffer.read(int.from_bytes(size, "little")))
    draw(path, spec)
    return 0


class Painter:
    """A worker process that draws one PNG (module docstring); a context manager that always ends it."""

    def __init__(self):
        self.proc = None
        self.sent = None

    def start(self) -> "Painter":
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-I", "-c", f"import runpy; runpy.run_path({str(Path(__file__))!r}, "
                 "run_name='__png_worker__')"],
                stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        except OSError as exc:  # no process to be had: every figure is drawn here
            log.debug("PNG worker not started (%s); drawing in this process", exc)
            self.proc = None
        return self

    def paint(self, path, spec: dict) -> None:
        """Send the figure to the worker (or draw it here when there is none or it is gone)."""
        if self.proc is None or self.sent is not None:
            draw(path, spec)
            return
        try:
            data = pickle.dumps((str(path), spec), protocol=pickle.HIGHEST_PROTOCOL)
            self.proc.stdin.write(len(data).to_bytes(8, "little") + data)  # length-prefixed: no EOF needed
            self.proc.stdin.flush()
            self.sent = (path, spec)
        except OSError:  # the worker died (its error is in finish's log line): draw here
            self._stop()
            draw(path, spec)

    def finish(self) -> None:
        """Wait for the worker's PNG; draw it here if the worker failed."""
        if self.proc is None:
            return
        if self.sent is None:
            self._stop()
            return
        path, spec = self.sent
        try:
            _, err = self.proc.communicate(timeout=WAIT_S)
            ok = self.proc.returncode == 0 and Path(path).is_file()
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
            ok = False
        self.proc = None
        if not ok:
            tail = (err or b"").decode(errors="replace").strip().splitlines()[-1:]
            log.warning("the PNG worker failed (%s); drawing %s here", tail[0] if tail else "no message",
                        Path(path).name)
            draw(path, spec)

    def _stop(self) -> None:
        """End the worker without a figure (it reads the end of its input and exits)."""
        if self.proc is None:
            return
        try:
            self.proc.communicate(timeout=WAIT_S)
        except (subprocess.TimeoutExpired, OSError):
            self.proc.kill()
            self.proc.communicate()
        self.proc = None

    def __enter__(self) -> "Painter":
        return self.start()

    def __exit__(self, *exc) -> None:
        if exc[0] is None:
            self.finish()
        elif self.proc is not None:  # an error on the way: the worker's figure will not be needed
            self.proc.kill()
            self.proc.communicate()
            self.proc = None


if __name__ == "__png_worker__":
    sys.exit(_serve())
