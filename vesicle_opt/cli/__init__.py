"""Command line: ``vesicle-opt solve SCENE [--out DIR] [--set KEY=VALUE ...]`` (SCENE: a TOML path
or a bundled name), ``vesicle-opt flow SCENE --scheme ... [--out DIR]`` (a gradient flow) and
``vesicle-opt study NAME --out DIR [--quick] [--workers N | --scheduler ADDRESS]`` (``vesicle-opt study --list``: the names) and
``vesicle-opt branch SCENE --param reduced_volume|c0 --to VALUE [--step DS] [--out DIR]``.

Exit codes: 0 converged; 1 the solver did not converge (results still written); 2 bad input
(one line naming the key and the allowed range, no traceback); 130 / 143 interrupted by SIGINT /
SIGTERM (one line saying where, ``io.interrupt``; ``solve`` and ``flow`` stage their files and move
them into --out only when the run has ended, ``io.staging``).

Output: the final result line of a verb on stdout; everything else through ``logging`` on stderr
(``setup_logging``): INFO by default (which backend and why, the phases of a solve, study lines,
progress bars with an ETA: tqdm on a terminal, plain lines in a log), ``-q`` only warnings and
errors, ``-v`` also the solvers' iteration logs (IPOPT's own, one line per Newton step, one per
flow step). ``-v``/``-q`` are accepted before or after the verb.

Start-up: ``run`` (the ``vesicle-opt`` command) sets SIGINT and SIGTERM to end the process with the
same one line (``interrupted (SIGINT) at start-up; ...``, exit 130 / 143) *before* it imports the
parser and the verbs (numpy, scipy, the solvers: 0.6 s), and this package and ``vesicle_opt`` itself
import nothing heavy, so no signal meets the default handler's KeyboardInterrupt traceback once
this module runs. Only the interpreter's own start (its ``site`` import: 0.03-0.05 s measured, most
of it an editable install's path finder) comes before it. ``main`` then installs the run's handlers
(``io.interrupt.handled``).

``cli.app`` holds the parser, the logging and ``main`` (exit codes, one-line errors); the verbs
themselves are ``cli.verbs`` (``cmd_solve``, ``cmd_study``, ``cmd_flow``, ``cmd_branch``). Their
public names (``main``, ``build_parser``, ``setup_logging``, ``DESCRIPTION``, ...) are read here
too, loaded with their first use (PEP 562).
"""

from __future__ import annotations

import os
import signal
import sys

from vesicle_opt.io import interrupt


def _at_start_up(signum, frame):
    """SIGINT / SIGTERM before ``main`` has its own handlers: the run's one line, its exit code."""
    try:
        sys.stderr.flush()
    except (OSError, RuntimeError, ValueError):  # a flush cut by this very signal: the line still goes
        pass
    os.write(2, f"vesicle-opt: {interrupt.message(signum)}\n".encode())
    os._exit(128 + signum)


def run() -> None:
    """The ``vesicle-opt`` command (and ``python -m vesicle_opt``): the start-up's interrupt handling,
    then ``app.main``, then the process ended at once (``app.finish``). ``main`` called in-process
    keeps the normal exit and installs no handler outside its run."""
    interrupt.reset()  # where = "at start-up"
    for s in interrupt.SIGNALS:
        signal.signal(s, _at_start_up)
    from vesicle_opt.cli import app  # after the handlers: the heavy imports (0.6 s) are interruptible
    code = app.main()
    for s in interrupt.SIGNALS:  # the run has ended and said so: a late signal changes nothing
        signal.signal(s, signal.SIG_IGN)
    app.finish(code)


def __getattr__(name: str):
    """``cli.main``, ``cli.build_parser``, ... from ``cli.app`` (loaded with the first such use)."""
    if name.startswith("__") or name in ("app", "verbs"):  # the import system asks for these before
        raise AttributeError(f"module 'vesicle_opt.cli' has no attribute {name!r}")  # loading them
    from vesicle_opt.cli import app  # the public names of the command line, lazily

    try:
        value = getattr(app, name)
    except AttributeError:
        raise AttributeError(f"module 'vesicle_opt.cli' has no attribute {name!r}") from None
    globals()[name] = value
    return value
