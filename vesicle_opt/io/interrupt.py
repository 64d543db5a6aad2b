"""Interrupts of a run (SIGINT, SIGTERM): one line, the conventional exit code, no traceback.

``handled()`` installs, for the block, handlers of SIGINT and SIGTERM that record the signal and
raise ``Interrupted`` (a ``KeyboardInterrupt``, so no ``except Exception`` of a solver swallows it).
C extensions may still catch it: CasADi turns an exception raised during an IPOPT iteration into a
solver status ("NonIpopt_Exception_Thrown") and returns. The record stays, so ``check()`` raises
``Interrupted`` again at the next boundary (after each IPOPT call, before files are committed):
an interrupted solve is never returned as a result nor written as a row.

``note(where, resume)`` says where the run is ("at step 12 (t = 0.012)", "at point 3", "after 4 of 9
cases") and whether the verb resumes from its files; ``message(signum)`` is the one line the CLI prints:
``interrupted (SIGINT) at step 12; rerun the same command to resume``. ``deferred()`` is a block a
signal does not split (the staged files' move into ``--out``): a signal received inside it is
raised at its end. Exit codes: 128 + the signal's number (130 SIGINT, 143 SIGTERM).

``casadi_line_absorbed()``: CasADi reports the exception it turned into a status with a line of its
own on ``sys.stderr`` (``CasADi - <date> WARNING("KeyboardInterruptException") [.../ipopt_nlp.cpp:132]``,
written in pieces); inside this block, once a signal was received, that line is dropped, so the
user sees only the run's own one line. Every other write passes at once (progress bars included).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading

SIGNALS = (signal.SIGINT, signal.SIGTERM)
_state = {"signum": None, "where": "at start-up", "resume": False, "defer": 0, "pending": None}


class Interrupted(KeyboardInterrupt):
    """The run received ``signum`` (SIGINT or SIGTERM); ``exit_code`` is 128 + signum."""

    def __init__(self, signum: int):
        self.signum = int(signum)
        super().__init__(signal.Signals(self.signum).name)

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


def _handler(signum, frame):
    _state["signum"] = signum
    if _state["defer"]:
        _state["pending"] = signum
        return
    raise Interrupted(signum)


def reset() -> None:
    _state.update(signum=None, where="at start-up", resume=False, defer=0, pending=None)


@contextlib.contextmanager
def handled():
    """The block with SIGINT and SIGTERM raising ``Interrupted`` (module docstring); the previous
    handlers are restored after it. Outside the main thread (no handler can be set) a no-op."""
    reset()
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.getsignal(s) for s in SIGNALS}
    for s in SIGNALS:
        signal.signal(s, _handler)
    try:
        yield
    except Exception as exc:  # the handler's Interrupted raised inside a C extension's call comes back as
        # that extension's error (CasADi: a SystemError from DM.__array__, "returned a result with an
        # exception set"; a RuntimeError from Function::call naming KeyboardInterrupt; both seen in CI
        # runs): after a recorded signal, whatever is raised is the interrupt, not an error
        if _state["signum"] is None:
            raise
        raise Interrupted(_state["signum"]) from exc
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        # the record ends with the block: a later solve in this process (an API call after an
        # interrupted cli.main) is not taken for interrupted; ``where`` stays for the message
        _state.update(signum=None, pending=None, defer=0)


def received() -> int | None:
    """The signal received since ``handled()`` began (None: none)."""
    return _state["signum"]


def check() -> None:
    """Raise ``Interrupted`` when a signal was received (and swallowed by a C extension)."""
    if _state["signum"] is not None and not _state["defer"]:
        raise Interrupted(_state["signum"])


def note(where: str, resume: bool | None = None) -> None:
    """Where the run is, for the message; ``resume``: the verb resumes from its files."""
    _state["where"] = where
    if resume is not None:
        _state["resume"] = resume


@contextlib.contextmanager
def deferred():
    """A block a signal does not interrupt; a signal received in it is raised at its end."""
    _state["defer"] += 1
    try:
        yield
    finally:
        _state["defer"] -= 1
        if not _state["defer"] and _state["pending"] is not None:
            signum, _state["pending"] = _state["pending"], None
            raise Interrupted(signum)


def message(signum: int) -> str:
    """The CLI's one line for an interrupt (module docstring)."""
    name = signal.Signals(signum).name
    tail = ("rerun the same command to resume" if _state["resume"] else
            "the files in --out were left as they were; rerun the same command to start again")
    return f"interrupted ({name}) {_state['where']}; {tail}"


class _CasadiLineFilter:
    """``sys.stderr`` less CasADi's line for an interrupt (``casadi_line_absorbed``)."""

    PREFIX = "CasADi - "  # CasADi's messages begin with it, written as a piece of its own
    MARK = "KeyboardInterruptException"

    def __init__(self, stream):
        self._stream = stream
        self._held = None  # a CasADi message being written, until its newline

    def write(self, text: str) -> int:
        if self._held is None and not text.startswith(self.PREFIX):
            return self._stream.write(text)
        self._held = (self._held or "") + text
        if "\n" in self._held:
            line, _, rest = self._held.partition("\n")
            self._held = None
            if not (self.MARK in line and _state["signum"] is not None):
                self._stream.write(line + "\n")
            if rest:
                self.write(rest)
        return len(text)

    def release(self) -> None:
        """Write what is held (a CasADi message without its newline yet)."""
        if self._held:
            self._stream.write(self._held)
        self._held = None

    def __getattr__(self, name):  # flush, isatty, fileno, encoding, ...: the stream's own
        return getattr(self._stream, name)


@contextlib.contextmanager
def casadi_line_absorbed():
    """The block with ``sys.stderr`` filtered (module docstring); restored after it."""
    stream = sys.stderr
    sys.stderr = filtered = _CasadiLineFilter(stream)
    try:
        yield
    finally:
        filtered.release()
        if sys.stderr is filtered:  # a block that swapped stderr itself keeps its own swap
            sys.stderr = stream
