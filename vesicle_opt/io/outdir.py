"""The output directory of a run (``--out``): checked before any work, then locked for the run.

``check(path)`` refuses, with a one-line ``InputError`` naming ``--out``, a path that is a regular
file, lies below a file, cannot be created, or is not writable (probed by creating and removing a
file in it, so it is right for any file system and user, root included); any OSError on the way
(a name over the file system's limit, a read-only file system, no space left, permission denied)
is such a line, naming the path. ``locked(path)`` holds
an exclusive lock (``filelock``: ``flock`` on POSIX, released by the kernel when the process ends,
SIGKILL included) on ``DIR/.vesicle-opt.lock`` for the whole run; a second run into the same
directory is refused at once with one line instead of interleaving its files with the first's.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

import filelock

from vesicle_opt.errors import InputError

LOCK_NAME = ".vesicle-opt.lock"


def check(arg: str | Path, key: str = "--out") -> Path:
    """The output directory, created and probed for writing now (module docstring)."""
    if not isinstance(arg, (str, os.PathLike)) or not str(arg):
        raise InputError(key, f"expected a directory path, got {type(arg).__name__} {str(arg)[:40]!r}")
    path = Path(arg)
    try:
        for parent in [path, *path.parents]:  # the first existing ancestor must be a directory
            if parent.exists() or parent.is_symlink():
                if not parent.is_dir():
                    what = "is a file" if parent == path else f"lies below the file {str(parent)!r}"
                    raise InputError(key, f"cannot use {str(arg)!r} as the output directory: it {what}")
                break
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".probe-", dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise InputError(key, f"cannot write into {str(arg)!r} ({exc.strerror or exc})") from None
    return path


def make(out: str | Path, sub: str = "", key: str = "--out") -> None:
    """Create the directory ``out / sub`` (parents too); any OSError is one InputError line naming
    the output directory ``out``."""
    try:
        (Path(out) / sub).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(key, f"cannot use {str(out)!r} as the output directory "
                         f"({exc.strerror or exc})") from None


@contextlib.contextmanager
def locked(path: Path, key: str = "--out"):
    """Hold the run's exclusive lock on ``path`` (module docstring); InputError when another run
    holds it."""
    lock = filelock.FileLock(str(Path(path) / LOCK_NAME), timeout=0)
    try:
        lock.acquire()
    except filelock.Timeout:
        raise InputError(key, f"{str(path)!r} is in use by another vesicle-opt run (it holds "
                         f"{LOCK_NAME}); wait for it or choose another --out") from None
    except OSError as exc:
        raise InputError(key, f"cannot lock {str(path)!r} ({exc.strerror or exc})") from None
    try:
        yield path
    finally:
        lock.release()
