"""A run's files staged beside those of ``--out`` and moved in only when complete.

``solve`` and ``flow`` write everything into ``DIR/.vesicle-opt-partial/`` (``PARTIAL``) and move
each entry into ``DIR`` (``Staging.commit``: ``os.replace`` per file, a directory swapped whole)
when the run has ended. So an interrupted run, or one whose disk failed, never replaces a finished
run's ``summary.json``, ``phi.npz`` or pictures: it leaves its files in the staging directory (a
flow its checkpoint there, which the rerun resumes from) and ``DIR``'s own as they were. The
directory lock (``io.outdir.locked``) is held throughout, so the staging directory has one writer.

A run that ended but *failed* (a solve not converged, a flow with status ``failed``) is moved in
too, as the exit-1 contract says ("results still written"), except when ``DIR`` holds a good run
(``holds_good_run``: a ``summary.json`` with ``converged`` true or a flow status other than
``failed``): then its files stay in the staging directory and the caller says where.

``rescue(write, why)`` writes a result whose ``--out`` failed during the run (no space left, a
read-only remount, ...) into a fresh temporary directory instead, so a computed result is kept.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable

from vesicle_opt.errors import OutputError
from vesicle_opt.io import interrupt

PARTIAL = ".vesicle-opt-partial"


def holds_good_run(out: Path) -> bool:
    """Whether ``out`` holds a finished good run (module docstring); unreadable: no."""
    try:
        summary = json.loads((Path(out) / "summary.json").read_text())
    except (OSError, ValueError):
        return False
    if not isinstance(summary, dict):
        return False
    if "converged" in summary:
        return summary["converged"] is True
    return summary.get("status") not in (None, "failed")


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


class Staging:
    """The staging directory ``out/PARTIAL`` of one run (module docstring)."""

    def __init__(self, out: Path):
        self.out = Path(out)
        self.dir = self.out / PARTIAL

    def fresh(self) -> Path:
        """The staging directory, emptied (what an earlier run left there is not this run's)."""
        _remove(self.dir)
        self.dir.mkdir(parents=True)
        return self.dir

    def discard(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)

    def commit(self) -> None:
        """Move every entry of the staging directory into ``out`` (a signal waits until the move
        is done), then remove the staging directory. Raises ``Interrupted`` first when a signal was
        received and swallowed during the run."""
        interrupt.check()
        with interrupt.deferred():
            for entry in sorted(self.dir.iterdir()):
                dest = self.out / entry.name
                if entry.is_dir() and not entry.is_symlink():
                    old = self.out / f".{entry.name}.old-{os.getpid()}"
                    _remove(old)
                    if dest.exists() or dest.is_symlink():
                        dest.rename(old)
                    entry.rename(dest)
                    _remove(old)
                else:
                    if dest.is_dir() and not dest.is_symlink():
                        shutil.rmtree(dest)
                    os.replace(entry, dest)
            self.dir.rmdir()

    def finish(self, ok: bool) -> Path:
        """Commit when ``ok`` or when ``out`` holds no good run; returns where the files are."""
        if ok or not holds_good_run(self.out):
            self.commit()
            return self.out
        interrupt.check()
        return self.dir


def rescue(write: Callable[[Path], object], out: Path, exc: OSError, name: str = "run") -> OutputError:
    """Write the result into a new temporary directory after ``out`` failed with ``exc`` during the
    run; returns the ``OutputError`` (exit 1) that names both, for the caller to raise."""
    where = exc.filename or out
    why = f"{exc.strerror or exc} ({where})"
    try:
        spare = Path(tempfile.mkdtemp(prefix=f"vesicle-opt-{name}-"))
        write(spare)
    except OSError as exc2:
        return OutputError(f"cannot write into {str(out)!r}: {why}; nor into a temporary directory "
                           f"({exc2.strerror or exc2}); the result is lost")
    return OutputError(f"cannot write into {str(out)!r}: {why}; the computed result was written to "
                       f"{str(spare)!r} instead ({str(out)!r} was left as it was)")


def write_run(out: Path, write: Callable[[Path], object], ok: Callable[[object], bool],
              name: str = "run") -> tuple[object, Path]:
    """``write(dir)`` into the staging directory of ``out``, then ``Staging.finish``: returns
    (what ``write`` returned, where the files are). An OSError of the disk during the writing is
    an ``OutputError`` after ``rescue`` (the result written to a temporary directory)."""
    stage = Staging(out)
    try:
        value = write(stage.fresh())
    except OSError as exc:
        stage.discard()
        raise rescue(write, out, exc, name) from None
    return value, stage.finish(ok(value))
