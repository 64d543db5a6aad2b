"""Run a gradient flow of a scene and write its outputs (the ``vesicle-opt flow`` verb).

Writes into DIR: ``history.csv`` (one row per accepted step, flushed as it goes; columns in
``COLUMNS`` plus scheme extras), ``checkpoint.npz`` (resume state), ``snapshots/phi_JJJ.npz`` and
``frames/frame_JJJ.png`` at t = t_end * j / flow.frames, and at the end ``phi.npz``, ``phi.vtu``,
``phi.png`` and ``summary.json``. A run finding a checkpoint of the same problem in DIR resumes
from it (``restart=True`` starts afresh); history rows after the checkpoint are dropped.
"""

from __future__ import annotations

import csv
import hashlib
import math
import shutil
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from vesicle_opt.io import output
from vesicle_opt.mesh import Discretization, discretize
from vesicle_opt.mesh.base import require_lumped
from vesicle_opt.errors import InputError
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.scene.shapes import phase_field
from vesicle_opt.flows.backward_euler import BackwardEulerScheme
from vesicle_opt.flows.discrete import FEATURE, WHY, FlowModel
from vesicle_opt.flows.lagrange import LagrangeScheme
from vesicle_opt.flows.penalty import PenaltyScheme
from vesicle_opt.flows.projection import project
from vesicle_opt.flows.stepper import RunOutcome, StepperOptions, run

SCHEMES = {"penalty": PenaltyScheme, "lagrange": LagrangeScheme, "backward-euler": BackwardEulerScheme}
COLUMNS = ["step", "t", "dt", "energy", "penalized_energy", "volume_residual", "area_residual",
           "energy_law_residual", "newton_iterations", "krylov_iterations", "wall_time_s", "rejections", "phi_t_norm"]
EXTRA = {"penalty": [], "lagrange": ["lambda_1", "lambda_2"], "backward-euler": ["equality_law_defect"]}


def build_model(scene, disc: Discretization | None = None) -> FlowModel:
    disc = disc or discretize(scene)
    alpha, beta = constraint_data(scene, disc)
    return FlowModel(disc, scene.model.epsilon, scene.model.C, scene.model.rigidity, alpha, beta,
                     scene.solver.M, scene.flow.gamma)


def initial_field(scene, md: FlowModel) -> np.ndarray:
    """The scene's initial shape, projected onto A = alpha, B = beta (``projection``) unless
    ``flow.initial = "shape"`` (penalty and backward Euler only; (17) must start on the set)."""
    phi0 = phase_field(scene.initial, md.disc.nodes, md.disc.box, scene.model.epsilon)
    if scene.flow.initial == "projected" or scene.flow.scheme == "lagrange":
        phi0 = project(md, phi0, md.alpha, md.beta)
    return phi0


def make_scheme(scene, md: FlowModel):
    return SCHEMES[scene.flow.scheme](md, law_tol=scene.flow.law_tol)


def stepper_options(scene, progress: bool = False) -> StepperOptions:
    fl = scene.flow
    return StepperOptions(dt=fl.dt, t_end=fl.t_end, max_steps=fl.steps, adaptive=fl.stepping == "adaptive",
                          dt_min=fl.dt_min, dt_max=fl.dt_max, steady_tol=fl.steady_tol,
                          checkpoint_every=fl.checkpoint_every, progress=progress)


