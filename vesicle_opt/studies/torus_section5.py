"""Section 5 by the gradient flow: a flat elliptic disk pinches into a torus (Figures 1-2, Table 1).

The paper's data (scene ``torus-table1-3d``): box [-pi, pi]^3, alpha = -202.67, beta = 45.43,
eps = 0.255254, rigidity 10, c0 = 0, penalty M = 1e4, Fourier-spectral grids n^3. For each n:

1. **Flow, the path.** Scheme (23), backward Euler, each step the minimising movement of
   Proposition 4.1 solved by the matrix-free Newton-CG minimiser (``flows.backward_euler_nk``; law
   (24) checked every step), from the flat elliptic disk ``DISK`` (an ellipsoid with semi-axes
   2.5 x 2.3 x 0.94; not projected: the penalty pulls A, B onto the constraints, as in the paper),
   adaptive k from ``DT0`` (grows after easy Newton solves, halves on a rejection; (23) is L-stable,
   so k is not capped), frames to t = ``T_END``: the pinch-off is over by then on every grid.
2. **Flow, on to equilibrium.** The same flow continues (``flows.api.flow(resume_from=...)``) with
   k growing as it relaxes until the one certificate (``verify.certify`` through
   ``flows.equilibrium.EquilibriumTracker``: the penalty problem (11) at the flow's M, relative L2
   KKT residual <= 100 tol from gradients independent of the steps, round-off floor below tol) passes:
   a **certified equilibrium reached by the flow itself** (``flow_eq_*`` columns). Beside it, for
   comparison, the polish of earlier versions: the penalised problem (11) solved by Newton-Krylov
   from the path's end field (``equilibrium_*``), and the same problem from the scene's torus start
   (``torus_start_energy``); ``flow_eq_vs_torus_start`` is the relative difference of 10E.
   The flow is a gradient flow of E_M, so its steady state is the *penalty* equilibrium at M = 1e4,
   the problem of the paper's Table 1 and of the torus-start solve: the comparison is between equal
   problems.
3. **Flow, on to the exact-constraint equilibrium.** The exact-constraint equilibrium differs from
   the penalty one by O(lambda^2 / M) (1.8e-4 relative at 16^3), so the flow continues as an
   augmented Lagrangian of flows (``flows.equilibrium.flow_to_equilibrium(exact=True)``): stages of
   the (23) flow of E_M - mu . c, mu <- mu - M c between them, until the certificate with exact
   constraints passes (``flow_exact_*`` columns), compared with the exact-constraint solve from the
   torus start (``exact_torus_start_energy``).
3. **Start sensitivity** (16^3, reported, not part of the verdict): the wider disk ``WIDE_DISK``
   ends as a tube joined to its periodic image (wraps x, lower energy than the torus): not a
   vesicle, and the topology columns say so.
4. **Topology of every frame** (``flow.frames`` snapshots): components of {phi > 0}, Euler
   characteristic (1 for a disk/ball, 0 for a solid torus), periodic wraps (a slab joined to its
   images wraps two directions) and the torus check ``_common.torus_check`` (shared with
   ``table1``: one component, chi 0, no wrap, phi < 0 on the centre axis); ``path`` lists the
   distinct states.

Rows (one CSV, appended per grid through ``runner``; a killed flow resumes from its
checkpoint in ``flow-<n>/``): ``row = "frame"`` per snapshot (t, energy, topology) and one
``row = "final"`` per grid (flow and equilibrium energies beside the paper's Table 1).
``main(out, quick)``: quick = 16^3 only; full = 16^3, 32^3, 48^3, 64^3 and the wide disk. Writes
``torus_section5.csv`` and ``torus_section5.png`` (Figure 1: cut views of the frames on the finest
grid; Figure 2: the final shapes on every grid). ``flow_eq_wall_s`` is the wall time of the whole
flow (path and relaxation, as the checkpointed state counts it), ``flow_eq_cpu_s`` the CPU time of
this process for it. Returns 0 when every flow reached T_END with every step's law verified, ended
a single torus, went on to a certified equilibrium, and every polish converged to that torus.
"""

from __future__ import annotations

import logging
import csv
import sys
import time
from pathlib import Path

import numpy as np

from vesicle_opt import scene
from vesicle_opt.api import solve
from vesicle_opt.flows.api import flow
from vesicle_opt.flows.equilibrium import EquilibriumTracker, flow_to_equilibrium
from vesicle_opt.flows.run import COLUMNS as FLOW_COLUMNS, write_flow
from vesicle_opt.flows.trackers import HistoryTracker
from vesicle_opt.io.png import draw_cut
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.studies._common import TABLE1, TABLE1_M, pyplot as plt, torus_check
from vesicle_opt.studies.runner import run_cases

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

