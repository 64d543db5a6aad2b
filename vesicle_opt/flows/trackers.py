"""Trackers of a flow run (py-pde style): history, snapshots, checkpoints, progress, stop criteria.

The stepper (``flows.stepper.run``) calls, for every tracker in order, ``start(state)`` before the
first step, ``handle(state, row)`` after every accepted step and ``finish(state)`` when the loop ends
normally (never when an exception escapes it). ``state`` is the ``FlowState`` a resumed run would
start from; ``row`` is the step's history row (the ``COLUMNS`` of ``flows.run`` plus scheme extras).
``handle`` returning True ends the run with status ``stopped``. Trackers hold no physics: where a
label needs an energy, the caller hands it a function.

Ready trackers:

* ``HistoryTracker``: rows in memory (``keep``) and/or appended to a CSV, flushed row by row;
* ``SnapshotTracker``: ``snapshots/phi_JJJ.npz`` and ``frames/frame_JJJ.png`` at t = t_end j / frames;
* ``CheckpointTracker``: ``checkpoint.npz`` every ``every`` steps and at the end (atomic,
  ``io.files.save_npz``); ``CheckpointTracker.load(path)`` gives the state to resume from;
* ``ProgressTracker``: progress with an ETA on a stream (stderr by default; tqdm on a terminal);
* ``StopTracker``: stop when ``criterion(row)`` is true; ``CallbackTracker``: any ``fn(state, row)``.
"""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path
from typing import Callable

import numpy as np

from vesicle_opt.errors import InputError, StateFileError
from vesicle_opt.io import progress
from vesicle_opt.io import fields
from vesicle_opt.io.files import save_npz
from vesicle_opt.io.state import read_npz
from vesicle_opt.flows.stepper import FlowState


class Tracker:
    """The protocol, with do-nothing defaults: override what you need."""

    def start(self, state: FlowState) -> None:
        pass

    def handle(self, state: FlowState, row: dict) -> bool | None:
        return None

    def finish(self, state: FlowState) -> None:
        pass


class CallbackTracker(Tracker):
    """``fn(state, row)`` after every accepted step; a True return stops the run."""

    def __init__(self, fn: Callable[[FlowState, dict], bool | None]):
        self.fn = fn

    def handle(self, state, row):
        return self.fn(state, row)


class StopTracker(Tracker):
    """Stops the run (status ``stopped``) at the first accepted step whose row meets ``criterion``."""

    def __init__(self, criterion: Callable[[dict], bool]):
        self.criterion = criterion

    def handle(self, state, row):
        return bool(self.criterion(row))


def as_tracker(obj) -> Tracker:
    """A tracker as given, or a plain callable ``fn(state, row)`` wrapped as a ``CallbackTracker``."""
    if all(hasattr(obj, m) for m in ("start", "handle", "finish")):
        return obj
    if callable(obj):
        return CallbackTracker(obj)
    raise InputError("trackers", f"expected a Tracker or a callable fn(state, row), got {type(obj).__name__}")


class HistoryTracker(Tracker):
    """The rows of the accepted steps: in ``rows`` when ``keep``, and written to ``path`` (CSV,
    header first, flushed after each row) when given. ``columns`` fixes the CSV header (other keys
    are dropped; default: the first row's keys); ``prior`` rows (e.g. those of a checkpointed run,
    as read back from its CSV) come first in both."""

    def __init__(self, path: Path | None = None, *, columns: list[str] | None = None, keep: bool = True,
                 prior: list[dict] = ()):
        self.path, self.columns, self.keep, self.prior = path, columns, keep, list(prior)
        self.rows: list[dict] = []
        self._fh = self._writer = None

    def start(self, state):
        self.rows = list(self.prior) if self.keep else []
        if self.path is None:
            return
        self._fh = open(self.path, "w", newline="")
        if self.columns is not None or self.prior:
            self._open_writer(self.columns or list(self.prior[0]))
            self._writer.writerows(self.prior)
            self._fh.flush()

    def _open_writer(self, columns):
        self._writer = csv.DictWriter(self._fh, fieldnames=columns, extrasaction="ignore")
        self._writer.writeheader()

    def handle(self, state, row):
        if self.keep:
            self.rows.append(row)
        if self._fh is not None:
            if self._writer is None:
                self._open_writer(list(row))
            self._writer.writerow(row)
            self._fh.flush()

    def finish(self, state):
        self.close()

    def close(self) -> None:
        """Close the CSV (also after an exception; ``finish`` does it after a normal end)."""
        if self._fh is not None:
            self._fh.close()
        self._fh = self._writer = None


