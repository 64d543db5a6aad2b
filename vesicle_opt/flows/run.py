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

All of it is written into the staging directory ``DIR/.vesicle-opt-partial`` and moved into DIR
when the run ends (``io.staging``): an interrupted run leaves DIR's files as they were and its own
state in the staging directory, which the rerun resumes from (a checkpoint of the last accepted
step is written when a SIGINT/SIGTERM ends the run, ``io.interrupt``); a run extending a finished
one of the same problem starts from a copy of DIR's state files.
"""

from __future__ import annotations

import logging
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vesicle_opt.io import fields, files, interrupt, output
from vesicle_opt.io import state as state_files
from vesicle_opt.io.staging import Staging
from vesicle_opt.scene import resolved
from vesicle_opt.scene.ranges import resolution_warning
from vesicle_opt.flows.api import FlowResult, build_model, check_supported, fingerprint, flow
from vesicle_opt.flows.trackers import CheckpointTracker, HistoryTracker, ProgressTracker, SnapshotTracker, Tracker

COLUMNS = ["step", "t", "dt", "energy", "penalized_energy", "volume_residual", "area_residual",
           "energy_law_residual", "newton_iterations", "krylov_iterations", "wall_time_s", "rejections", "phi_t_norm"]
EXTRA = {"penalty": [], "lagrange": ["lambda_1", "lambda_2"], "backward-euler": ["equality_law_defect"]}


log = logging.getLogger(__name__)

STATE_FILES = ("history.csv", "checkpoint.npz", "checkpoint.id", "snapshots", "frames", "phi.pvd")


@dataclass(frozen=True)
class FlowRun:
    result: FlowResult
    summary: dict
    where: Path | None = None  # the directory holding the files (DIR, or its staging directory)


class _LastState(Tracker):
    """The last state every other tracker has handled (checkpointed when a signal ends the run),
    and the interrupt message's place (``io.interrupt.note``)."""

    state = None

    def start(self, state):
        self.state = state
        interrupt.note(f"at step {state.step} (t = {state.t:.6g})", resume=True)

    def handle(self, state, row):
        self.start(state)


def _same_problem(d: Path, fp: str) -> bool:
    ckpt, fp_file = d / "checkpoint.npz", d / "checkpoint.id"
    return ckpt.exists() and fp_file.exists() and fp_file.read_text(errors="replace").strip() == fp


ADVICE = "delete it, or rerun with --restart (nothing there was changed)"


def _check_state(d: Path, fp: str, n_nodes: int) -> None:
    """The checkpoint and history of ``d`` through the checked loaders (``io.state``), before any
    work: a StateFileError (exit 2, the files untouched) when they do not parse or are not this run's."""
    CheckpointTracker.load(d / "checkpoint.npz", fp, n_nodes, key="--out", advice=ADVICE)
    _history(d / "history.csv")


def _history(path: Path) -> list[dict]:
    """The rows of history.csv (checked, ``io.state``; a torn last line left out)."""
    found = state_files.read_csv(path, lambda h: None if "step" in h else "no step column", _step_row, ADVICE)
    return [] if found is None else found[1]


def _step_row(row: dict, index: int) -> str | None:
    return state_files.typed_row(row, ints=("step",)) or (None if row["step"] else "no step")


def _rows_upto(path: Path, step: int) -> list[dict]:
    return [r for r in _history(path) if int(r["step"]) <= step]


def _work_dir(out: Path, fp: str, restart: bool, n_nodes: int) -> tuple[Staging, bool]:
    """The staging directory of the run and whether it resumes (module docstring)."""
    stage = Staging(out)
    if not restart and _same_problem(stage.dir, fp):
        _check_state(stage.dir, fp, n_nodes)
        return stage, True
    if restart or not _same_problem(out, fp):
        stage.fresh()
        return stage, False
    _check_state(out, fp, n_nodes)
    work = stage.fresh()
    for name in STATE_FILES:  # copies: the run's writes must not reach a finished run's files
        src = out / name
        if src.is_dir():
            shutil.copytree(src, work / name)
        elif src.exists():
            shutil.copy2(src, work / name)
    return stage, True


def write_flow(scene, out: Path, *, restart: bool = False, progress: bool = False, frames: bool = True) -> FlowRun:
    """Run ``scene.flow`` and write DIR (see the module docstring). Returns the result and summary."""
    check_supported(scene)
    final = Path(out)
    final.mkdir(parents=True, exist_ok=True)
    md = build_model(scene)
    fl = scene.flow
    fp = fingerprint(scene)
    stage, resume = _work_dir(final, fp, restart, md.disc.n_nodes)  # the state files' refusals
    if (coarse := resolution_warning(scene)) is not None:  # eps / h below the recommended 2: after every
        log.warning("%s", coarse)  # refusal (one line, exit 2, alone), before the flow (as api.solve)
    out = stage.dir
    ckpt, hist, fp_file = out / "checkpoint.npz", out / "history.csv", out / "checkpoint.id"
    if not resume:
        fp_file.write_text(fp + "\n")
    (out / "snapshots").mkdir(exist_ok=True)
    (out / "frames").mkdir(exist_ok=True)
    state = CheckpointTracker.load(ckpt, fp, md.disc.n_nodes, key="--out", advice=ADVICE) if resume else None
    history = HistoryTracker(hist, columns=COLUMNS + EXTRA[fl.scheme], keep=False,
                             prior=_rows_upto(hist, state.step) if resume else [])
    trackers = [history, SnapshotTracker(out, md.disc, fl.t_end, fl.frames, png=frames,
                                         title=f"{scene.name} {fl.scheme}", energy=md.E, steps=fl.steps,
                                         vtk=frames),
                checkpoint := CheckpointTracker(ckpt, every=fl.checkpoint_every)]
    if progress:
        trackers.append(ProgressTracker(t_end=fl.t_end, steps=fl.steps,
                                        dt=fl.dt if fl.stepping == "constant" else None))
    last = _LastState()
    trackers.append(last)  # last: its state has been handled by every tracker before it
    try:
        res = flow(scene, trackers=trackers, resume_from=state, model=md)
    except KeyboardInterrupt:  # SIGINT/SIGTERM (io.interrupt): the last accepted step, checkpointed
        if last.state is not None:
            with interrupt.deferred():
                checkpoint.save(last.state)
        raise
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
    return FlowRun(res, summary, stage.finish(ok=res.status.value != "failed"))
