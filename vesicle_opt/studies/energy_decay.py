"""Figure 3 analogue: log(E_M - E_min) against t for two constant time steps k and k/2.

2D ``ellipse-2d`` scene (FD), penalty scheme (18) with the paper's M = 1e4, started from the
scene's initial shape projected onto A = alpha, B = beta (``flows.projection``): from the raw shape
the penalty terms (M/2 (B - beta)^2 ~ 2e3) drive a violent first transient in which constant k
is rejected repeatedly.
E_min is the penalised energy of the discrete steady state: an adaptive run of (18) to t = T_ss,
then polished by IPOPT minimising E_M from there (the k -> infinity minimising movement of (23));
the steady states of (18) are the critical points of E_M, the same for every k. The two constant-k curves should lie on top of each other (convergence in k).
Rows go through ``runner``: ``energy_decay.csv`` with one ``row = "steady"`` (E_min in
``penalized_energy``; phi_min in ``steady-n<n>.npz`` beside it) and ``row = "step"`` per step of each
constant-k case; ``energy_decay.png`` is drawn from the finished rows.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from vesicle_opt.flows.backward_euler import BackwardEulerScheme
from vesicle_opt.flows.stepper import StepperOptions, run
from vesicle_opt.flows.trackers import HistoryTracker
from vesicle_opt.io.files import load_npz, save_npz
from vesicle_opt.studies._common import pyplot as plt
from vesicle_opt.studies._flowkit import report_failures, setup
from vesicle_opt.studies.runner import run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

T_SS = 20.0
EXTRA = ["row", "k", "step", "t", "penalized_energy", "excess", "energy_law_residual",
         "flow_penalized_energy", "polish_distance"]


def _base(n: int) -> list[str]:
    return [f"mesh.n={n}", "solver.M=1e4", 'flow.scheme="penalty"', "flow.steady_tol=0"]


def _steady(case: dict) -> dict:
    """phi_min and E_min from their npz beside the CSV, or computed and written (atomically) when
    missing, so the k-cases need not wait for the steady-state case."""
    n = case["n"]
    path = Path(case["dir"]) / f"steady-n{n}.npz"
    st = load_npz(path)
    if st is not None:
        return st
    sc, md, sch, phi0 = setup("ellipse-2d", _base(n))  # flow.initial = "projected" (the default)
    ss = run(sch, phi0, StepperOptions(dt=1e-4, t_end=T_SS, max_steps=20000, adaptive=True, dt_max=0.5))
    phi_min, ok, status = BackwardEulerScheme(md, law_tol=sc.flow.law_tol).minimise(ss.phi)
    if ss.status != "t_end" or not ok:
        msg = f"steady state not found: flow {ss.status} ({ss.message}), IPOPT {status}"
        log.info(msg)
        raise RuntimeError(msg)
    st = {"phi": phi_min, "E_min": md.E_M(phi_min), "t": ss.t, "steps": ss.step,
          "flow_penalized_energy": md.E_M(ss.phi), "status": status,
          "polish_distance": np.sqrt(md.norm2(phi_min - ss.phi))}
    save_npz(path, **st)
    return st


def case_rows(case: dict) -> list[dict]:
    """The steady state (one ``row = "steady"``) or one constant-k run (``row = "step"`` per step)."""
    st = _steady(case)
    E_min = st["E_min"]
    if case["row"] == "steady":
        log.info(f"E_min = {E_min:.12g} (flow to t = {st['t']:.4g} in {st['steps']} steps: E_M = "
              f"{st['flow_penalized_energy']:.12g}; IPOPT polish: {st['status']}, ||phi_min - phi(T_ss)|| = "
              f"{st['polish_distance']:.2e})")
        return [{"row": "steady", "n": case["n"], "t": st["t"], "step": st["steps"], "penalized_energy": E_min,
                 "flow_penalized_energy": st["flow_penalized_energy"], "status": st["status"],
                 "polish_distance": st["polish_distance"]}]
    sc, md, sch, phi0 = setup("ellipse-2d", _base(case["n"]))
    kk = case["k"]
    E0 = md.E_M(phi0)
    history = HistoryTracker()
    o = run(sch, phi0, StepperOptions(dt=kk, t_end=case["T"], max_steps=10**6), [history])
    rows = [{"row": "step", "k": kk, "step": 0, "t": 0.0, "penalized_energy": E0, "excess": E0 - E_min}]
    rows += [{"row": "step", "k": kk, "step": r["step"], "t": r["t"], "penalized_energy": r["penalized_energy"],
              "excess": r["penalized_energy"] - E_min, "energy_law_residual": r["energy_law_residual"]}
             for r in history.rows]
    law = max(abs(r.get("energy_law_residual", 0.0)) for r in rows)
    log.info(f"k = {kk:.3g}: {o.status}, {o.step} steps, rejections {o.rejections}, "
          f"E_M(T) - E_min = {rows[-1]['excess']:.4e}, max |law (22)| = {law:.2e}")
    return rows


def main(out: Path, quick: bool = False) -> int:
    """Cases through ``runner`` (a re-run skips the finished ones); gap and figure derived."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n, T, k = (24, 0.5, 2e-3) if quick else (48, 2.0, 1e-3)
    cases = [{"case": f"n={n} steady state", "row": "steady", "n": n, "dir": str(out)}]
    cases += [{"case": f"n={n} T={T:g} k={kk:.6e}", "row": "step", "n": n, "T": T, "k": kk, "dir": str(out)}
              for kk in (k, k / 2)]
    raw = run_cases("energy_decay", cases, case_rows, out / "energy_decay.csv", workers=1, extra_columns=EXTRA)
    ids = {c["case"] for c in cases}
    mine = [r for r in raw if r["case"] in ids]
    if report_failures(mine):
        return 1
    E_min = next(float(r["penalized_energy"]) for r in mine if r["row"] == "steady")
    rows = [{**r, **{key: float(r[key]) for key in ("k", "t", "excess")}} for r in mine if r["row"] == "step"]
    # the two curves at the common times (every step of the coarse run)
    a = {round(r["t"] / k): r["excess"] for r in rows if r["k"] == k}
    b = {round(r["t"] / k): r["excess"] for r in rows if r["k"] == k / 2 and abs(r["t"] / k - round(r["t"] / k)) < 1e-9}
    common = sorted(set(a) & set(b))
    rel = max(abs(a[j] - b[j]) / abs(b[j]) for j in common if b[j] > 0)
    log.info(f"max relative gap between the curves (E_M - E_min, k vs k/2): {rel:.3e}")
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
