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
* ``ProgressTracker``: one refreshed progress line on a stream (stderr by default);
* ``StopTracker``: stop when ``criterion(row)`` is true; ``CallbackTracker``: any ``fn(state, row)``.
"""

from __future__ import annotations

import csv
import math
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from vesicle_opt.errors import InputError
from vesicle_opt.io.files import load_npz, save_npz
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
    """``DIR/snapshots/phi_JJJ.npz`` (phi, t) and, with ``png``, ``DIR/frames/frame_JJJ.png`` at the
    first accepted step with t >= t_end j / frames (j = 0 at the start of a fresh run). ``title``
    labels the frames, with ``E = energy(phi)`` at j = 0 and the row's ``energy`` after."""

    def __init__(self, directory: Path, disc, t_end: float, frames: int, *, png: bool = True, title: str = "",
                 energy: Callable[[np.ndarray], float] | None = None):
        self.dir, self.disc, self.frame_dt, self.png = Path(directory), disc, t_end / frames, png
        self.title, self.energy = title, energy
        self.next_frame = 1

    def _snapshot(self, j: int, t: float, phi: np.ndarray, E: float | None) -> None:
        np.savez_compressed(self.dir / "snapshots" / f"phi_{j:03d}.npz", phi=phi, t=t)
        if self.png:
            # matplotlib only when frames are drawn: ``import vesicle_opt`` does not load it
            from vesicle_opt.io.output import write_png
            label = f"{self.title}: t = {t:.4g}" + ("" if E is None else f", E = {E:.6g}")
            write_png(self.dir / "frames" / f"frame_{j:03d}.png", self.disc, phi, title=label)

    def start(self, state):
        (self.dir / "snapshots").mkdir(parents=True, exist_ok=True)
        if self.png:
            (self.dir / "frames").mkdir(parents=True, exist_ok=True)
        self.next_frame = int(math.floor(state.t / self.frame_dt + 1e-9)) + 1
        if state.step == 0:
            self._snapshot(0, state.t, state.phi, None if self.energy is None else self.energy(state.phi))

    def handle(self, state, row):
        if state.t >= self.next_frame * self.frame_dt * (1 - 1e-9):
            self._snapshot(self.next_frame, state.t, state.phi, row.get("energy"))
            self.next_frame = int(math.floor(state.t / self.frame_dt + 1e-9)) + 1


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

    @staticmethod
    def load(path: Path, fingerprint: str | None = None) -> FlowState | None:
        """The state saved in ``path``, or None when there is no such file; with ``fingerprint``, an
        InputError (key resume_from) when the checkpoint was written for another problem."""
        st = load_npz(path)
        if st is None:
            return None
        saved = st.get("fingerprint")
        if fingerprint is not None and saved is not None and str(saved) != fingerprint:
            raise InputError("resume_from", f"{path} is a checkpoint of another problem (scene, scheme or "
                             "model changed); start afresh or give that scene")
        return FlowState.from_arrays(st)


class ProgressTracker(Tracker):
    """A progress line (step, t[/t_end], k, E, law residual, rejections) refreshed in place on
    ``stream`` (default: sys.stderr at the time of writing) at most every ``interval`` seconds,
    ended by a newline when the run ends."""

    def __init__(self, stream=None, *, interval: float = 2.0, t_end: float | None = None):
        self.stream, self.interval, self.t_end = stream, interval, t_end
        self._last = -math.inf

    def _out(self):
        return self.stream if self.stream is not None else sys.stderr

    def start(self, state):
        self._last = -math.inf

    def handle(self, state, row):
        if time.perf_counter() - self._last > self.interval:
            self._last = time.perf_counter()
            t = f"{state.t:.4g}" + ("" if self.t_end is None else f"/{self.t_end:.4g}")
            print(f"\r  step {state.step}  t = {t}  dt = {row['dt']:.3g}  E = {row.get('energy', math.nan):.8g}  "
                  f"law = {row.get('energy_law_residual', math.nan):.1e}  rejected = {state.rejections}",
                  end="", file=self._out(), flush=True)

    def finish(self, state):
        print(file=self._out(), flush=True)