class SnapshotTracker(Tracker):
    """Snapshots spaced over the run's actual span: ``DIR/snapshots/phi_JJJ.npz`` (phi, t), with
    ``vtk`` a viewer file beside it (``phi_JJJ.vti`` on periodic grids, ``.vtu`` on meshes) listed in
    the time series ``DIR/phi.pvd`` (rewritten after every snapshot, so a killed run leaves a valid
    one), and with ``png`` ``DIR/frames/frame_JJJ.png``. Snapshot j is taken at the first accepted
    step with t >= t_end j / frames or step >= steps j / frames (``steps``: the run's step cap, so
    that ``--steps 20`` spreads the frames over its 20 steps, not over t_end); j = 0 at the start
    of a fresh run, and the final state at the end when it is not a snapshot already. ``title``
    labels the frames, with ``E = energy(phi)`` at j = 0 and the row's ``energy`` after."""

    def __init__(self, directory: Path, disc, t_end: float, frames: int, *, png: bool = True, title: str = "",
                 energy: Callable[[np.ndarray], float] | None = None, steps: int | None = None,
                 vtk: bool = False):
        self.dir, self.disc, self.frame_dt, self.png = Path(directory), disc, t_end / frames, png
        self.frame_steps = None if steps is None else steps / frames
        self.title, self.energy, self.vtk = title, energy, vtk
        self.next_frame = 1
        self._last_step = None
        self._row: dict = {}

    def _due(self, state) -> int:
        j = int(math.floor(state.t / self.frame_dt * (1 + 1e-9) + 1e-9))
        if self.frame_steps is not None:
            j = max(j, int(math.floor(state.step / self.frame_steps + 1e-9)))
        return j

    def _snapshot(self, j: int, t: float, phi: np.ndarray, E: float | None, step: int) -> None:
        fields.write(self.dir / "snapshots" / f"phi_{j:03d}.npz", "flow-snapshot", phi, self.disc, compressed=True, t=t)
        self._last_step = step
        if self.png or self.vtk:
            # matplotlib and meshio only when files are drawn: ``import vesicle_opt`` does not load them
            from vesicle_opt.io import output
        if self.vtk:
            output.write_field(self.dir / "snapshots", f"phi_{j:03d}", self.disc, phi)
            self._write_pvd()
        if self.png:
            label = f"{self.title}: t = {t:.4g}" + ("" if E is None else f", E = {E:.6g}")
            output.write_png(self.dir / "frames" / f"frame_{j:03d}.png", self.disc, phi, title=label)

    def _write_pvd(self) -> None:
        from vesicle_opt.io.vtk import write_pvd  # with the viewer files only (see _snapshot)
        entries = []
        for npz in sorted((self.dir / "snapshots").glob("phi_*.npz")):
            view = next((p for p in (npz.with_suffix(".vti"), npz.with_suffix(".vtu")) if p.exists()), None)
            if view is not None:
                with np.load(npz) as z:
                    entries.append((float(z["t"]), f"snapshots/{view.name}"))
        write_pvd(self.dir / "phi.pvd", entries)

    def start(self, state):
        (self.dir / "snapshots").mkdir(parents=True, exist_ok=True)
        if self.png:
            (self.dir / "frames").mkdir(parents=True, exist_ok=True)
        self.next_frame = self._due(state) + 1
        if state.step == 0:
            self._snapshot(0, state.t, state.phi, None if self.energy is None else self.energy(state.phi), 0)

    def handle(self, state, row):
        due = self._due(state)
        if due >= self.next_frame:
            self._snapshot(due, state.t, state.phi, row.get("energy"), state.step)
            self.next_frame = due + 1
        self._row = row

    def finish(self, state):
        if self._last_step != state.step:  # the end state (t_end, steps, steady or stopped)
            self._snapshot(self.next_frame, state.t, state.phi, self._row.get("energy"), state.step)
            self.next_frame += 1


