"""The energy-diagram PNG: reduced energy against the parameter, one line per branch, stable
(``second_order_min_eigenvalue`` > 0 at both ends of a segment: the reduced Hessian without the
symmetry modes is positive) solid, unstable dashed, with small insets of
the shapes (the zero level of phi: the 2D field, a central cut of a 3D one) read from the snapshots.

matplotlib is imported here only (Agg backend: files, no windows).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from vesicle_opt.io.files import load_npz  # noqa: E402

INSETS = 4  # shapes drawn per branch


def _cut(snapshot: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """(field section, its box (2, 2)) of a grid snapshot; None off grids."""
    grid = tuple(int(k) for k in np.atleast_1d(snapshot.get("grid_shape", ())))
    if not grid:
        return None
    phi = np.asarray(snapshot["phi"], float).reshape(grid)
    box = np.asarray(snapshot["box"], float)
    if int(snapshot.get("mirror_cells", 1)) > 1:  # one mirror cell: the whole vesicle, centred
        for axis in range(phi.ndim):
            phi = np.concatenate([np.flip(phi, axis=axis), phi], axis=axis)
        box = np.column_stack([2 * box[:, 0] - box[:, 1], box[:, 1]])
    if len(grid) == 3:
        return phi[:, phi.shape[1] // 2, :], box[[0, 2]]  # the y = mid plane: x (long axis) against z
    return phi, box


def plot(series: list[tuple[str, list[dict], Path | None]], path: Path, xlabel: str = "reduced volume",
         xkey: str = "target", title: str = "", events: list[dict] = (), dim: int = 3) -> None:
    """``series``: (label, accepted rows of one branch, its snapshot directory or None);
    ``events``: located event rows (``branch.events``), marked x (branch point) or v (fold). The one
    legend convention of the package's figures: solid stable, dashed unstable; in 2D the axis
    says reduced area and E / E_circle (the circle of the same perimeter), in 3D reduced volume
    and E / E_sphere."""
    if dim == 2 and xlabel == "reduced volume":
        xlabel = "reduced area"
    fig, ax = plt.subplots(figsize=(7.5, 5))
    for kind, marker in (("branch point", "x"), ("fold", "v")):
        pts = [(r[xkey], r["reduced_energy"]) for r in events if r.get("event") == kind and r.get("reduced_energy") is not None]
        if pts:
            ax.plot(*zip(*pts), marker, color="k", ms=8, label=kind, zorder=5)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (label, rows, points) in enumerate(series):
        rows = [r for r in rows if r.get("reduced_energy") is not None]
        if not rows:
            continue
        c = colors[k % len(colors)]
        x = np.array([r[xkey] for r in rows], float)
        y = np.array([r["reduced_energy"] for r in rows], float)
        stable = [(r.get("second_order_min_eigenvalue") or -1.0) > 0 for r in rows]
        for i in range(len(rows) - 1):
            ls = "-" if stable[i] and stable[i + 1] else "--"
            ax.plot(x[i:i + 2], y[i:i + 2], ls, color=c, lw=1.8, label=label if i == 0 else None)
        if len(rows) == 1:
            ax.plot(x, y, "o", color=c, label=label)
        ax.plot(x, y, ".", color=c, ms=4)
        if points is None:
            continue
        for j in np.unique(np.linspace(0, len(rows) - 1, min(INSETS, len(rows))).round().astype(int)):
            snap = load_npz(Path(points) / f"point-{int(rows[j]['point']):04d}.npz")
            cut = None if snap is None else _cut(snap)
            if cut is None:
                continue
            field, box = cut
            axi = fig.add_axes([0, 0, 0.1, 0.1])  # moved beside its point once the limits are fixed
            axi.contour(np.linspace(*box[0], field.shape[0], endpoint=False),
                        np.linspace(*box[1], field.shape[1], endpoint=False), field.T, levels=[0.0], colors=[c])
            axi.set_aspect("equal")
            axi.set_xticks([])
            axi.set_yticks([])
            axi._anchor_data = (x[j], y[j])
    ax.set_xlabel(xlabel)
    ax.set_ylabel("reduced energy E / E_circle" if dim == 2 else "reduced energy E / E_sphere")
    ax.set_title(title or "energy diagram (solid: least reduced-Hessian eigenvalue > 0, dashed: < 0)")
    if ax.get_legend_handles_labels()[0]:  # no certified point: no labelled line, no legend (nor matplotlib's warning)
        ax.legend(fontsize=8, loc="best")
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.1, top=0.93)
    fig.canvas.draw()
    for axi in fig.axes[1:]:  # the insets beside their points, in figure coordinates
        px, py = fig.transFigure.inverted().transform(ax.transData.transform(axi._anchor_data))
        w = axi.get_position().width
        h = w * fig.get_figwidth() / fig.get_figheight()
        box = ax.get_position()  # kept inside the plot area
        px = min(max(px + 0.01, box.x0), box.x1 - w)
        py = min(max(py + 0.01, box.y0), box.y1 - h)
        axi.set_position([px, py, w, h])
    fig.savefig(path, dpi=110)
    plt.close(fig)