PAPER, M_PAPER = TABLE1, TABLE1_M  # the paper's Table 1 (``_common``)

DISK = [2.5, 2.3, 0.94]
WIDE_DISK = [2.6, 2.2, 0.95]  # 0.44 from the box face: its tanh tail meets its periodic image (16^3 only)
DT0 = 1e-5  # the first steps resolve the fast relaxation of the tanh profile
DT_MAX = 1e12  # (23) is L-stable: k is not capped; it grows as the flow relaxes
T_END = 0.4  # pinch-off is over by t ~ 0.35 at 16^3 and ~ 0.2 at 32^3 (measured)
RELAX_T_END = 1e12  # stage 2 ends at the certificate, not at a time
EXACT_MARGIN = NewtonKrylovOptions.constraint_margin  # the exact stages hold the constraints as tightly
# as the exact torus-start solve they are compared with (|c| <= 0.1 tol, scaled)
RELAX_STEPS = 500  # ... or after this many steps (measured 11-13 beyond T_END at 32^3, 64^3)
FRAMES = 20

EXTRA = ["row", "start", "t", "frame", "penalized_energy", "components", "euler_characteristic", "wraps",
         "axis_negative", "torus_ok", "paper_energy", "rel_diff_paper", "flow_energy", "flow_penalized_energy",
         "flow_steps", "flow_rejections", "flow_status", "max_law_residual", "flow_wall_s",
         "newton_iterations", "krylov_iterations", "equilibrium_energy", "equilibrium_penalized",
         "equilibrium_converged", "equilibrium_kkt_dual", "equilibrium_wall_s",
         "torus_start_energy", "flow_vs_torus_start", "path", "flow_eq_certified", "flow_eq_energy",
         "flow_eq_kkt_residual", "flow_eq_outcome", "flow_eq_steps", "flow_eq_t", "flow_eq_wall_s",
         "flow_eq_cpu_s", "flow_eq_vs_torus_start", "torus_start_wall_s", "flow_exact_certified",
         "flow_exact_energy", "flow_exact_kkt_residual", "flow_exact_stages", "flow_exact_steps",
         "flow_exact_wall_s", "exact_torus_start_energy", "exact_torus_start_converged",
         "flow_exact_vs_exact_torus_start", "flow_eq_reason", "flow_exact_outcome", "flow_exact_reason",
         "flow_exact_shape"]


def _scene(n: int, t_end: float, disk=DISK, steps: int = 100000, extra=()):
    """The flow's scene (from the disk) and the same problem from the scene's torus start."""
    sets = ["mesh.kind='spectral'", f"mesh.n={n}", "solver.backend='newton-krylov'", "solver.method='penalty'",
            f"solver.M={M_PAPER}", "flow.scheme='backward-euler'", "flow.initial='shape'", "flow.stepping='adaptive'",
            f"flow.dt={DT0}", f"flow.dt_max={DT_MAX}", f"flow.t_end={t_end}", f"flow.frames={FRAMES}",
            "flow.steady_tol=0", f"flow.steps={steps}", *extra]
    torus_start = scene.load("torus-table1-3d", sets)
    start = f"initial={{shape='ellipsoid', semi_axes={list(disk)}}}"
    disk_start = scene.load("torus-table1-3d", sets + [start])
    return disk_start, torus_start


