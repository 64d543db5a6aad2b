"""The figure of the ``phase_diagram`` study (not a study): f against v per eps with the sharp branches,
the transitions (per eps, eps -> 0, sharp, published) and small meridian pictures of the shapes."""

from __future__ import annotations

import logging
import math
import warnings
from pathlib import Path

from vesicle_opt.sharp import axisymmetric as sharp
from vesicle_opt.sharp import stomatocyte as sharp_s
from vesicle_opt.studies import _stomatocyte as stoma
from vesicle_opt.studies._common import plt, savefig
from vesicle_opt.studies._common import num as _num

log = logging.getLogger(__name__)
BRANCHES = ("prolate", "oblate")


def figure(rows: list[dict], summary: dict, path: Path, published: dict) -> None:
    """``path``: f against v (module docstring); h-level rows are left out (their branches' points
    are the eps/h = 4 walks); the eps -> 0 limits of the h-corrected transitions as filled diamonds."""
    rows = [r for r in rows if r.get("kind") != "h_level"]
    pyplot = plt()
    fig = pyplot.figure(figsize=(6.5, 6))
    ax = fig.add_axes([0.12, 0.3, 0.84, 0.64])
    for b, colour in zip(BRANCHES, ("C0", "C3")):
        sel = sorted([r for r in rows if r["branch"] == b and math.isfinite(_num(r.get("sharp_f")))],
                     key=lambda r: _num(r["target_v"]))
        ax.plot([_num(r["target_v"]) for r in sel], [_num(r["sharp_f"]) for r in sel], "-", color=colour,
                label=f"{b}, sharp")
        for eps in sorted({_num(r["epsilon"]) for r in sel}):
            pts = [r for r in sel if _num(r["epsilon"]) == eps and str(r["converged"]) == "True"
                   and r.get("shape") in (b, None, "")]  # a torus or a cup is not this branch's point
            ax.plot([_num(r["reduced_volume"]) for r in pts], [_num(r["f"]) for r in pts], "o--", color=colour,
                    ms=4, alpha=0.5 + 0.5 * (eps == min(_num(q["epsilon"]) for q in sel)), label=f"{b}, eps {eps:g}")
    for e, x in summary.get("crossings", {}).items():
        ax.plot(x["v"], x["f"], "kx")
    corrected = [summary.get("extrapolated_h_corrected", {})] + [summary.get(k, {}).get("extrapolated_h_corrected", {})
                                                                 for k in ("stomatocyte_fold", "oblate_stomatocyte_crossing")]
    for ext in corrected:
        if math.isfinite(_num(ext.get("reduced_volume_p2"))):
            ax.plot(ext["reduced_volume_p2"], ext["reduced_energy_p2"], "D", color="k", ms=5)
    ax.plot([], [], "D", color="k", ms=5, label="eps -> 0, h-corrected")
    _stomatocyte_panel(ax, rows, summary)
    for name, (v, f) in published.items():
        if "c0=2.4" not in name:
            ax.plot(v, f, "s", mfc="none", mec="k", ms=8)
    ax.plot([], [], "s", mfc="none", mec="k", label="published (SBL 1991)")
    ax.set_xlabel("reduced volume v")
    ax.set_ylabel("f = F / 8 pi kappa")
    ax.set_title("c0 = 0: prolate, oblate, stomatocyte (meridian half-plane)")
    ax.legend(fontsize=6, loc="upper right")
    _meridian_insets(fig, rows)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # tight_layout skips the placed axes: they are placed by hand
        savefig(fig, path)


def _stomatocyte_panel(ax, rows: list[dict], summary: dict) -> None:
    """The stomatocyte: sharp lower/upper sides (eps = 0 rows), phase-field points per eps, and the
    fold / oblate crossing (sharp: stars, per eps: plus signs, eps -> 0: a diamond)."""
    st = [r for r in rows if r["branch"] == "stomatocyte" and str(r.get("converged")) == "True"]
    for side, style in (("lower", "-"), ("upper", ":")):
        pts = sorted([(_num(r["reduced_volume"]), _num(r["f"])) for r in st if _num(r["epsilon"]) == 0
                      and r.get("kind") == "point" and r.get("side") == side])
        if pts:
            ax.plot(*zip(*pts), style, color="C2", label=f"stomatocyte, sharp ({side})")
    for eps in sorted({_num(r["epsilon"]) for r in st} - {0.0}):
        pts = [(_num(r["reduced_volume"]), _num(r["f"])) for r in st if _num(r["epsilon"]) == eps and r.get("kind") == "point"]
        ax.plot(*zip(*pts), "^", color="C2", ms=3, alpha=0.7, label=f"stomatocyte, eps {eps:g}")
    for key in ("stomatocyte_fold", "oblate_stomatocyte_crossing"):
        entry = summary.get(key, {})
        if "sharp" in entry:
            ax.plot(entry["sharp"]["v"], entry["sharp"]["f"], "*", color="k", ms=8)
        for x in entry.get("per_eps", {}).values():
            ax.plot(x["v"], x["f"], "+", color="C2")
        ext = entry.get("extrapolated", {})
        if math.isfinite(_num(ext.get("reduced_volume_p2"))):
            ax.plot(ext["reduced_volume_p2"], ext["reduced_energy_p2"], "D", mfc="none", mec="C2")


def _meridian_insets(fig, rows: list[dict]) -> None:
    """Small meridian pictures (below the axes) of the sharp prolate (v 0.65), oblate (0.65) and
    stomatocyte (0.62)."""
    shapes = []
    try:
        for which in BRANCHES:
            shapes.append((which, sharp.solve(0.65, which, 8, second_order=False).meridian(256)))
        if any(r["branch"] == "stomatocyte" for r in rows):
            shapes.append(("stomatocyte", sharp_s.start_point(stoma.V_SEED, 0.0, 16).meridian(256)))
    except Exception as exc:  # noqa: BLE001 - a picture is decoration: say so, draw the rest
        log.warning(f"phase_diagram: meridian insets skipped ({type(exc).__name__}: {exc})")
    for i, (name, (r, z)) in enumerate(shapes):
        ins = fig.add_axes([0.12 + 0.22 * i, 0.02, 0.18, 0.17])
        ins.plot(r, z, "k-", lw=0.8)
        ins.plot(-r, z, "k-", lw=0.8)
        ins.set_aspect("equal")
        ins.axis("off")
        ins.set_title(name, fontsize=7)
