"""Theorem 3.2: minimisers of the penalised energy E_{M,h} (11) approach the constrained one as M -> inf.

Per scene: the exact-constraint solution phi* on the mesh (IPOPT), then ONE warm-started penalty
continuation M = M0, 10 M0, ..., M_max on one solver. Every stage is a CSV row with E_h, E_{M,h},
A - alpha, B - beta, the multiplier estimates -M(A - alpha), -M(B - beta), |phi_M - phi*|_{H1},
|Delta_h phi_M - Delta_h phi*|_{L2}, iterations and wall time, each against the nearer of two exact references (from the scene's start, and an exact
solve from the last penalty stage: the problem is non-convex with near-degenerate translation
families on the periodic box). ``<out>/penalty_continuation_rates.csv``
holds the observed rates against M (least-squares slopes over FIT_RANGE, expected -1: the bias
is O(1/M)) and the figure shows all of them. Full mode adds sphere-3d and a cold-started
continuation (every stage from the initial shape) to measure what the warm starts buy.
"""

from __future__ import annotations

import logging
import csv
from pathlib import Path

import numpy as np

from vesicle_opt.studies._common import EXTRA, column, nlp_for, plt, row, savefig, select
from vesicle_opt.model.penalty import schedule
from vesicle_opt.nlp.continuation import continuation
from vesicle_opt.verify.metrics import observed_order
from vesicle_opt.api import solve
from vesicle_opt.nlp.ipopt import IpoptOptions
from vesicle_opt.studies.runner import run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

NAME = "penalty_continuation"
FIT_RANGE = (1e2, 1e6)  # above ~1e6 round-off in M (A - alpha) (penalty.roundoff_floor) competes with the 1/M bias
RATE_BAND = (-1.15, -0.85)  # O(1/M): slope -1; +-0.15 allows the O(1/M^2) curvature seen from M = 1e2
QUANTITIES = ("volume_residual", "area_residual", "error_energy", "error_h1", "error_lambda")


def cases(quick: bool) -> list[dict]:
    Ms = schedule(10.0, 10.0, 1e8)
    out = [{"case": "ellipse-2d-64" if quick else "ellipse-2d-128", "scene": "ellipse-2d",
            "overrides": ["mesh.n=64" if quick else "mesh.n=128"], "Ms": Ms, "warm": True}]
    if not quick:
        out.append({"case": "ellipse-2d-128-cold", "scene": "ellipse-2d", "overrides": ["mesh.n=128"],
                    "Ms": Ms, "warm": False})
        out.append({"case": "sphere-3d-16", "scene": "sphere-3d", "overrides": ["mesh.n=16"], "Ms": Ms,
                    "warm": True})
    return out


def run(case: dict) -> list[dict]:
    over = list(case["overrides"]) + ['solver.method="continuation"']
    nlp = nlp_for(case["scene"], over)
    disc, n = nlp.disc, nlp.scene.mesh.n[0]
    exact = solve(nlp.exact)
    stages = []
    continuation(nlp, case["Ms"], warm=case["warm"], stage_callback=lambda k, r: stages.append(r))
    # Non-convex, with near-degenerate translation families on the periodic box: an exact solve
    # started from the last penalty stage may end on another constrained stationary point (seen:
    # 64^2, the warm path slides at M = 1e7 to a translated state 3e-5 lower in energy; sphere-3d
    # 16^3, 0.1% lower). Theorem 3.2 speaks of convergence to *some* minimiser, so each stage is
    # measured against the nearer (aligned H1) of the two references, named in ``reference``.
    # constraints to 1e-14: at tol 1e-8 the M = 1e8 stage (residual 4e-9/|Omega|) passes as exact
    polish = solve(nlp.exact, x0=stages[-1].x[: nlp.n_base],
                   options=IpoptOptions(tol=nlp.scene.solver.tol, extra=(("ipopt.constr_viol_tol", 1e-14),)))
    refs = [("scene start", exact)]
    if polish.converged and np.linalg.norm(polish.phi - exact.phi) > 0:
        refs.append(("penalty endpoint", polish))
    method = "continuation" if case["warm"] else "continuation-cold"
    rows = [row(ref, case["scene"], "exact", n, disc.h, error_lambda=0.0, reference=name) for name, ref in refs]
    for r in stages:
        cands = []
        for name, ref in refs:
            lam_ref = np.hypot(ref.lambda_volume, ref.lambda_area)
            err_lam = np.hypot(r.lambda_volume - ref.lambda_volume, r.lambda_area - ref.lambda_area) / lam_ref
            cands.append(row(r, case["scene"], method, n, disc.h, ref=ref, disc=disc, error_lambda=err_lam,
                             error_penalized=abs(r.penalized_energy - ref.energy) / abs(ref.energy),
                             reference=name))
        rows.append(min(cands, key=lambda c: c["error_h1"]))
    for r in rows:
        if not all(ref.converged for _, ref in refs):
            r["status"] = f"{r['status']} (a reference did not converge)"
    return rows


def rates(rows: list[dict]) -> list[dict]:
    out = []
    for scene_case in sorted({r["case"] for r in rows if r["method"] == "continuation"}):
        sel = select(rows, case=scene_case, method="continuation")
        M = column(sel, "M")
        if not len(M):
            continue
        keep = (M >= FIT_RANGE[0]) & (M <= FIT_RANGE[1])
        for q in QUANTITIES:
            v = np.abs(column(sel, q))
            out.append({"case": scene_case, "quantity": q, "rate": observed_order(M[keep], v[keep]),
                        "M_from": FIT_RANGE[0], "M_to": FIT_RANGE[1]})
    return out


def figure(rows: list[dict], path: Path) -> None:
    pyplot = plt()
    cases_ = sorted({r["case"] for r in rows if r["method"] == "continuation"})
    fig, axes = pyplot.subplots(1, len(cases_), figsize=(6 * len(cases_), 4.5), squeeze=False)
    for ax, c in zip(axes[0], cases_):
        sel = select(rows, case=c, method="continuation")
        M = column(sel, "M")
        for q, lab in [("volume_residual", "|A-alpha|"), ("area_residual", "|B-beta|"),
                       ("error_energy", "|E-E*|/E*"), ("error_h1", "|phi_M-phi*|_H1"),
                       ("error_lambda", "|lambda_M-lambda*|/|lambda*|")]:
            ax.loglog(M, np.abs(column(sel, q)), "o-", label=lab)
        ax.loglog(M, 1.0 / M, "k--", label="1/M")
        ax.set_xlabel("M")
        ax.set_title(f"Theorem 3.2: {c}")
        ax.legend(fontsize=7)
    savefig(fig, path)


def main(out, quick: bool = False, executor=None) -> int:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = run_cases(NAME, cases(quick), run, out / f"{NAME}.csv", executor=executor,
                     extra_columns=EXTRA + ["error_lambda", "error_penalized", "reference"])
    rs = rates(rows)
    with open(out / f"{NAME}_rates.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ["case", "quantity", "rate", "M_from", "M_to"], lineterminator="\n")
        w.writeheader()
        w.writerows(rs)
    figure(rows, out / f"{NAME}.png")
    bad = [r for r in rs if not RATE_BAND[0] <= r["rate"] <= RATE_BAND[1]]
    for r in rs:
        log.info(f"{r['case']}: rate of {r['quantity']} against M = {r['rate']:.3f}")
    if bad:
        log.warning(f"{NAME}: rates outside {RATE_BAND}: {bad}")
        return 1
    return 0