def case_rows(case: dict) -> list[dict]:
    n, out = case["n"], Path(case["dir"])
    disk_scene, torus_scene = _scene(n, case["t_end"], case["disk"])
    cpu0 = time.process_time()
    fr = write_flow(disk_scene, out, frames=True)
    md = fr.result.model
    with open(out / "history.csv", newline="") as fh:
        hist = list(csv.DictReader(fh))
    rows, states = [], []
    for snap in sorted((out / "snapshots").glob("phi_*.npz")):
        with np.load(snap) as z:
            phi, t = z["phi"], float(z["t"])
        topo = torus_check(md.disc, phi)
        rows.append({"scene": "torus-table1-3d", "n": n, "method": "flow (23)", "row": "frame", "start": case["start"],
                     "frame": int(snap.stem.split("_")[1]), "t": t, "energy": md.E(phi),
                     "penalized_energy": md.E_M(phi), **topo})
        state = f"{topo['components']} comp, chi {topo['euler_characteristic']}, wraps {topo['wraps']}"
        if not states or states[-1] != state:
            states.append(state)
    phi_flow = fr.result.phi
    # stage 2: the same flow on to the certified equilibrium (every step certified, the first pass ends it)
    relax_scene, _ = _scene(n, RELAX_T_END, case["disk"], steps=fr.result.steps + RELAX_STEPS)
    cert = EquilibriumTracker(relax_scene, md)
    relax_hist = HistoryTracker(out / "relax_history.csv", columns=FLOW_COLUMNS + ["kkt_residual"], keep=True)
    try:
        relax = flow(relax_scene, trackers=[cert, relax_hist], resume_from=fr.result.state, model=md)
    finally:
        relax_hist.close()
    flow_cpu = time.process_time() - cpu0  # this process's share (a resumed path counts only its rest)
    # stage 3: multiplier shifts between flow stages, to the exact-constraint equilibrium
    exact_scene, exact_torus = _scene(n, RELAX_T_END, case["disk"], steps=relax.steps + RELAX_STEPS,
                                      extra=["solver.method='exact'", "solver.second_order=false"])
    exact_laws: list[float] = []
    flow_exact, exact_run, exact_stages = flow_to_equilibrium(
        exact_scene, md, exact=True, resume_from=relax.state, constraint_margin=EXACT_MARGIN,
        trackers=[lambda state, row: exact_laws.append(float(row["energy_law_residual"]))])
    exact_ref = solve(exact_torus)
    flow_eq = cert.result if cert.result is not None else cert.last
    eq = solve(torus_scene, x0=phi_flow)  # the polish: front door, penalty form (11), no second-order check
    ref = solve(torus_scene)
    laws = [float(r["energy_law_residual"]) for r in hist] + \
        [float(r["energy_law_residual"]) for r in relax_hist.rows] + exact_laws
    topo = torus_check(eq.disc, eq.phi, eq.extra)
    s = fr.summary
    rows.append({
        "scene": "torus-table1-3d", "n": n, "method": "flow (23) + newton-krylov", "row": "final",
        "start": case["start"], "t": s["t"],
        "M": M_PAPER, "energy": eq.energy, "paper_energy": PAPER[n], "rel_diff_paper": eq.energy / PAPER[n] - 1,
        "flow_energy": s["energy"], "flow_penalized_energy": s["penalized_energy"], "flow_steps": s["steps"],
        "flow_rejections": s["rejections"], "flow_status": s["status"],
        "max_law_residual": max(laws),  # (24): the left side must be <= 0 (round-off allowed)
        "flow_wall_s": s["wall_time_s"], "newton_iterations": sum(int(r["newton_iterations"]) for r in hist),
        "krylov_iterations": sum(int(r["krylov_iterations"]) for r in hist),
        "equilibrium_energy": eq.energy, "equilibrium_penalized": eq.penalized_energy,
        "equilibrium_converged": eq.converged, "equilibrium_kkt_dual": eq.extra["kkt_dual"],
        "equilibrium_wall_s": eq.wall_time_s, "torus_start_energy": ref.energy,
        "flow_vs_torus_start": eq.energy / ref.energy - 1, "volume_residual": eq.volume_residual,
        "area_residual": eq.area_residual, "status": eq.status, "path": " -> ".join(states),
        "flow_eq_certified": bool(flow_eq is not None and flow_eq.converged),
        "flow_eq_energy": None if flow_eq is None else flow_eq.energy,
        "flow_eq_kkt_residual": None if flow_eq is None else flow_eq.kkt_residual,
        "flow_eq_outcome": None if flow_eq is None else flow_eq.outcome.value,
        "flow_eq_steps": relax.steps, "flow_eq_t": relax.t, "flow_eq_wall_s": relax.wall_time_s,
        "flow_eq_cpu_s": flow_cpu,
        "flow_eq_vs_torus_start": None if flow_eq is None else flow_eq.energy / ref.energy - 1,
        "torus_start_wall_s": ref.wall_time_s,
        "flow_exact_certified": bool(flow_exact is not None and flow_exact.converged),
        "flow_exact_energy": None if flow_exact is None else flow_exact.energy,
        "flow_exact_kkt_residual": None if flow_exact is None else flow_exact.kkt_residual,
        "flow_exact_stages": len(exact_stages), "flow_exact_steps": exact_run.steps,
        "flow_exact_wall_s": exact_run.wall_time_s, "exact_torus_start_energy": exact_ref.energy,
        "exact_torus_start_converged": exact_ref.converged,
        "flow_exact_vs_exact_torus_start": None if flow_exact is None else flow_exact.energy / exact_ref.energy - 1,
        # a flow equilibrium that fails says how and why (its reason names a floor's certifiable tol)
        "flow_eq_reason": None if flow_eq is None else flow_eq.reason,
        "flow_exact_outcome": None if flow_exact is None else flow_exact.outcome.value,
        "flow_exact_reason": None if flow_exact is None else flow_exact.reason,
        "flow_exact_shape": None if flow_exact is None else flow_exact.extra.get("shape"),
        **topo})
    np.savez_compressed(out / "equilibrium.npz", phi=eq.phi)
    log.info(f"torus_section5: n={n} flow t={s['t']:.3g} steps={s['steps']} E_flow={s['energy']:.6f} "
          f"E_eq={eq.energy:.6f} (paper {PAPER[n]}) path: {' -> '.join(states)}; flow to equilibrium: "
          f"{rows[-1]['flow_eq_outcome']} at step {relax.steps}, E = {rows[-1]['flow_eq_energy']}, "
          f"vs torus start {rows[-1]['flow_eq_vs_torus_start']}, wall {relax.wall_time_s:.1f} s; exact: "
          f"{rows[-1]['flow_exact_outcome']} after {len(exact_stages)} stages, E = {rows[-1]['flow_exact_energy']}, "
          f"vs exact torus start {rows[-1]['flow_exact_vs_exact_torus_start']}")
    for what in ("flow_eq", "flow_exact"):  # a failed flow equilibrium: its outcome and why, on the console
        if rows[-1][f"{what}_outcome"] not in (None, "converged"):
            log.warning(f"torus_section5: n={n} {what}: {rows[-1][f'{what}_outcome']} ({rows[-1][f'{what}_reason']})")
    return rows


