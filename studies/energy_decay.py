"""Figure 3 analogue: log(E_M - E_min) against t for two constant time steps k and k/2.

2D ``ellipse-2d`` scene (FD), penalty scheme (18) with the paper's M = 1e4, started from the
scene's initial shape projected onto A = alpha, B = beta (``flows.projection``): from the raw shape
the penalty terms (M/2 (B - beta)^2 ~ 2e3) drive a violent first transient in which constant k
is rejected repeatedly.
E_min is the penalised energy of the discrete steady state: an adaptive run of (18) to t = T_ss,
then polished by IPOPT minimising E_M from there (the k -> infinity minimising movement of (23));
the steady states of (18) are the critical points of E_M, the same for every k. The two constant-k curves should lie on top of each other (convergence in k).
Writes ``energy_decay.csv``, ``energy_decay.png``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vesicle_opt.flows.stepper import StepperOptions, run

from ._flowkit import setup, write_csv


def main(out: Path, quick: bool = False) -> int:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n, T, k = (24, 0.5, 2e-3) if quick else (48, 2.0, 1e-3)
    base = [f"mesh.n={n}", "solver.M=1e4", 'flow.scheme="penalty"', "flow.steady_tol=0"]
    sc, md, sch, phi0 = setup("ellipse-2d", base)  # flow.initial = "projected" (the default)
    from vesicle_opt.flows.backward_euler import BackwardEulerScheme
    T_ss = 20.0
    ss = run(sch, phi0, StepperOptions(dt=1e-4, t_end=T_ss, max_steps=20000, adaptive=True, dt_max=0.5))
    phi_min, ok, status = BackwardEulerScheme(md, law_tol=sc.flow.law_tol).minimise(ss.phi)
    if ss.status != "t_end" or not ok:
        print(f"steady state not found: flow {ss.status} ({ss.message}), IPOPT {status}")
        return 1
    E_min = md.E_M(phi_min)
    print(f"E_min = {E_min:.12g} (flow to t = {ss.t:.4g} in {ss.step} steps: E_M = {md.E_M(ss.phi):.12g}; "
          f"IPOPT polish: {status}, ||phi_min - phi(T_ss)|| = {np.sqrt(md.norm2(phi_min - ss.phi)):.2e})", flush=True)
    rows = []
    for kk in (k, k / 2):
        E0 = md.E_M(phi0)
        rows.append({"k": kk, "step": 0, "t": 0.0, "penalized_energy": E0, "excess": E0 - E_min})

        def on_accept(step, t, phi, row, kk=kk):
            rows.append({"k": kk, "step": step, "t": t, "penalized_energy": row["penalized_energy"],
                         "excess": row["penalized_energy"] - E_min,
                         "energy_law_residual": row["energy_law_residual"]})

        o = run(sch, phi0, StepperOptions(dt=kk, t_end=T, max_steps=10**6), on_accept=on_accept)
        law = max(abs(r.get("energy_law_residual", 0.0)) for r in rows if r["k"] == kk)
        print(f"k = {kk:.3g}: {o.status}, {o.step} steps, rejections {o.rejections}, "
              f"E_M(T) - E_min = {rows[-1]['excess']:.4e}, max |law (22)| = {law:.2e}", flush=True)
    # the two curves at the common times (every step of the coarse run)
    a = {round(r["t"] / k): r["excess"] for r in rows if r["k"] == k}
    b = {round(r["t"] / k): r["excess"] for r in rows if r["k"] == k / 2 and abs(r["t"] / k - round(r["t"] / k)) < 1e-9}
    common = sorted(set(a) & set(b))
    rel = max(abs(a[j] - b[j]) / abs(b[j]) for j in common if b[j] > 0)
    print(f"max relative gap between the curves (E_M - E_min, k vs k/2): {rel:.3e}", flush=True)
    write_csv(out / "energy_decay.csv", rows)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for kk in (k, k / 2):
        r = [x for x in rows if x["k"] == kk and x["excess"] > 0]
        ax.plot([x["t"] for x in r], [np.log(x["excess"]) for x in r], label=f"k = {kk:.3g}")
    ax.set_xlabel("t")
    ax.set_ylabel("log(E_M - E_min)")
    ax.set_title(f"ellipse-2d {n}x{n}, (18), M = 1e4, E_min = {E_min:.8g}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "energy_decay.png", dpi=100)
    plt.close(fig)
    return 0
