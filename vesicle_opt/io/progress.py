"""Progress of long work: a tqdm bar on a terminal, plain periodic lines anywhere else.

``bar(desc, total=, unit=)`` is what the solvers, the flows and the study runner call. It shows
nothing unless progress is switched on (``enable()``: the CLI does it, ``-q`` does not), so a
library user and the test suite see no output. On a terminal (``stream.isatty()``) it is a
``tqdm`` bar (counts, rate, elapsed and ETA); on a pipe or a log file it writes one plain line
every ``interval`` seconds (``desc: 12/40 (30%), 8.1 s elapsed, ETA 19 s, <postfix>``), ended by a
newline and never containing ``\\r``, so logs stay readable. ``total=None`` (unknown length, e.g.
Newton steps) shows counts and elapsed time only.
"""

from __future__ import annotations

import math
import os
import sys
import time

_STATE = {"enabled": False, "silenced": False}


def enable(on: bool = True) -> None:
    """Switch progress output on (the CLI) or off (the default for library use)."""
    _STATE["enabled"] = bool(on)


def silence(on: bool = True) -> None:
    """No bar at all, not even a forced one (the CLI's ``-q``: a quiet run prints warnings only)."""
    _STATE["silenced"] = bool(on)


def enabled() -> bool:
    return _STATE["enabled"]


def _is_tty(stream) -> bool:
    """A terminal with a width (a pty without a size, e.g. under ``script``, gets plain lines: tqdm
    would cut its bar to 0 columns and show nothing)."""
    try:
        return bool(stream.isatty()) and os.get_terminal_size(stream.fileno()).columns > 0
    except (AttributeError, ValueError, OSError):
        return False


def eta_text(done: float, total: float | None, elapsed: float) -> str:
    """``ETA 19 s`` from the mean rate so far ('' when it cannot be estimated yet)."""
    if total is None or done <= 0 or not math.isfinite(total):
        return ""
    left = max(total - done, 0.0) * elapsed / done
    return f"ETA {left:.0f} s" if left < 120 else f"ETA {left / 60:.1f} min"


class NullBar:
    """What ``bar`` returns when progress is off: every call does nothing."""

    n = 0.0

    def update(self, n: float = 1) -> None:
        pass

    def set_postfix_str(self, s: str, refresh: bool = True) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class PlainBar(NullBar):
    """One line per ``interval`` seconds (and one at the end) on ``stream``: no ``\\r``, no cursor."""

    def __init__(self, desc: str, total: float | None, unit: str, stream, interval: float):
        self.desc, self.total, self.unit, self.stream, self.interval = desc, total, unit, stream, interval
        self.n, self.postfix = 0.0, ""
        self._t0 = time.perf_counter()
        self._last = self._t0
        self._closed = False
        self._shown = None  # (n, postfix) of the last line written

    def _count(self, x: float) -> str:
        return f"{x:.4g}" if isinstance(x, float) and not float(x).is_integer() else f"{int(x)}"

    def line(self) -> str:
        elapsed = time.perf_counter() - self._t0
        if self.total is not None:
            pct = 100.0 * self.n / self.total if self.total else 100.0
            head = f"{self._count(self.n)}/{self._count(self.total)} {self.unit} ({pct:.0f}%)"
        else:
            head = f"{self._count(self.n)} {self.unit}"
        parts = [head, f"{elapsed:.1f} s elapsed", eta_text(self.n, self.total, elapsed), self.postfix]
        return f"{self.desc}: " + ", ".join(p for p in parts if p)

    def _emit(self) -> None:
        self.stream.write(self.line() + "\n")
        self.stream.flush()
        self._last = time.perf_counter()
        self._shown = (self.n, self.postfix)

    def update(self, n: float = 1) -> None:
        self.n += n
        if time.perf_counter() - self._last >= self.interval:
            self._emit()

    def set_postfix_str(self, s: str, refresh: bool = True) -> None:
        self.postfix = s

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self._shown != (self.n, self.postfix):  # the final state, unless just written
                self._emit()


def bar(desc: str, total: float | None = None, unit: str = "it", *, stream=None, interval: float = 5.0,
        force: bool = False):
    """A progress bar for ``desc`` (see the module docstring); ``force`` shows it even when progress
    is off (a caller that asked for progress explicitly, e.g. ``ProgressTracker``)."""
    if _STATE["silenced"] or not (force or enabled()):
        return NullBar()
    stream = sys.stderr if stream is None else stream
    if _is_tty(stream):
        from tqdm import tqdm  # only when a bar is drawn: ``import vesicle_opt`` does not load it
        fmt = "{l_bar}{bar}| {n:.4g}/{total:.4g} {unit} [{elapsed}<{remaining}{postfix}]" \
            if total is not None else "{desc}: {n:.4g} {unit} [{elapsed}{postfix}]"
        return tqdm(desc=desc, total=total, unit=unit, file=stream, mininterval=0.5, dynamic_ncols=True,
                    bar_format=fmt, leave=True)
    return PlainBar(desc, total, unit, stream, interval)
