"""Time-step convergence of the flows (Theorems 4.2-4.4): fixed T, k, k/2, k/4, ...

2D ``ellipse-2d`` scene (FD, M = 100 so the penalty stiffness does not hide the time error), all
three schemes from the scene's initial shape projected onto the constraint set (``flow.initial``). Errors at T
against a fine-k reference, in the lumped L^2 norm and in the energy (kappa E_h):
* (18) and (23) discretise the same flow (14): both are compared with one reference, (18) at
  k_ref = k_min / 4 (its error there is ~1/16 of the finest (18) error, and ~1e-3 of (23)'s);
* (17) discretises (13) and gets its own reference at k_ref = k_min / 4.
The observed order is the least-squares slope of log(error) against log(k) (np.polyfit).
Writes ``time_step_convergence.csv``, ``time_step_orders.csv`` and ``time_step_convergence.png``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from vesicle_opt.flows.stepper import StepperOptions, run

from ._flowkit import setup, write_csv


def _solve(name, sets, k, T):
    sc, md, sch, phi0 = setup(name, sets)
    t0 = time.perf_counter()
    o = run(sch, phi0, StepperOptions(dt=k, t_end=T, max_steps=10**7))
    if o.status != "t_end":
        raise RuntimeError(f"{sc.flow.scheme} at k = {k}: {o.status}: {o.message}")
    return md, o, time.perf_counter() - t0


def main(out: Path, quick: bool = False) -> int:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n, T, levels = (24, 0.01, 4) if quick else (48, 0.01, 5)
    k0 = T / 10
    ks = [k0 / 2**j for j in range(levels)]
    base = [f"mesh.n={n}", "solver.M=100", "flow.steady_tol=0"]
    refs = {}
    for flow_name, scheme in (("(14)", "penalty"), ("(13)", "lagrange")):
        md, o, wall = _solve("ellipse-2d", base + [f'flow.scheme="{scheme}"'], ks[-1] / 4, T)
        refs[flow_name] = (o.phi, md.E(o.phi))
        print(f"reference for {flow_name}: {scheme} at k = {ks[-1] / 4:.3g}, {o.step} steps, {wall:.1f}s", flush=True)
    rows, orders = [], []
    for scheme, flow_name in (("penalty", "(14)"), ("lagrange", "(13)"), ("backward-euler", "(14)")):
        phi_ref, E_ref = refs[flow_name]
        errs = []
        for k in ks:
            md, o, wall = _solve("ellipse-2d", base + [f'flow.scheme="{scheme}"'], k, T)
            e2 = float(np.sqrt(md.norm2(o.phi - phi_ref)))
            eE = abs(md.E(o.phi) - E_ref) / abs(E_ref)
            errs.append((e2, eE))
            rows.append({"scheme": scheme, "flow": flow_name, "n": n, "T": T, "k": k, "steps": o.step,
                         "l2_error": e2, "energy_rel_error": eE, "rejections": o.rejections, "wall_time_s": wall})
            print(f"{scheme:15s} k = {k:.3e}  L2 error {e2:.3e}  energy error {eE:.3e}  {wall:.1f}s", flush=True)
        e = np.array(errs)
        p2 = float(np.polyfit(np.log(ks), np.log(e[:, 0]), 1)[0])
        pE = float(np.polyfit(np.log(ks), np.log(e[:, 1]), 1)[0])
        orders.append({"scheme": scheme, "flow": flow_name, "order_l2": p2, "order_energy": pE,
                       "expected": 1 if scheme == "backward-euler" else 2})
        print(f"{scheme}: observed order L2 {p2:.3f}, energy {pE:.3f}", flush=True)
    write_csv(out / "time_step_convergence.csv", rows)
    write_csv(out / "time_step_orders.csv", orders)
    _plot(out / "time_step_convergence.png", rows, orders)
    return 0


def _plot(path, rows, orders):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for o in orders:
        r = [x for x in rows if x["scheme"] == o["scheme"]]
        k = [x["k"] for x in r]
        axes[0].loglog(k, [x["l2_error"] for x in r], "o-", label=f"{o['scheme']} (p = {o['order_l2']:.2f})")
        axes[1].loglog(k, [x["energy_rel_error"] for x in r], "o-", label=f"{o['scheme']} (p = {o['order_energy']:.2f})")
    for ax, t in zip(axes, ["L2 error at T", "relative energy error at T"]):
        ax.set_xlabel("k")
        ax.set_title(t)
        ax.legend()
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