class CheckpointTracker(Tracker):
    """The resumable state in ``path`` (npz, written atomically) every ``every`` accepted steps
    (0: never) and at the end of the run; ``run(..., start=CheckpointTracker.load(path))`` continues
    it bit-for-bit. ``fingerprint`` (``flows.api.fingerprint(scene)``; ``vesicle_opt.flow`` sets it)
    is stored beside the state, so that a checkpoint is never resumed under another problem."""

    def __init__(self, path: Path, every: int = 50, fingerprint: str | None = None):
        self.path, self.every, self.fingerprint = Path(path), every, fingerprint

    def save(self, state: FlowState) -> None:
        tag = {} if self.fingerprint is None else {"fingerprint": np.array(self.fingerprint)}
        save_npz(self.path, **state.as_arrays(), **tag)

    def handle(self, state, row):
        if self.every and state.step % self.every == 0:
            self.save(state)

    def finish(self, state):
        self.save(state)

    KEYS = {"phi": ("f", 1), "phi_prev": ("f", 1), "t": ("n", 0), "step": ("i", 0), "k_try": ("n", 0),
            "k_last": ("x", 0), "rate0": ("x", 0), "rejections": ("i", 0), "wall_time_s": ("x", 0)}

    @staticmethod
    def load(path: Path, fingerprint: str | None = None, n_nodes: int | None = None, key: str = "resume_from",
             advice: str = "give another checkpoint or none") -> FlowState | None:
        """The state saved in ``path``, or None when there is no such file; read through the checked
        loader (``io.state.read_npz``): a file that is not a checkpoint, or one written for another
        problem (``fingerprint``) or grid (``n_nodes``), is a ``StateFileError`` (key ``key``)."""
        if not Path(path).exists():
            return None
        st = read_npz(path, CheckpointTracker.KEYS, advice, key)
        saved = st.get("fingerprint")
        if fingerprint is not None and saved is not None and str(saved) != fingerprint:
            raise StateFileError(path, "is a checkpoint of another problem (scene, scheme or model changed); "
                                 + advice, key)
        phi, prev = np.asarray(st["phi"]), np.asarray(st["phi_prev"])
        if (n_nodes is not None and phi.shape != (n_nodes,)) or prev.size not in (0, phi.size) \
                or st["step"] < 0 or st["rejections"] < 0 or st["t"] < 0 or st["k_try"] <= 0:
            raise StateFileError(path, f"is not a checkpoint of this grid ({phi.size} values, this grid has "
                                 f"{n_nodes}) or holds impossible values; {advice}", key)
        return FlowState.from_arrays(st)


class ProgressTracker(Tracker):
    """Progress of the run on ``stream`` (default: sys.stderr): a tqdm bar with an ETA on a terminal,
    plain lines every ``interval`` seconds elsewhere (``io.progress.bar``; never ``\r`` in a log).
    The bar runs over simulated time to ``t_end``, or over accepted steps to ``steps`` when that
    ends the run first (``steps * dt < t_end``, constant k); the postfix shows step, t[/t_end], k,
    E, the law residual and the rejections."""

    def __init__(self, stream=None, *, interval: float = 2.0, t_end: float | None = None,
                 steps: int | None = None, dt: float | None = None):
        self.stream, self.interval, self.t_end, self.steps, self.dt = stream, interval, t_end, steps, dt
        self._bar = None
        self._by_steps = False
        self._t0 = self._step0 = 0.0

    def start(self, state):
        by_time = self.t_end is not None and (self.steps is None or self.dt is None
                                              or self.steps * self.dt >= self.t_end)
        self._by_steps = not by_time and self.steps is not None
        total = (self.steps if self._by_steps else self.t_end)
        done = state.step if self._by_steps else state.t
        self._bar = progress.bar("flow", total=total, unit="steps" if self._by_steps else "t",
                                 stream=self.stream if self.stream is not None else sys.stderr,
                                 interval=self.interval, force=True)
        self._t0, self._step0 = state.t, state.step
        if done:
            self._bar.update(done)

    def handle(self, state, row):
        t = f"{state.t:.4g}" + ("" if self.t_end is None or self._by_steps else f"/{self.t_end:.4g}")
        self._bar.set_postfix_str(f"step {state.step}  t = {t}  dt = {row['dt']:.3g}  "
                                  f"E = {row.get('energy', math.nan):.8g}  "
                                  f"law = {row.get('energy_law_residual', math.nan):.1e}  "
                                  f"rejected = {state.rejections}", refresh=False)
        if self._by_steps:
            self._bar.update(state.step - self._step0)
            self._step0 = state.step
        else:
            self._bar.update(state.t - self._t0)
            self._t0 = state.t

    def finish(self, state):
        if self._bar is not None:
            self._bar.close()
