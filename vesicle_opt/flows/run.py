"""Run a gradient flow of a scene into a directory (the ``vesicle-opt flow`` verb): the in-memory
``flows.api.flow`` plus the directory trackers.

Writes into DIR: ``history.csv`` (one row per accepted step, flushed as it goes; columns in
``COLUMNS`` plus scheme extras), ``checkpoint.npz`` (resume state) with ``checkpoint.id`` (the
problem's fingerprint), ``snapshots/phi_JJJ.npz`` with
``snapshots/phi_JJJ.vti`` (periodic grids; ``.vtu`` on meshes), the ParaView time series ``phi.pvd``
of all of them and ``frames/frame_JJJ.png``, spaced over the run's span (``SnapshotTracker``: t_end
or flow.steps, whichever ends the run), and at the end ``phi.npz``, ``phi.vtu``, ``phi.vti``
(grids), ``phi.png``, ``surface.ply`` (3D grids), ``scene.resolved.toml`` and ``summary.json``. A run finding a checkpoint of the same problem in DIR resumes from it
(``restart=True`` starts afresh); history rows after the checkpoint are dropped.
"""

from __future__ import annotations

import csv
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vesicle_opt.io import fields, files, output
from vesicle_opt.scene import resolved
from vesicle_opt.flows.api import FlowResult, build_model, check_supported, fingerprint, flow
from vesicle_opt.flows.trackers import CheckpointTracker, HistoryTracker, ProgressTracker, SnapshotTracker

COLUMNS = ["step", "t", "dt", "energy", "penalized_energy", "volume_residual", "area_residual",
           "energy_law_residual", "newton_iterations", "krylov_iterations", "wall_time_s", "rejections", "phi_t_norm"]
EXTRA = {"penalty": [], "lagrange": ["lambda_1", "lambda_2"], "backward-euler": ["equality_law_defect"]}


@dataclass(frozen=True)
class FlowRun:
    result: FlowResult
    summary: dict


def _rows_upto(path: Path, step: int) -> list[dict]:
    if not path.exists():
        return []
    with open(path, newline="") as fh:
        return [r for r in csv.DictReader(fh) if int(r["step"]) <= step]


def write_flow(scene, out: Path, *, restart: bool = False, progress: bool = False, frames: bool = True) -> FlowRun:
    """Run ``scene.flow`` and write DIR (see the module docstring). Returns the result and summary."""
    check_supported(scene)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md = build_model(scene)
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
    state = CheckpointTracker.load(ckpt) if resume else None
    history = HistoryTracker(hist, columns=COLUMNS + EXTRA[fl.scheme], keep=False,
                             prior=_rows_upto(hist, state.step) if resume else [])
    trackers = [history, SnapshotTracker(out, md.disc, fl.t_end, fl.frames, png=frames,
                                         title=f"{scene.name} {fl.scheme}", energy=md.E, steps=fl.steps,
                                         vtk=frames),
                CheckpointTracker(ckpt, every=fl.checkpoint_every)]
    if progress:
        trackers.append(ProgressTracker(t_end=fl.t_end, steps=fl.steps,
                                        dt=fl.dt if fl.stepping == "constant" else None))
    try:
        res = flow(scene, trackers=trackers, resume_from=state, model=md)
    finally:
        history.close()
    phi = res.phi
    summary = {"scene": scene.name, "version": files.package_version(), "scheme": fl.scheme, "law": res.law, "status": res.status.value,
               "outcome": res.status.value, "message": res.message, "steps": res.steps, "t": res.t,
               "rejections": res.rejections, "wall_time_s": res.wall_time_s,
               "resumed_from_step": res.resumed_from_step,
               "n_nodes": md.disc.n_nodes, "gamma": md.gamma, "M": md.M, "alpha": md.alpha, "beta": md.beta,
               **{k: float(v) for k, v in res.observed.items()}}
    fields.write(out / "phi.npz", "flow", phi, md.disc, compressed=True, t=res.t)  # the npz layout of io.fields
    output.write_vtk(out / "phi.vtu", md.disc, phi)
    if md.disc.grid_shape is not None:
        output.write_field(out, "phi", md.disc, phi)  # phi.vti: the complete periodic grid
    output.write_png(out / "phi.png", md.disc, phi,
                     title=f"{scene.name} {fl.scheme}: t = {res.t:.4g}, E = {res.energy:.6g}")
    summary.update(output.write_surface_files(out, md.disc, phi, {}))
    resolved.write(out / "scene.resolved.toml", scene)
    files.write_json(out / "summary.json", summary)
    return FlowRun(res, summary)
