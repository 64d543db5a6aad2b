"""Time-step convergence of the flows (Theorems 4.2-4.4): fixed T, k, k/2, k/4, ...

2D ``ellipse-2d`` scene (FD, M = 100 so the penalty stiffness does not hide the time error), all
three schemes from the scene's initial shape projected onto the constraint set (``flow.initial``). Errors at T
against a fine-k reference, in the lumped L^2 norm and in the energy (kappa E_h):
* (18) and (23) discretise the same flow (14): both are compared with one reference, (18) at
  k_ref = k_min / 4 (its error there is ~1/16 of the finest (18) error, and ~1e-3 of (23)'s);
* (17) discretises (13) and gets its own reference at k_ref = k_min / 4.
The observed order is the least-squares slope of log(error) against log(k) (np.polyfit).
Rows go through ``runner`` (one case per reference and per (scheme, k); the references' fields
are npz files beside the CSV): ``time_step_convergence.csv`` (``row`` = reference | run), then
``time_step_orders.csv`` and ``time_step_convergence.png`` derived from the finished rows.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from vesicle_opt.flows.stepper import StepperOptions, run
from vesicle_opt.io.files import load_npz, save_npz

from vesicle_opt.studies._common import pyplot as plt
from vesicle_opt.studies._flowkit import report_failures, setup, write_derived_csv
from vesicle_opt.studies.runner import run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

SCHEMES = (("penalty", "(14)"), ("lagrange", "(13)"), ("backward-euler", "(14)"))
REFERENCE = {"(14)": "penalty", "(13)": "lagrange"}  # the scheme whose fine-k run is each flow's reference
EXTRA = ["row", "scheme", "flow", "T", "k", "steps", "l2_error", "energy_rel_error", "rejections"]
ORDERS = ["scheme", "flow", "order_l2", "order_energy", "expected"]


def _base(n: int) -> list[str]:
    return [f"mesh.n={n}", "solver.M=100", "flow.steady_tol=0"]


def _solve(name, sets, k, T):
    sc, md, sch, phi0 = setup(name, sets)
    t0 = time.perf_counter()
    o = run(sch, phi0, StepperOptions(dt=k, t_end=T, max_steps=10**7))
    if o.status != "t_end":
        raise RuntimeError(f"{sc.flow.scheme} at k = {k}: {o.status}: {o.message}")
    return md, o, time.perf_counter() - t0


def _reference(case: dict) -> dict:
    """The fine-k reference of ``case["flow"]``: loaded from its npz beside the CSV, or computed and
    written (atomically) when missing, so any case may come first and on any executor."""
    scheme, n, T, k = REFERENCE[case["flow"]], case["n"], case["T"], case["k_ref"]
    path = Path(case["dir"]) / f"reference-{scheme}-n{n}-T{T:g}-k{k:.6e}.npz"
    ref = load_npz(path)
    if ref is None:
        md, o, wall = _solve("ellipse-2d", _base(n) + [f'flow.scheme="{scheme}"'], k, T)
        ref = {"phi": o.phi, "energy": md.E(o.phi), "steps": o.step, "rejections": o.rejections,
               "wall_time_s": wall}
        save_npz(path, **ref)
    return ref


def case_rows(case: dict) -> list[dict]:
    """A reference run (``row = "reference"``) or one scheme at one k against its reference."""
    ref = _reference(case)
    n, T, flow_name = case["n"], case["T"], case["flow"]
    if case["row"] == "reference":
        scheme, k = REFERENCE[flow_name], case["k_ref"]
        log.info(f"reference for {flow_name}: {scheme} at k = {k:.3g}, {ref['steps']} steps, "
              f"{ref['wall_time_s']:.1f}s")
        return [{"row": "reference", "scheme": scheme, "flow": flow_name, "n": n, "T": T, "k": k,
                 "steps": ref["steps"], "energy": ref["energy"], "rejections": ref["rejections"],
                 "wall_time_s": ref["wall_time_s"]}]
    scheme, k = case["scheme"], case["k"]
    md, o, wall = _solve("ellipse-2d", _base(n) + [f'flow.scheme="{scheme}"'], k, T)
    e2 = float(np.sqrt(md.norm2(o.phi - ref["phi"])))
    eE = abs(md.E(o.phi) - ref["energy"]) / abs(ref["energy"])
    log.info(f"{scheme:15s} k = {k:.3e}  L2 error {e2:.3e}  energy error {eE:.3e}  {wall:.1f}s")
    return [{"row": "run", "scheme": scheme, "flow": flow_name, "n": n, "T": T, "k": k, "steps": o.step,
             "l2_error": e2, "energy_rel_error": eE, "rejections": o.rejections, "wall_time_s": wall}]


def main(out: Path, quick: bool = False) -> int:
    """Cases through ``runner`` (a re-run skips the finished ones); orders and figure derived."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n, T, levels = (24, 0.01, 4) if quick else (48, 0.01, 5)
    k0 = T / 10
    ks = [k0 / 2**j for j in range(levels)]
    common = {"n": n, "T": T, "k_ref": ks[-1] / 4, "dir": str(out)}
    cases = [{**common, "case": f"n={n} reference {f}", "row": "reference", "flow": f} for f in REFERENCE]
    cases += [{**common, "case": f"n={n} {s} k={k:.6e}", "row": "run", "scheme": s, "flow": f, "k": k}
              for s, f in SCHEMES for k in ks]
    raw = run_cases("time_step_convergence", cases, case_rows, out / "time_step_convergence.csv",
                    workers=1, extra_columns=EXTRA)
    by_case = {r["case"]: r for r in raw}
    mine = [by_case[c["case"]] for c in cases]
    if report_failures(mine):
        return 1
    rows, orders = [], []
    for scheme, flow_name in SCHEMES:
        r = [by_case[c["case"]] for c in cases if c.get("scheme") == scheme]
        r = [{**x, **{key: float(x[key]) for key in ("k", "l2_error", "energy_rel_error")}} for x in r]
        p2 = float(np.polyfit(np.log(ks), np.log([x["l2_error"] for x in r]), 1)[0])
        pE = float(np.polyfit(np.log(ks), np.log([x["energy_rel_error"] for x in r]), 1)[0])
        rows += r
        orders.append({"scheme": scheme, "flow": flow_name, "order_l2": p2, "order_energy": pE,
                       "expected": 1 if scheme == "backward-euler" else 2})
        log.info(f"{scheme}: observed order L2 {p2:.3f}, energy {pE:.3f}")
    write_derived_csv(out / "time_step_orders.csv", orders, ORDERS)
    _plot(out / "time_step_convergence.png", rows, orders)
    return 0


def _plot(path, rows, orders):
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
