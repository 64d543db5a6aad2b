"""The phase-diagram PNG of a transition line (``branch.transition``): in the (v, c0) plane (c0 the
literature's C0 R0, ``c0_reduced``), the regions labelled by the branch of lowest energy, the
transition line v*(c0) through its certified crossings, optional fold lines and a sharp-interface
line, and small meridian pictures (the phi = 0 curve of both branches' fields at a few crossings,
mirrored about the axis: the 3D silhouette; ``io.meridian``).

Which branch is lowest on each side: Delta(v) = E_a - E_b changes sign at v* with the slope
dDelta/dv = a_dE_dp - b_dE_dp (the envelope derivatives of the row): above v*, a is lowest where
that slope is negative. A branch is named by its meridian's form at the crossing (``form``:
"prolate" when the height exceeds the width, else "oblate"), or "a"/"b" off the meridian mesh.

matplotlib is imported here only (Agg backend: files, no windows).
"""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from vesicle_opt.verify.updown import CUP, form  # noqa: E402,F401  (the meridian's form: prolate, oblate, cup)

PICTURES = 3  # crossings drawn with their two shapes: the ends and the middle of the line


def _curves(disc, phi):
    if getattr(disc, "kind", None) != "axisymmetric":
        return None
    from vesicle_opt.io.meridian import meridian_curves  # scikit-fem's mesh: meridian meshes only
    return meridian_curves(disc, phi)


def _on_mesh(disc, field):
    """(mesh, phi) of ``phi_of``'s answer: a field on ``disc``, or (its own mesh, field) where each
    point has its own (interface-refined meshes)."""
    return field if isinstance(field, tuple) else (disc, field)


def plot(points: list[dict], disc, phi_of, path: Path, folds: list[list[tuple[float, float]]] = (),
         reference: list[tuple[float, float]] | None = None, title: str = "", others=()) -> None:
    """Draw ``points`` (certified line rows, by c0; ``phi_of(row, "a"|"b")`` their fields, or
    (mesh, field) pairs where each has its own mesh) to
    ``path`` (module docstring); ``folds``: lines of (v, c0_reduced); ``reference``: the sharp
    line as (v, c0_reduced); ``others``: (label, [(v, c0_reduced)]) more crossings as markers
    (e.g. another resolution's)."""
    pts = sorted(points, key=lambda r: r["c0_reduced"] if r.get("c0_reduced") is not None else r["value"])
    if not pts:
        return
    cy = np.array([r["c0_reduced"] if r.get("c0_reduced") is not None else r["value"] for r in pts], float)
    vx = np.array([r["target"] for r in pts], float)
    shapes = {x: [_curves(*_on_mesh(disc, phi_of(r["row"], x))) for r in pts] for x in ("a", "b")}
    names = {x: next((form(c) for c in shapes[x] if form(c) in ("prolate", "oblate")), x) for x in ("a", "b")}
    slope = np.mean([r["a_dE_dp"] - r["b_dE_dp"] for r in pts if r.get("a_dE_dp") is not None] or [0.0])
    above, below = ("a", "b") if slope < 0 else ("b", "a")
    fig, ax = plt.subplots(figsize=(7.0, 5.0))
    vs = list(vx) + [v for v, _ in reference or []] + [v for f in folds for v, _ in f] + \
        [v for _, o in others for v, _ in o]
    lo, hi = min(vs) - 0.06, max(vs) + 0.06
    ax.fill_betweenx(cy, vx, hi, color="C0", alpha=0.12)
    ax.fill_betweenx(cy, lo, vx, color="C3", alpha=0.12)
    ax.text(hi - 0.01, cy.mean(), f"{names[above]}\nlowest", ha="right", va="center", color="C0")
    ax.text(lo + 0.01, cy.mean(), f"{names[below]}\nlowest", ha="left", va="center", color="C3")
    ax.plot(vx, cy, "k.-", label="transition line (certified crossings)")
    if reference:
        rv, rc = zip(*sorted(reference, key=lambda t: t[1]))
        ax.plot(rv, rc, "k:", label="sharp interface")
    for k, (label, o) in enumerate(others):
        ov, oc = zip(*o)
        ax.plot(ov, oc, "s", mfc="none", color=f"C{k + 4}", label=label)
    for k, fold in enumerate(folds):
        fv, fc = zip(*fold)
        ax.plot(fv, fc, "--", color="C2", label="fold line" if k == 0 else None)
    cs = list(cy) + [c for _, c in reference or []] + [c for _, o in others for _, c in o]
    span = max(max(cs) - min(cs), 0.1)
    ylo, yhi = min(cs) - 0.15 * span, max(cs) + 0.15 * span
    picks = sorted({0, len(pts) // 2, len(pts) - 1})[:PICTURES]
    for i in picks:  # fixed-size insets (axes fractions) beside the crossing, each in its own region
        xf, yf = (vx[i] - lo) / (hi - lo), (cy[i] - ylo) / (yhi - ylo)
        for x, dx in ((below, -1), (above, +1)):
            curves = shapes[x][i]
            if not curves:
                continue
            box = ax.inset_axes((xf + (0.015 if dx > 0 else -0.135), yf - 0.07, 0.12, 0.14))
            for c in curves:
                box.plot(c[:, 0], c[:, 1], "k-", lw=0.8)
                box.plot(-c[:, 0], c[:, 1], "k-", lw=0.8)
            box.set_aspect("equal", adjustable="datalim")
            box.axis("off")
    ax.set_ylim(ylo, yhi)
    ax.set_xlim(lo, hi)
    ax.set_xlabel("reduced volume v")
    ax.set_ylabel("c0 = C0 R0")
    ax.set_title(title or f"transition line: {names['a']} / {names['b']}")
    ax.legend(fontsize=7, loc="lower left")
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.png")  # drawn beside, then moved
    try:
        fig.tight_layout()
        fig.savefig(tmp, dpi=110)
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
