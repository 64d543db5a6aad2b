"""Stress study: stiff and extreme cases, each ending as a verified solution or an honest failure.

One CSV row per case with its outcome — ``converged`` (IPOPT success and the recomputed KKT and
constraint residuals within tolerance; ``second_order`` and ``topology`` say what was found),
``failed: <status>``, or ``refused: <reason>`` (bad or infeasible input, before any solve).
Groups:

* ``resolution``: eps/h = 8, 4, 2, 1, 0.5 at fixed h, energy against a 4x finer mesh;
* ``feasibility``: near the isoperimetric limit, placed against the phase-field bound
  beta = beta_min(alpha) (1 + delta), delta = 1e-2, 1e-3, 1e-4, and -1e-2 (must be refused); and,
  for comparison, against the sharp limit: the beta of sharp reduced volume v = 0.99, 0.999,
  0.9999 and 1.01 (beyond the sharp limit). At eps = 0.2 the phase-field bound lies 4.3% below the
  sharp one, so all four sharp cases are feasible phase-field data. Column ``limit_reference``
  says which bound a case is placed against, ``beta_over_beta_min`` = beta / beta_min - 1;
* ``curvature``: spontaneous curvature c0 R in {-3, -1, 0, 1, 3} (R: radius of equal area);
* ``initial``: starts far from the target (constant phi, noise, a shape across the periodic
  boundary; 3D: a torus start for a sphere target, a sphere start for the torus data);
* ``symmetry``: a circle start for the ellipse target (a saddle) and a large flat disk in a
  periodic box (a slab joined to its periodic image);
* ``domain``: a non-square box, an anisotropic grid, an unstructured mesh read from a file;
* ``penalty``: the penalty form (11) at M = 1e2 ... 1e12 (conditioning of the penalised problem);
* ``flow``: three steps of scheme (18) with k from the paper's 3e-8 up to 10, far beyond what the
  Newton solve can take: the stepper must reject and halve k, never produce NaN.

    vesicle-opt study stress --out DIR [--quick]
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
import skfem

from vesicle_opt import scene
from vesicle_opt.api import solve
from vesicle_opt.errors import InputError
from vesicle_opt.flows import stepper
from vesicle_opt.flows.api import build_model, initial_field, make_scheme
from vesicle_opt.flows.trackers import HistoryTracker
from vesicle_opt.mesh import discretize
from vesicle_opt.model import feasibility
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.studies._common import pyplot as plt
from vesicle_opt.studies.runner import run_cases

EXTRA = ["group", "parameter", "outcome", "reference_energy", "relative_energy_error", "kkt_residual",
         "second_order", "second_order_min_eigenvalue", "topology", "rejections", "max_law_residual",
         "limit_reference", "beta_over_beta_min"]
BETA_MIN, SHARP = "phase-field beta_min(alpha)", "sharp reduced volume"


def _cases(quick: bool, mesh_dir: Path) -> list[dict]:
    n = 48 if quick else 64
    base = ("ellipse-2d", [f"mesh.n={n}"])
    out: list[dict] = []

    def add(group, case, parameter, scene=base[0], overrides=(), reference=None):
        out.append({"group": group, "case": f"{group}: {case}", "method": "exact", "parameter": parameter, "scene": scene,
                    "overrides": [*(base[1] if scene == base[0] else []), *overrides],
                    "reference": reference})

    h = 8.0 / n
    for ratio in ([4, 1] if quick else [8, 4, 2, 1, 0.5]):
        eps = ratio * h
        ref = None if quick else [f"mesh.n={4 * n}", f"model.epsilon={eps!r}"]
        add("resolution", f"eps/h={ratio}", ratio, overrides=[f"model.epsilon={eps!r}"], reference=ref)
    for delta in ([1e-3, -1e-2] if quick else [1e-2, 1e-3, 1e-4, -1e-2]):
        add("feasibility", f"beta=beta_min(1{delta:+g})", delta, overrides=[f"@beta_factor={1 + delta!r}"])
    for v in ([0.999, 1.01] if quick else [0.99, 0.999, 0.9999, 1.01]):
        add("feasibility", f"sharp reduced volume {v:g}", v, overrides=[f"@reduced_volume={v!r}"])
    R = math.sqrt(2.0 * 1.0)  # circle with the area of the 2 x 1 ellipse
    for c0R in ([-1, 1] if quick else [-3, -1, 0, 1, 3]):
        add("curvature", f"c0*R={c0R}", c0R, overrides=[f"model.c0={c0R / R!r}"])
    add("initial", "phi=0.2 everywhere", 0.2, overrides=["initial.shape='constant'", "initial.value=0.2"])
    add("initial", "uniform noise", 0, overrides=["initial.shape='noise'", "initial.seed=1"])
    add("initial", "across the periodic boundary", 3.3, overrides=["initial.center=[3.3, 0.5]"])
    add("symmetry", "circle start, ellipse target", 1.5,
        overrides=["initial.shape='circle'", "initial.radius=1.5"])
    add("domain", "non-square box 8 x 6", 0.75,
        overrides=["domain.box=[[-4.0, 4.0], [-3.0, 3.0]]", f"mesh.n=[{n}, {3 * n // 4}]"])
    add("domain", "anisotropic grid", 0.5, overrides=[f"mesh.n=[{n}, {n // 2}]"])
    add("domain", "unstructured mesh file", 0, overrides=[
        "mesh.kind='fem-p1'", "domain.boundary='natural'", f"mesh.file='{mesh_dir / 'disk.vtk'}'",
        "model.epsilon=0.25", "constraints.target.semi_axes=[1.6, 0.9]", "initial.semi_axes=[1.5, 1.0]"])
    for M in ([1e2, 1e8, 1e12] if quick else [1e2, 1e4, 1e6, 1e8, 1e10, 1e12]):
        add("penalty", f"M={M:g}", M, overrides=["solver.method='penalty'", f"solver.M={M!r}"])
    for k in ([3e-8, 1e-1, 10.0] if quick else [3e-8, 1e-5, 1e-3, 1e-1, 10.0]):
        add("flow", f"scheme (18), k={k:g}", k, overrides=["mesh.n=32", "flow.scheme='penalty'", f"flow.dt={k!r}"])
        out[-1]["method"] = "flow (18)"
    if not quick:
        add("initial", "torus start, sphere target", 0, scene="sphere-3d",
            overrides=["mesh.kind='fd'", "initial.shape='torus'", "initial.radii=[1.0, 0.45]"])
        add("initial", "sphere start, torus data", 0, scene="torus-table1-3d",
            overrides=["initial.shape='sphere'", "initial.radius=1.7"])
        add("symmetry", "large flat disk, periodic box", 2.9, scene="torus-table1-3d",
            overrides=["initial.shape='disk'", "initial.radius=2.9", "initial.thickness=0.6"])
    return out


def _scene(case: dict, extra=()):
    overrides = [o for o in case["overrides"] if not o.startswith("@")]
    return scene.load(case["scene"], [*overrides, *extra])


def run_flow_case(case: dict) -> dict:
    """Three steps of the flow with constant k and rejection (halving) down to the default dt_min."""
    sc = _scene(case)
    md = build_model(sc)
    scheme = make_scheme(sc, md)
    k = sc.flow.dt
    history = HistoryTracker()
    opts = stepper.StepperOptions(dt=k, t_end=1e6 * k, max_steps=3)
    outcome = stepper.run(scheme, initial_field(sc, md), opts, [history])
    laws = [abs(float(r["energy_law_residual"])) for r in history.rows]
    obs = scheme.observe(outcome.phi)
    finite = bool(np.all(np.isfinite(outcome.phi)))
    ok = outcome.status in ("t_end", "max_steps", "steady") and finite
    return {"status": outcome.status, "energy": obs["energy"], "volume_residual": obs.get("volume_residual"),
            "area_residual": obs.get("area_residual"), "iterations": outcome.step,
            "wall_time_s": outcome.wall_time_s, "rejections": outcome.rejections,
            "max_law_residual": max(laws) if laws else None,
            "outcome": "converged" if ok else f"failed: {outcome.status}: {outcome.message}"[:200]}


def sharp_beta(alpha: float, sc, v: float) -> float:
    """beta whose sharp area gives reduced volume v to the enclosed volume V = (|Omega| + alpha)/2:
    v = 4 pi V / L^2 (2D), 6 sqrt(pi) V / S^(3/2) (3D); beta = 4 area / (3 sqrt 2) (Section 3.1)."""
    V = (sc.domain.volume + alpha) / 2
    area = math.sqrt(4 * math.pi * V / v) if sc.dim == 2 else (6 * math.sqrt(math.pi) * V / v) ** (2 / 3)
    return 4 * area / (3 * math.sqrt(2))


def run_case(case: dict) -> dict:
    row = {k: case[k] for k in ("group", "scene", "parameter", "method")}
    t0 = time.perf_counter()
    if case["group"] == "flow":
        return {**row, **run_flow_case(case)}
    try:
        extra = []
        tags = dict(o[1:].split("=") for o in case["overrides"] if o.startswith("@"))
        if tags:  # place beta near the isoperimetric limit of this alpha (see the module docstring)
            sc = _scene(case)
            alpha, _ = constraint_data(sc, discretize(sc))
            bound = feasibility.beta_min(alpha, sc.model.epsilon, sc.domain.box, sc.domain.boundary)
            if "beta_factor" in tags:
                beta, row["limit_reference"] = float(tags["beta_factor"]) * bound, BETA_MIN
            else:
                beta, row["limit_reference"] = sharp_beta(alpha, sc, float(tags["reduced_volume"])), SHARP
            row["beta_over_beta_min"] = beta / bound - 1
            extra = [f"constraints.alpha={alpha!r}", f"constraints.beta={beta!r}"]
        res = solve(_scene(case, extra))
    except InputError as exc:
        return {**row, "outcome": f"refused: {exc}", "wall_time_s": time.perf_counter() - t0}
    row.update(status=res.status, energy=res.energy, kkt_residual=res.kkt_residual,
               volume_residual=res.volume_residual, area_residual=res.area_residual,
               iterations=res.iterations, wall_time_s=res.wall_time_s,
               second_order=res.extra.get("second_order"), topology=res.extra.get("topology"),
               second_order_min_eigenvalue=res.extra.get("second_order_min_eigenvalue"),
               outcome="converged" if res.converged else
               f"failed: {res.status}: {res.extra.get('reason', 'not converged')}"[:200])
    if case["reference"] and res.converged:
        ref = solve(_scene(case, case["reference"]))
        if ref.converged:
            row["reference_energy"] = ref.energy
            row["relative_energy_error"] = abs(res.energy - ref.energy) / abs(ref.energy)
    return row


def case_rows(case: dict) -> list[dict]:
    return [run_case(case)]


def main(out: Path, quick: bool = False) -> int:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    mesh_path = out / "disk.vtk"
    if not mesh_path.exists():
        skfem.MeshTri.init_circle(5).scaled(3.0).save(str(mesh_path))
    rows = run_cases("stress", _cases(quick, out), case_rows, out / "stress.csv", extra_columns=EXTRA)
    _plot(rows, out / "stress.png")
    return 0


def _plot(rows: list[dict], path: Path) -> None:
    colours = {"converged": "tab:green", "failed": "tab:red", "refused": "tab:grey"}
    fig, ax = plt.subplots(figsize=(8, 0.3 * len(rows) + 1))
    for i, r in enumerate(rows):
        kind = (r["outcome"] or r["status"]).split(":")[0]
        t = float(r["wall_time_s"] or 0)
        ax.barh(i, max(t, 1e-3), color=colours.get(kind, "k"))
        label = (r["outcome"] or r["status"])[:40] + (f" ({r['second_order']})" if r["second_order"] else "")
        ax.text(max(t, 1e-3), i, " " + label, va="center", fontsize=7)
    ax.set_yticks(range(len(rows)), [r["case"] for r in rows], fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("wall time [s] (green: converged, red: failed, grey: refused)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "results"), quick="--quick" in sys.argv))
