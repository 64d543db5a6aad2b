"""Theorem 3.3 / Corollary 3.2: discrete minimisers converge as h -> 0 (phi^h in H^1, Delta_h phi^h in L^2).

One case per (scene, discretisation, method) solves a sequence of meshes n_1 < ... < n_K (exact
constraints, and the penalty (11) at fixed M = M_FIXED) and measures against the finest mesh:
|phi_n - phi_K|_{H1} and |Delta_h phi_n - Delta_h phi_K|_{L2} on the coarse mesh (the fine field
restricted by ``metrics.restrict``; this overstates orders near the finest mesh, so the differences
between consecutive meshes, diff_h1 and diff_lap, are fitted too: on a geometric sequence their slope
is the true order), and the energy against the Richardson limit E_inf of the three
finest meshes (E = E_inf + C h^p solved for E_inf, C, p). ``h_refinement_orders.csv`` gives the
observed orders (np.polyfit of log error against log h). The constraint data (alpha, beta) of a
target-shape scene are evaluated on each mesh, so they converge with the same order.
Quick: FD, exact, n = 54, 72, 96, 128 (ratio 4/3). Full: FD, P1 lumped and P1 consistent, exact and
penalty, 2D to 256^2 (P1 consistent to 128^2); sphere-3d (P1 lumped, exact) to 32^3.
"""

from __future__ import annotations

import logging
import csv
import math
from pathlib import Path

import numpy as np

from vesicle_opt.studies._common import EXTRA, column, nlp_for, plt, row, savefig, select
from vesicle_opt.verify.metrics import field_errors, observed_order, restrict, richardson
from vesicle_opt.api import solve
from vesicle_opt.studies.runner import run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

NAME = "h_refinement"
M_FIXED = 1e4
DISCS = {"fd": ["mesh.kind=\"fd\""],
         "fem-lumped": ["mesh.kind=\"fem-p1\"", "mesh.mass=\"lumped\""],
         "fem-consistent": ["mesh.kind=\"fem-p1\"", "mesh.mass=\"consistent\""]}


def cases(quick: bool) -> list[dict]:
    if quick:
        return [{"case": "ellipse-2d-fd-exact", "scene": "ellipse-2d", "disc": "fd", "method": "exact",
                 "ns": [54, 72, 96, 128]}]
    out = []
    for disc in DISCS:
        # P1 consistent needs 90-190 IPOPT iterations here (128^2: 216 s measured), so it stops at 128^2
        ns = [54, 72, 96, 128] if disc == "fem-consistent" else [54, 72, 96, 128, 192, 256]
        for method in ("exact", "penalty"):
            out.append({"case": f"ellipse-2d-{disc}-{method}", "scene": "ellipse-2d", "disc": disc,
                        "method": method, "ns": ns})
    out.append({"case": "sphere-3d-fem-lumped-exact", "scene": "sphere-3d", "disc": "fem-lumped",
                "method": "exact", "ns": [12, 16, 24, 32]})
    return out


def run(case: dict) -> list[dict]:
    results = []
    for n in case["ns"]:
        over = DISCS[case["disc"]] + [f"mesh.n={n}"]
        if case["method"] == "penalty":
            over += ['solver.method="penalty"', f"solver.M={M_FIXED}"]
        nlp = nlp_for(case["scene"], over)
        results.append((n, nlp.disc, solve(nlp)))
    _, fine_disc, fine = results[-1]
    h = [d.h for _, d, _ in results]
    E_inf, p = richardson(h, [r.energy for _, _, r in results])
    rows = []
    for k, (n, disc, r) in enumerate(results):
        ref = restrict(fine_disc, disc, fine.phi)
        nxt = restrict(results[k + 1][1], disc, results[k + 1][2].phi) if k + 1 < len(results) else None
        errs = field_errors(disc, r.phi, ref) if r is not fine else {"error_h1": 0.0, "error_lap": 0.0}
        diff = field_errors(disc, r.phi, nxt) if nxt is not None else {"error_h1": math.nan, "error_lap": math.nan}
        rows.append(row(r, case["scene"], case["method"], n, disc.h, setting=case["disc"], **errs,
                        error_energy=abs(r.energy - E_inf) / abs(E_inf), energy_limit=E_inf,
                        energy_order=p, diff_h1=diff["error_h1"], diff_lap=diff["error_lap"]))
    return rows


def orders(rows: list[dict]) -> list[dict]:
    out = []
    for c in sorted({r["case"] for r in rows}):
        sel = select(rows, case=c)
        h = column(sel, "h")
        coarse = slice(0, len(sel) - 1)  # the finest is the reference of the field errors
        out.append({"case": c, "order_h1": observed_order(h[coarse], column(sel, "error_h1")[coarse]),
                    "order_lap": observed_order(h[coarse], column(sel, "error_lap")[coarse]),
                    "order_energy": observed_order(h, column(sel, "error_energy")),
                    "order_h1_successive": observed_order(h[coarse], column(sel, "diff_h1")[coarse]),
                    "order_lap_successive": observed_order(h[coarse], column(sel, "diff_lap")[coarse]),
                    "richardson_order": column(sel, "energy_order")[0]})
    return out


def figure(rows, path: Path) -> None:
    pyplot = plt()
    fig, axes = pyplot.subplots(1, 3, figsize=(15, 4.5))
    for c in sorted({r["case"] for r in rows}):
        sel = select(rows, case=c)
        h = column(sel, "h")
        for ax, q in zip(axes, ("error_h1", "error_lap", "error_energy")):
            v = column(sel, q)
            ok = v > 0
            ax.loglog(h[ok], v[ok], "o-", label=c)
    for ax, q in zip(axes, ("|phi_h - phi_fine|_H1", "|Lap_h phi_h - Lap_h phi_fine|_L2", "|E_h - E_inf|/E_inf")):
        hs = column(rows, "h")
        ax.loglog(hs, 0.5 * np.nanmax(hs) ** -2 * hs**2 * 1e-1, "k--", label="h^2")
        ax.set_xlabel("h")
        ax.set_title(q)
    axes[0].legend(fontsize=7)
    savefig(fig, path)


def main(out, quick: bool = False, executor=None) -> int:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = run_cases(NAME, cases(quick), run, out / f"{NAME}.csv", executor=executor,
                     extra_columns=EXTRA + ["energy_limit", "energy_order", "diff_h1", "diff_lap"])
    od = orders(rows)
    with open(out / f"{NAME}_orders.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(od[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(od)
    for o in od:
        log.info(f"{o['case']}: observed orders H1 {o['order_h1']:.2f}, Lap L2 {o['order_lap']:.2f}, "
              f"energy {o['order_energy']:.2f} (Richardson p = {o['richardson_order']:.2f}); successive "
              f"differences: H1 {o['order_h1_successive']:.2f}, Lap L2 {o['order_lap_successive']:.2f}")
    figure(rows, out / f"{NAME}.png")
    return 0
