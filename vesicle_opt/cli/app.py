"""The command line's parser, logging and ``main`` (exit codes, one-line errors); the verbs
themselves are ``cli.verbs``. Loaded by ``cli.run`` after the interrupt handling of the start-up
is in place (``cli`` package docstring)."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import warnings
from pathlib import Path

from vesicle_opt.cli.verbs import cmd_branch, cmd_flow, cmd_solve, cmd_study, out_dir  # noqa: F401 (out_dir: re-exported)
from vesicle_opt.errors import InputError, VesicleError
from vesicle_opt.io import interrupt, progress
from vesicle_opt.io.files import package_version
from vesicle_opt.studies import DESCRIPTIONS, STUDIES, docstring

DESCRIPTION = ("Equilibrium shapes of vesicle membranes with the phase-field bending model, computed as "
               "constrained minimisation (CasADi + IPOPT, or matrix-free Newton-Krylov), gradient flows "
               "of the model, and the studies that check the paper's convergence theory.")
EPILOG = """examples:
  vesicle-opt solve ellipse-2d --out out/ellipse            # a bundled scene (or a TOML path)
  vesicle-opt solve torus-table1-3d --set mesh.n=32 -v      # with the solver's iteration log
  vesicle-opt flow ellipse-2d --steps 20 --out out/flow     # a gradient flow, ParaView series phi.pvd
  vesicle-opt study --list                                  # the studies, one line each
  vesicle-opt study table1 --help                           # what one study does

exit codes: 0 converged, 1 not converged (results still written), 2 bad input.
Run 'vesicle-opt VERB --help' for the options of a verb."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2
        print(f"vesicle-opt: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def _flow_parser(sub) -> None:
    f = sub.add_parser("flow", help="run a gradient flow (17), (18) or (23) of a scene")
    f.add_argument("scene", help="scene TOML file or bundled scene name")
    f.add_argument("--scheme", choices=("penalty", "lagrange", "backward-euler"),
                   help="time scheme (default: the scene's flow.scheme)")
    f.add_argument("--dt", type=float, help="time step k (initial k with --adaptive)")
    f.add_argument("--steps", type=int, help="at most this many accepted steps")
    f.add_argument("--t-end", type=float, help="final time T")
    f.add_argument("--adaptive", action="store_true", help="adaptive k with rejection")
    f.add_argument("--out", default="out", help="output directory (default: out)")
    f.add_argument("--restart", action="store_true", help="ignore a checkpoint in --out")
    f.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="no progress bar; only warnings and errors")
    f.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key (dotted, value parsed as TOML); repeatable")
    _add_verbose(f)
    f.set_defaults(func=cmd_flow)