def main(out: Path, quick: bool = False) -> int:
    out = Path(out)
    ns = (16,) if quick else (16, 32, 48, 64)
    cases = [{"case": f"n={n}", "n": n, "dir": str(out / f"flow-{n}"), "t_end": T_END, "disk": DISK,
              "start": "disk"} for n in ns]
    if not quick:
        cases.append({"case": "n=16 wide", "n": 16, "dir": str(out / "flow-16-wide"), "t_end": T_END,
                      "disk": WIDE_DISK, "start": "wide disk"})
    raw = run_cases("torus_section5", cases, case_rows, out / "torus_section5.csv", workers=1,
                    extra_columns=EXTRA)
    finals = [r for r in raw if r.get("row") == "final" and r.get("start") == "disk"]
    frames = [r for r in raw if r.get("row") == "frame" and r.get("start") == "disk"]
    _plot(out / "torus_section5.png", out, ns, frames, finals)
    ok = len(finals) == len(ns) and all(
        r["flow_status"] == "t_end" and r["torus_ok"] == "True" and r["equilibrium_converged"] == "True"
        and r["flow_eq_certified"] == "True" and r["flow_exact_certified"] == "True" for r in finals) and all(r["wraps"] == "none" for r in frames)
    return 0 if ok else 1


def _figure1_frames(frames: list[dict], count: int = 6) -> list[dict]:
    """The first frames up to two past the last topology change (the pinch-off), then the last one."""
    if not frames:
        return []
    chi = [r["euler_characteristic"] for r in frames]
    change = max((i for i in range(1, len(chi)) if chi[i] != chi[i - 1]), default=0)
    head = frames[:min(change + 3, count - 1, len(frames) - 1)]
    return head + [frames[-1]]


def _plot(path: Path, out: Path, ns, frames, finals) -> None:
    n = max(ns)
    shown = [r for r in frames if int(r["n"]) == n]
    shown = _figure1_frames(shown)
    cols = max(len(shown), len(ns), 1)
    fig, axes = plt.subplots(2, cols, figsize=(3.2 * cols, 6.6), squeeze=False)

    def cut(ax, phi, k, title):
        draw_cut(ax, phi.reshape(k, k, k)[:, k // 2, :], (-np.pi, -np.pi), (np.pi, np.pi), title)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax, r in zip(axes[0], shown):
        with np.load(out / f"flow-{n}" / "snapshots" / f"phi_{int(r['frame']):03d}.npz") as z:
            cut(ax, z["phi"], n, f"{n}^3, t = {float(r['t']):.3g}\nchi = {r['euler_characteristic']}")
    for ax, k in zip(axes[1], ns):
        eq = out / f"flow-{k}" / "equilibrium.npz"
        if eq.exists():
            e = next((float(r["energy"]) for r in finals if int(r["n"]) == k), float("nan"))
            cut(ax, np.load(eq)["phi"], k, f"final {k}^3: E = {e:.5f}\n(paper {PAPER[k]})")
    for row in axes:
        for ax in row:
            if not ax.images:
                ax.axis("off")
    fig.suptitle("Section 5: flat elliptic disk -> torus by scheme (23) (cut y = 0); bottom: final shapes")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/torus_section5"), quick="--quick" in sys.argv))
