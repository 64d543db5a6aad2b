"""Theorem 3.4: h_n -> 0 and M_n -> inf together; a practical rule M(h).

One case per mesh n: the exact-constraint minimiser phi*_h and a warm-started continuation
M = 1e1 ... 1e8 (rows: the penalty error |phi_{M,h} - phi*_h|_{H1} and |E_{M,h} - E*_h|/E*_h on
the same mesh). The discretisation error of phi*_h is measured against the finest mesh of the
sequence (``metrics.restrict``), and its energy against the Richardson limit of the three finest.
The penalty error is c/M over BIAS_RANGE (Theorem 3.2 study), so c = median of M e_pen there, and
``diagonal_rule.csv`` gives, per h, the M at which the penalty error equals the discretisation
error, M(h) = c / e_disc(h) (H1 and energy); beyond it the total error is at most 2 e_disc. A
fitted power law M(h) ~ h^-q is printed (e_pen ~ 1/M and e_disc ~ h^2 predict q = 2).
"""

from __future__ import annotations

import logging
import csv
import math
from pathlib import Path

import numpy as np

from vesicle_opt.studies._common import EXTRA, column, load, nlp_for, plt, row, savefig, select
from vesicle_opt.model.penalty import schedule
from vesicle_opt.nlp.continuation import continuation
from vesicle_opt.mesh import discretize
from vesicle_opt.verify.metrics import field_errors, observed_order, restrict, richardson
from vesicle_opt.api import solve
from vesicle_opt.studies.runner import run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

NAME = "diagonal"
MS = schedule(10.0, 10.0, 1e8)
BIAS_RANGE = (1e2, 1e6)  # where the penalty error is c/M (penalty_continuation: slopes -1.00 there)


def cases(quick: bool, fields: Path) -> list[dict]:
    ns = [48, 64, 96] if quick else [64, 96, 128, 192, 256]
    return [{"case": f"ellipse-2d-{n}", "scene": "ellipse-2d", "n": n, "fields": str(fields)} for n in ns]


def run(case: dict) -> list[dict]:
    nlp = nlp_for(case["scene"], [f"mesh.n={case['n']}", 'solver.method="continuation"'])
    disc = nlp.disc
    exact = solve(nlp.exact)
    np.savez(Path(case["fields"]) / f"{case['case']}.npz", phi=exact.phi)
    rows = [row(exact, case["scene"], "exact", case["n"], disc.h)]
    continuation(nlp, MS, stage_callback=lambda k, r: rows.append(
        row(r, case["scene"], "continuation", case["n"], disc.h, ref=exact, disc=disc)))
    return rows


def rule(rows: list[dict], fields: Path) -> list[dict]:
    ex = sorted(select(rows, method="exact"), key=lambda r: -float(r["h"]))
    ns = [int(r["n"]) for r in ex]
    scene = ex[0]["scene"]
    discs = {n: discretize(load(scene, [f"mesh.n={n}"])) for n in ns}
    phis = {n: np.load(fields / f"ellipse-2d-{n}.npz")["phi"] for n in ns}
    E = [float(r["energy"]) for r in ex]
    E_inf, _ = richardson([float(r["h"]) for r in ex], E) if len(ex) >= 3 else (E[-1], math.nan)
    out = []
    for r, n in zip(ex[:-1], ns[:-1]):  # the finest mesh is the reference
        e_disc = field_errors(discs[n], phis[n], restrict(discs[ns[-1]], discs[n], phis[ns[-1]]))["error_h1"]
        e_disc_E = abs(float(r["energy"]) - E_inf) / abs(E_inf)
        pen = select(rows, n=n, method="continuation")
        M, eh1, eE = column(pen, "M"), column(pen, "error_h1"), column(pen, "error_energy")
        fit = (M >= BIAS_RANGE[0]) & (M <= BIAS_RANGE[1])
        c_h1, c_E = float(np.median(M[fit] * eh1[fit])), float(np.median(M[fit] * eE[fit]))
        out.append({"n": n, "h": float(r["h"]), "disc_error_h1": e_disc, "disc_error_energy": e_disc_E,
                    "penalty_constant_h1": c_h1, "penalty_constant_energy": c_E,
                    "M_rule_h1": c_h1 / e_disc, "M_rule_energy": c_E / e_disc_E})
    return out


def figure(rows, rules, path: Path) -> None:
    pyplot = plt()
    fig, axes = pyplot.subplots(1, 2, figsize=(12, 4.5))
    for k, n in enumerate(sorted({int(r["n"]) for r in rows})):
        pen = select(rows, n=n, method="continuation")
        line = axes[0].loglog(column(pen, "M"), column(pen, "error_h1"), "o-", label=f"penalty error, n={n}")
        for ru in rules:
            if ru["n"] == n:
                axes[0].axhline(ru["disc_error_h1"], ls="--", color=line[0].get_color(),
                                label=f"discretisation error, n={n}")
    axes[0].set_xlabel("M")
    axes[0].set_ylabel("H1 error")
    axes[0].legend(fontsize=7)
    axes[0].set_title("Theorem 3.4: penalty vs discretisation error")
    h = np.array([r["h"] for r in rules])
    axes[1].loglog(h, [r["M_rule_h1"] for r in rules], "o-", label="M(h), H1")
    axes[1].loglog(h, [r["M_rule_energy"] for r in rules], "s-", label="M(h), energy")
    axes[1].set_xlabel("h")
    axes[1].set_ylabel("M(h): penalty error = discretisation error")
    axes[1].legend(fontsize=8)
    savefig(fig, path)


def main(out, quick: bool = False, executor=None) -> int:
    out = Path(out)
    fields = out / "fields"
    fields.mkdir(parents=True, exist_ok=True)
    rows = run_cases(NAME, cases(quick, fields), run, out / f"{NAME}.csv", executor=executor,
                     extra_columns=EXTRA)
    rules = rule(rows, fields)
    q = -observed_order([r["h"] for r in rules], [r["M_rule_h1"] for r in rules])
    with open(out / f"{NAME}_rule.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rules[0]) + ["fitted_q"], lineterminator="\n")
        w.writeheader()
        w.writerows([{**r, "fitted_q": q} for r in rules])
    for r in rules:
        log.info(f"n={r['n']}: discretisation H1 error {r['disc_error_h1']:.3g}, M(h) = {r['M_rule_h1']:.3g} (H1), "
              f"{r['M_rule_energy']:.3g} (energy)")
    log.info(f"fitted M(h) ~ h^-{q:.2f}")
    figure(rows, rules, out / f"{NAME}.png")
    return 0
