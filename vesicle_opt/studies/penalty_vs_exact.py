"""Work-precision: error against run time for exact constraints, penalty, continuation, augmented
Lagrangian and a Gauss-Newton SCP baseline (cvxpy), all on the same mesh of ellipse-2d.

The reference is the exact-constraint minimiser on the same mesh, at the scene's tol 1e-8 (a
tighter polish slides off-centre on the periodic box) (computed once, ``fields/reference-<n>.npz``). One CSV row per (method, setting, tolerance): wall time, IPOPT
iterations, |E - E*|/E*, |phi - phi*|_{H1}, A - alpha, B - beta. SCP records one row per checkpoint
of a single run (cumulative time). The figure plots H1 and energy error against wall time.
Penalty runs at fixed M start cold from the initial shape (the honest cost of a one-shot penalty).
``energy_difference`` = E - E* is signed: the problem is non-convex, and a method may end on another
constrained stationary point (seen: the 64^2 continuation to 1e8 slides at M = 1e7 to a translated
state 3.3e-5 lower in energy than the reference from the scene's start).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from vesicle_opt.studies._common import EXTRA, column, nlp_for, plt, row, savefig, select
from vesicle_opt.verify.metrics import field_errors
from vesicle_opt.api import solve
from vesicle_opt.nlp.ipopt import IpoptOptions
from vesicle_opt.nlp.scp import scp  # cvxpy, its optional dependency, is imported when scp runs
from vesicle_opt.studies.runner import run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

NAME = "penalty_vs_exact"
REF_TOL = 1e-8  # the scene's tol; 1e-10 ends Solved_To_Acceptable_Level on 48^2


def cases(quick: bool, fields: Path) -> list[dict]:
    n = 48 if quick else 64
    base = {"scene": "ellipse-2d", "n": n, "fields": str(fields)}
    tols = (1e-4, 1e-8) if quick else (1e-4, 1e-6, 1e-8)
    Ms = (1e2, 1e4, 1e8) if quick else (1e2, 1e4, 1e6, 1e8)
    out = [{**base, "case": f"exact-tol{t:g}", "method": "exact", "tol": t, "setting": f"tol={t:g}"}
           for t in tols]
    out += [{**base, "case": f"penalty-M{M:g}", "method": "penalty", "M": M, "tol": 1e-8, "setting": f"M={M:g}"}
            for M in Ms]
    out += [{**base, "case": f"continuation-Mmax{M:g}", "method": "continuation", "M_max": M, "tol": 1e-8,
             "setting": f"M_max={M:g}"} for M in Ms[1:]]
    out += [{**base, "case": f"augmented-tol{t:g}", "method": "augmented", "tol": t, "setting": f"tol={t:g}"}
            for t in tols[1:]]
    try:
        import cvxpy  # noqa: F401 - optional extra (local: the study runs without it)
        out.append({**base, "case": "scp", "method": "scp", "tol": 1e-8, "max_iter": 6 if quick else 60,
                    "setting": "Gauss-Newton SCP"})
    except ImportError:
        pass
    return out


def reference(n: int, fields: Path):
    path = fields / f"reference-{n}.npz"
    if not path.exists():
        nlp = nlp_for("ellipse-2d", [f"mesh.n={n}"])
        # NOT polished at a tighter tol: on the periodic box a polish from it was seen to slide
        # off-centre to another (grid-pinned, 0.2% lower) minimiser, |phi - phi*|_H1 = 1 (48^2);
        # every method starts from the same centred, symmetric shape and stays centred.
        r = solve(nlp, options=IpoptOptions(tol=REF_TOL))
        # then its constraints to 1e-14 from there (a Newton step; stays on the same state)
        r = solve(nlp, x0=r,  # the primal-dual point of the first solve
                  options=IpoptOptions(tol=REF_TOL, extra=(("ipopt.constr_viol_tol", 1e-14),)))
        if not r.converged:
            raise RuntimeError(f"reference solve did not converge: {r.status}")
        np.savez(path, phi=r.phi, energy=r.energy, lam=[r.lambda_volume, r.lambda_area])
    return np.load(path)


def run(case: dict) -> list[dict]:
    ref = reference(case["n"], Path(case["fields"]))
    E_ref = float(ref["energy"])
    over = [f"mesh.n={case['n']}", f"solver.tol={case['tol']}"]
    if case["method"] == "scp":
        nlp = nlp_for(case["scene"], over)
        rows = []
        checkpoints = {1, 2, 4, 8, 16, 32, case["max_iter"]}  # cumulative time

        def rec(k, phi, info):
            if k + 1 in checkpoints:
                rows.append({"scene": case["scene"], "method": "scp", "n": case["n"], "h": nlp.disc.h,
                             "energy": info["energy"], "volume_residual": info["volume_residual"],
                             "area_residual": info["area_residual"], "iterations": info["iterations"],
                             "wall_time_s": info["wall_time_s"], "status": "running",
                             "error_energy": abs(info["energy"] - E_ref) / E_ref,
                             "energy_difference": info["energy"] - E_ref,
                             **field_errors(nlp.disc, phi, ref["phi"]), "setting": case["setting"]})
        res = scp(nlp, max_iter=case["max_iter"], tol=case["tol"], record=rec)
        if rows:
            rows[-1]["status"] = res["status"]
        return rows
    if case["method"] != "exact":
        over.append(f'solver.method="{case["method"]}"')
    if "M" in case:
        over.append(f"solver.M={case['M']}")
    if "M_max" in case:
        over.append(f"solver.M_max={case['M_max']}")
    nlp = nlp_for(case["scene"], over)
    r = solve(nlp)
    out = row(r, case["scene"], case["method"], case["n"], nlp.disc.h, tol=case["tol"], setting=case["setting"],
              error_energy=abs(r.energy - E_ref) / E_ref, energy_difference=r.energy - E_ref,
              **field_errors(nlp.disc, r.phi, ref["phi"]))
    return [out]


def figure(rows, path: Path) -> None:
    pyplot = plt()
    fig, axes = pyplot.subplots(1, 2, figsize=(13, 5))
    markers = {"exact": "o", "penalty": "s", "continuation": "^", "augmented": "D", "scp": "x"}
    for method, mk in markers.items():
        sel = select(rows, method=method)
        if not sel:
            continue
        t = column(sel, "wall_time_s")
        for ax, q in zip(axes, ("error_h1", "error_energy")):
            v = column(sel, q)
            ok = v > 0  # an error of exactly 0 is the reference itself
            ax.loglog(t[ok], v[ok], mk + ("-" if method == "scp" else ""), label=method, ms=7)
            for ti, vi, r in zip(t[ok], v[ok], [x for x, k in zip(sel, ok) if k]):
                if method != "scp":
                    ax.annotate(r.get("setting", ""), (ti, vi), fontsize=6)
    for ax, q in zip(axes, ("|phi - phi*|_H1", "|E - E*|/E*")):
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel(q)
        ax.legend(fontsize=8)
    axes[0].set_title(f"work-precision on ellipse-2d, n = {rows[0]['n']}")
    savefig(fig, path)


def main(out, quick: bool = False, executor=None) -> int:
    out = Path(out)
    fields = out / "fields"
    fields.mkdir(parents=True, exist_ok=True)
    cs = cases(quick, fields)
    reference(cs[0]["n"], fields)  # once, before the cases fan out
    rows = run_cases(NAME, cs, run, out / f"{NAME}.csv", executor=executor,
                     extra_columns=EXTRA + ["energy_difference"])
    for r in rows:
        log.info(f"{r['method']:13s} {r.get('setting', ''):18s} time {float(r['wall_time_s']):7.2f}s "
              f"H1 err {float(r['error_h1'] or 'nan'):.2e} energy err {float(r['error_energy'] or 'nan'):.2e} "
              f"(E - E* = {float(r.get('energy_difference') or 'nan'):+.2e}) "
              f"{r['status']}")
    figure(rows, out / f"{NAME}.png")
    return 0