class _StudyHelp(argparse.Action):
    """``study --help`` with the study list; ``study NAME --help`` adds that study's own description."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        parser.print_help()
        name = getattr(namespace, "name", None)
        if name is not None:
            try:
                text = docstring(name)
            except InputError as exc:
                print(f"\nvesicle-opt: error: {exc}", file=sys.stderr)
                parser.exit(2)
            print(f"\nstudy {name}:\n{text}")
        parser.exit()


def _add_verbose(p) -> None:
    """-v (repeatable), default SUPPRESS so that a verb's parser does not reset the main parser's."""
    p.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                   help="also the solvers' iteration logs (IPOPT's own, Newton steps, flow steps)")


def _add_verbosity(p) -> None:
    _add_verbose(p)
    p.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="only warnings and errors (no progress bars)")


class _Handler(logging.Handler):
    """stderr as it is when a record is emitted (tests swap it); through tqdm on a terminal, so a
    progress bar is not torn by a log line."""

    def emit(self, record):
        try:
            text = self.format(record)
            if sys.stderr.isatty():
                from tqdm import tqdm  # only on a terminal, where bars are drawn
                tqdm.write(text, file=sys.stderr)
            else:
                sys.stderr.write(text + "\n")
                sys.stderr.flush()
        except Exception:  # noqa: BLE001 - logging must never end the run (logging.Handler's own rule)
            self.handleError(record)


class _Format(logging.Formatter):
    def format(self, record):
        msg = record.getMessage()
        if record.levelno >= logging.WARNING:
            return f"vesicle-opt: {record.levelname.lower()}: {msg}"
        return msg if record.levelno >= logging.INFO else f"[{record.name.removeprefix('vesicle_opt.')}] {msg}"


def setup_logging(verbose: int = 0, quiet: bool = False) -> logging.Handler:
    """The CLI's logging: the ``vesicle_opt`` logger at WARNING (quiet), INFO or DEBUG (verbose) to
    stderr, and progress bars on unless quiet. Returns the handler (``main`` removes it again)."""
    logger = logging.getLogger("vesicle_opt")
    handler = _Handler()
    handler.setFormatter(_Format())
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO)
    progress.enable(not quiet)
    progress.silence(quiet)  # -q: no bar, the forced ones (a study's cases) included
    return handler


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="vesicle-opt", description=DESCRIPTION, epilog=EPILOG,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"vesicle-opt {package_version()}")
    _add_verbosity(p)
    sub = p.add_subparsers(dest="verb", required=True, parser_class=_Parser, metavar="{solve,flow,branch,study}")
    s = sub.add_parser("solve", help="solve the equilibrium problem of a scene")
    s.add_argument("scene", nargs="?", help="scene TOML file or bundled scene name (see --list)")
    s.add_argument("--list", action="store_true", help="print the bundled scenes, one line each")
    s.add_argument("--out", default="out", help="output directory (default: out)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key (dotted, value parsed as TOML); repeatable")
    _add_verbosity(s)
    s.set_defaults(func=cmd_solve)
    st = sub.add_parser("study", help="run a study from studies/ writing CSV and figures", add_help=False,
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="studies:\n" + "\n".join(f"  {n:<22} {DESCRIPTIONS[n]}" for n in STUDIES))
    st.add_argument("-h", "--help", action=_StudyHelp, help="this help; with NAME, also that study's description")
    st.add_argument("name", nargs="?", help="the study (- or _ alike); see --list")
    st.add_argument("--list", action="store_true", help="print the study names, one per line")
    st.add_argument("--out", default=None, help="output directory (required with a study name)")
    st.add_argument("--quick", action="store_true", help="small, fast variant")
    st.add_argument("--workers", default=None, metavar="N",
                    help="local worker processes for the study's independent cases (default 1; studies that run cases in parallel)")
    st.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="run the cases on the dask cluster of this scheduler (e.g. tcp://host:8786; the 'dask' extra)")
    _add_verbosity(st)
    st.set_defaults(func=cmd_study)
    _flow_parser(sub)
    b = sub.add_parser("branch", help="follow a branch of equilibria in reduced_volume or c0")
    b.add_argument("scene", help="scene TOML file or bundled scene name")
    b.add_argument("--param", required=True, help="reduced_volume or c0")
    b.add_argument("--to", required=True, type=float, help="end value (reduced_volume in (0, 1])")
    b.add_argument("--step", type=float, help="first parameter step, signed towards --to (default: range/25)")
    b.add_argument("--out", default="out", help="output directory, resumed when it holds the same run")
    b.add_argument("--sharp", nargs="?", const="auto", choices=("auto", "elastica", "prolate", "oblate"),
                   help="fill sharp_reduced_energy with the eps -> 0 reference (alone: auto, from the scene)")
    b.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key (dotted, value parsed as TOML); repeatable")
    b.add_argument("--switch", action=argparse.BooleanOptionalAction, default=True,
                   help="follow the branches leaving each located branch point (default: on)")
    b.add_argument("--depth", type=int, default=1,
                   help="levels of branches switched to, recursively (default 1; 0: the first branch only)")
    b.add_argument("--deflate", type=int, default=0,
                   help="where switching finds no branch, seek up to N other points at the start by deflation")
    b.add_argument("--second", default=None,
                   help="a second parameter (reduced_volume or c0): one diagram per --values, and their folds "
                        "as a line in fold_line.csv")
    b.add_argument("--values", type=lambda t: [float(x) for x in t.split(",") if x.strip()], default=None,
                   metavar="Q1,Q2,...", help="the values of --second (comma-separated)")
    b.add_argument("--fold-line", action="store_true",
                   help="with --second reduced_volume|c0 --values: walk the branch once, then continue its first "
                        "located fold (a symmetric turn of a periodic 2D grid) in --second, in its symmetric "
                        "subspace (branch.symmetric_fold; fold_line.csv)")
    b.add_argument("--fold-kind", choices=("auto", "symmetric", "ordinary"), default="auto",
                   help="with --fold-line: the fold's kind; symmetric: a symmetric turn (above); ordinary: a "
                        "fold where one eigenvalue crosses zero while others stay negative, continued by its "
                        "index change with p free (branch.ordinary_fold); auto (default): ordinary where the "
                        "walk located the fold on the chord, symmetric where it saw a turn with no index change")
    b.add_argument("--transition", action="append", default=None, metavar="KEY=VALUE",
                   help="the other branch: the scene with these overrides too (e.g. initial.semi_axes=[1.3,1.3,0.5]); "
                        "with --second c0 --values, the energy crossing of the two branches in reduced_volume, "
                        "searched from the scene's towards --to in samples |--step| apart and continued to each "
                        "value (transition_line.csv, phase_diagram.png); repeatable")
    _add_verbosity(b)
    b.set_defaults(func=cmd_branch)
    return p


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except BrokenPipeError:  # --help piped into a reader that closed early (`| head`): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0

    def one_line_warning(message, category, filename, lineno, file=None, line=None):
        # the tool's own warnings as its own; a library's named as that library's (matplotlib, ...)
        ours = Path(filename).resolve().is_relative_to(Path(__file__).resolve().parents[1])  # vesicle_opt/
        parts = Path(filename).parts
        site = [i for i, p in enumerate(parts) if p in ("site-packages", "dist-packages")]
        who = "vesicle-opt" if ours else parts[site[-1] + 1] if site and site[-1] + 1 < len(parts) - 1 else \
            Path(filename).stem
        print(f"{who}: {'warning' if ours else category.__name__}: {message}", file=sys.stderr)

    warnings.showwarning = one_line_warning
    handler = setup_logging(getattr(args, "verbose", 0), getattr(args, "quiet", False))
    try:
        # SIGINT / SIGTERM: one line, exit 130 / 143, and not CasADi's own line besides (io.interrupt)
        with interrupt.handled(), interrupt.casadi_line_absorbed():
            code = args.func(args)
            interrupt.check()
        sys.stdout.flush()  # a closed pipe shows here, inside the handler, not at interpreter exit
        return code
    except VesicleError as exc:
        print(f"vesicle-opt: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt as exc:  # io.interrupt.Interrupted, or a bare one (before the handlers)
        signum = getattr(exc, "signum", signal.SIGINT)
        print(f"vesicle-opt: {interrupt.message(signum)}", file=sys.stderr)
        return 128 + signum
    except BrokenPipeError:  # stdout piped into a reader that closed early (`| head`): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0
    except OSError as exc:  # the disk failed during the run (what is checked before work is exit 2 above)
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"vesicle-opt: error: cannot write{where}: {exc.strerror or exc}; the run stopped there "
              f"(a flow or branch resumes from its files, a study from its CSV)", file=sys.stderr)
        return 1
    finally:  # main() called in-process (tests, scripts) leaves no handler, level or bar switched on
        logging.getLogger("vesicle_opt").removeHandler(handler)
        logging.getLogger("vesicle_opt").setLevel(logging.NOTSET)
        progress.enable(False)
        progress.silence(False)


def finish(code: int) -> None:
    """End the ``vesicle-opt`` process with ``code`` (``cli.run``): the streams and the log flushed,
    then ``os._exit``. Every file a verb writes is closed and every thread and worker process it
    started is joined before ``main`` returns; what the interpreter's own teardown would add is
    freeing the modules and arrays, 0.2-0.45 s after a 64^3 solve (measured), which nothing needs."""
    try:
        sys.stdout.flush()
    except BrokenPipeError:  # a reader that closed early: not an error (as in ``main``)
        pass
    sys.stderr.flush()
    logging.shutdown()
    os._exit(code)