def fingerprint(scene) -> str:
    """Identifies the problem a checkpoint belongs to (not t_end, steps, frames: those may change)."""
    key = replace(scene, name="", flow=replace(scene.flow, t_end=0.0, steps=1, frames=1, dt=0.0,
                                                stepping="constant", checkpoint_every=1))
    return hashlib.sha256(repr(key).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class FlowRun:
    outcome: RunOutcome
    model: FlowModel
    summary: dict


def _rows_upto(path: Path, step: int) -> list[dict]:
    if not path.exists():
        return []
    with open(path, newline="") as fh:
        return [r for r in csv.DictReader(fh) if int(r["step"]) <= step]


def flow(scene, out: Path, *, restart: bool = False, progress: bool = False, frames: bool = True) -> FlowRun:
    """Run ``scene.flow`` and write DIR (see the module docstring). Returns the outcome and summary."""
    check_supported(scene)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md = build_model(scene)
    scheme = make_scheme(scene, md)
    fl = scene.flow
    ckpt, hist, fp_file = out / "checkpoint.npz", out / "history.csv", out / "checkpoint.id"
    fp = fingerprint(scene)
    resume = (not restart and ckpt.exists() and fp_file.exists() and fp_file.read_text().strip() == fp)
    if not resume:
        for p in (ckpt, hist):
            p.unlink(missing_ok=True)
        for d in ("snapshots", "frames"):
            shutil.rmtree(out / d, ignore_errors=True)
        fp_file.write_text(fp + "\n")
    (out / "snapshots").mkdir(exist_ok=True)
    (out / "frames").mkdir(exist_ok=True)
    phi0 = initial_field(scene, md)
    fields = COLUMNS + EXTRA[fl.scheme]
    if resume:
        start_step = int(np.load(ckpt)["step"])
        rows = _rows_upto(hist, start_step)
        t_start = float(np.load(ckpt)["t"])
    else:
        rows, t_start, start_step = [], 0.0, 0
    fh = open(hist, "w", newline="")
    writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    fh.flush()
    frame_dt = fl.t_end / fl.frames
    next_frame = [int(math.floor(t_start / frame_dt + 1e-9)) + 1]

    def snapshot(j: int, t: float, phi: np.ndarray, E: float):
        np.savez_compressed(out / "snapshots" / f"phi_{j:03d}.npz", phi=phi, t=t)
        if frames:
            output.write_png(out / "frames" / f"frame_{j:03d}.png", md.disc, phi,
                             title=f"{scene.name} {fl.scheme}: t = {t:.4g}, E = {E:.6g}")

    if not resume:
        snapshot(0, 0.0, phi0, md.E(phi0))

    def on_accept(step, t, phi, row):
        writer.writerow(row)
        fh.flush()
        if t >= next_frame[0] * frame_dt * (1 - 1e-9):
            snapshot(next_frame[0], t, phi, row["energy"])
            next_frame[0] = int(math.floor(t / frame_dt + 1e-9)) + 1

    try:
        outcome = run(scheme, phi0, stepper_options(scene, progress), checkpoint=ckpt, resume=resume,
                      on_accept=on_accept)
    finally:
        fh.close()
    phi = outcome.phi
    obs = scheme.observe(phi)
    summary = {"scene": scene.name, "scheme": fl.scheme, "law": scheme.law, "status": outcome.status,
               "message": outcome.message, "steps": outcome.step, "t": outcome.t,
               "rejections": outcome.rejections, "wall_time_s": outcome.wall_time_s,
               "resumed_from_step": start_step,
               "n_nodes": md.disc.n_nodes, "gamma": md.gamma, "M": md.M, "alpha": md.alpha, "beta": md.beta,
               **{k: float(v) for k, v in obs.items()}}
    np.savez_compressed(out / "phi.npz", phi=phi, nodes=md.disc.nodes, t=outcome.t)
    output.write_vtk(out / "phi.vtu", md.disc, phi)
    output.write_png(out / "phi.png", md.disc, phi,
                     title=f"{scene.name} {fl.scheme}: t = {outcome.t:.4g}, E = {obs['energy']:.6g}")
    output.write_json(out / "summary.json", summary)
    return FlowRun(outcome, md, summary)


def check_supported(scene) -> None:
    """Refuse what the flows do not support, before any work (one-line InputError)."""
    if scene.mesh.kind not in ("fd", "fem-p1", "spectral"):
        raise InputError("mesh.kind", f"the gradient flows support 'fd', 'fem-p1' and 'spectral', "
                                      f"got {scene.mesh.kind!r}")
    if scene.mesh.kind == "spectral" and scene.flow.scheme == "backward-euler":
        raise InputError("flow.scheme", "'backward-euler' (23) goes through IPOPT, which needs assembled "
                                        "matrices: use 'penalty' or 'lagrange' on spectral grids")
    require_lumped(FEATURE, scene.mesh.mass, scene.mesh.quadrature, WHY)
