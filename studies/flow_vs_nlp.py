"""Flows as a route to equilibria: wall time of each flow to reach the NLP equilibrium energy.

The exact-constraint NLP (``vesicle_opt.solve``) gives E* and phi* on the ``ellipse-2d`` scene; each
flow then runs with adaptive k from the scene's initial shape projected onto the constraint set
(``flow.initial = "projected"``, the default) and records, against its wall time, the relative energy error |E - E*|/E* (E = kappa E_h,
never the penalty terms) and the lumped-L^2 distance ||phi - phi*||. The flows stop at a relative
energy error <= 1e-6 *and* ||phi - phi*|| <= 1e-3 (an energy crossing alone is not convergence),
at a steady state, or at a wall-time cap; the first time the energy alone is within 1e-6 (which a
flow passing E* on its way elsewhere also meets) is reported separately.
Finding (ellipse-2d): the NLP's KKT point is a saddle of the discrete problem (the centred ellipse;
the grid breaks translation invariance): all flows plateau near it and then drift to a lower state
(32^2: E 4% lower and asymmetric; 64^2: 2.4e-5 lower). The study re-solves the NLP from the lowest
flow end state to confirm the lower constrained critical point.
(18) and (23) minimise E_M, whose minimiser misses the constraints by O(1/M) and whose E differs from
E* by about lambda^2/M: they may stall above 1e-6 (the floor is reported).
Writes ``flow_vs_nlp.csv`` (one row per flow step), ``flow_vs_nlp_summary.csv`` and a PNG.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from vesicle_opt.flows.stepper import StepperOptions, run
from vesicle_opt.solve import solve

from ._flowkit import setup, write_csv

TARGET = 1e-6  # relative energy error asked by the study
PHI_TOL = 1e-3  # and the field itself close to phi* (lumped L^2, |Omega| = 64)


def main(out: Path, quick: bool = False, n: int | None = None, cap: float | None = None) -> int:
    """quick: 32^2 with a 90 s cap per flow; full: 64^2 with 300 s (n, cap override)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n0, cap0 = (32, 90.0) if quick else (64, 300.0)
    n, cap = n or n0, cap or cap0
    base = [f"mesh.n={n}", "flow.steady_tol=1e-9", "flow.dt=1e-4", "flow.dt_max=100", "flow.t_end=1e5",
            'flow.stepping="adaptive"']
    sc, md, _, _ = setup("ellipse-2d", base)
    res = solve(sc)
    if not res.converged:
        print(f"NLP did not converge: {res.status}")
        return 1
    E_star, phi_star = res.energy, res.phi
    print(f"NLP: E* = {E_star:.10g}, {res.iterations} iterations, {res.wall_time_s:.2f}s", flush=True)
    rows, summary = [], [{"method": "nlp-exact", "wall_time_s": res.wall_time_s, "time_to_target_s": res.wall_time_s,
                          "final_energy": E_star, "best_energy_rel_error": 0.0, "final_phi_distance": 0.0,
                          "status": res.status, "steps": res.iterations}]
    ends = {}
    for scheme in ("lagrange", "penalty", "backward-euler"):
        sc, md, sch, phi0 = setup("ellipse-2d", base + [f'flow.scheme="{scheme}"'])
        hit = {"t": None, "t_energy": None}
        best = [np.inf]
        t0 = time.perf_counter()

        def on_accept(step, t, phi, row, scheme=scheme):
            eE = abs(row["energy"] - E_star) / E_star
            dphi = float(np.sqrt(md.norm2(phi - phi_star)))
            best[0] = min(best[0], eE)
            rows.append({"method": scheme, "step": step, "t": t, "dt": row["dt"], "wall_time_s": row["wall_time_s"],
                         "energy": row["energy"], "energy_rel_error": eE, "phi_distance": dphi,
                         "volume_residual": row["volume_residual"], "area_residual": row["area_residual"]})
            if hit["t_energy"] is None and eE <= TARGET:
                hit["t_energy"] = row["wall_time_s"]
            if hit["t"] is None and eE <= TARGET and dphi <= PHI_TOL:
                hit["t"] = row["wall_time_s"]

        def stop(row):
            return hit["t"] is not None or time.perf_counter() - t0 > cap

        o = run(sch, phi0, StepperOptions(dt=sc.flow.dt, t_end=sc.flow.t_end, max_steps=10**6, adaptive=True,
                                           dt_max=sc.flow.dt_max, steady_tol=sc.flow.steady_tol), on_accept=on_accept,
                stop=stop)
        last = [r for r in rows if r["method"] == scheme][-1]
        ends[scheme] = o.phi
        summary.append({"method": scheme, "wall_time_s": o.wall_time_s, "time_to_target_s": hit["t"],
                        "time_to_energy_only_target_s": hit["t_energy"],
                        "final_energy": last["energy"], "best_energy_rel_error": best[0],
                        "final_phi_distance": last["phi_distance"], "status": o.status, "steps": o.step})
        print(f"{scheme:15s}: {o.status}, {o.step} steps, t = {o.t:.4g}, wall {o.wall_time_s:.1f}s, "
              f"time to target {hit['t']} (energy alone: {hit['t_energy']}), best rel. energy error {best[0]:.2e}, "
              f"final ||phi - phi*|| {last['phi_distance']:.2e}, final E {last['energy']:.10g}", flush=True)
    # Is the NLP's KKT point a minimum? Re-solve the NLP from the lowest flow end state: a lower
    # converged E there means the first NLP answer was a saddle or a higher local minimum.
    low = min((s for s in summary[1:]), key=lambda s: s["final_energy"])
    phi_low = ends[low["method"]]
    res2 = solve(sc, x0=phi_low)
    summary.append({"method": f"nlp-exact from {low['method']} end state", "wall_time_s": res2.wall_time_s,
                    "time_to_target_s": None, "final_energy": res2.energy,
                    "best_energy_rel_error": abs(res2.energy - E_star) / E_star,
                    "final_phi_distance": float(np.sqrt(md.norm2(res2.phi - phi_star))),
                    "status": res2.status, "steps": res2.iterations})
    print(f"NLP from the {low['method']} end state: {res2.status}, converged={res2.converged}, "
          f"E = {res2.energy:.10g} ({(res2.energy - E_star) / E_star:+.3e} relative to E*)", flush=True)
    write_csv(out / "flow_vs_nlp.csv", rows)
    write_csv(out / "flow_vs_nlp_summary.csv", summary)
    _plot(out / "flow_vs_nlp.png", rows, res.wall_time_s)
    return 0


def _plot(path, rows, nlp_time):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for m in dict.fromkeys(r["method"] for r in rows):
        r = [x for x in rows if x["method"] == m]
        w = [x["wall_time_s"] for x in r]
        axes[0].semilogy(w, [max(x["energy_rel_error"], 1e-16) for x in r], label=m)
        axes[1].semilogy(w, [x["phi_distance"] for x in r], label=m)
    for ax, t in zip(axes, ["|E - E*| / E*", "||phi - phi*||"]):
        ax.axvline(nlp_time, color="k", ls="--", label="NLP solve")
        ax.set_xlabel("wall time [s]")
        ax.set_title(t)
        ax.legend()
        ax.grid(True, which="both", alpha=0.3)
    axes[0].axhline(TARGET, color="gray", ls=":")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
