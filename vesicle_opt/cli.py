"""Command line: ``vesicle-opt solve SCENE [--out DIR] [--set KEY=VALUE ...]`` (SCENE: a TOML path
or a bundled name), ``vesicle-opt flow SCENE --scheme ... [--out DIR]`` (a gradient flow) and
``vesicle-opt study NAME --out DIR [--quick]`` (``vesicle-opt study --list``: the names) and
``vesicle-opt branch SCENE --param reduced_volume|c0 --to VALUE [--step DS] [--out DIR]``.

Exit codes: 0 converged; 1 the solver did not converge (results still written); 2 bad input
(one line naming the key and the allowed range, no traceback).
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

from vesicle_opt.api import solve
from vesicle_opt.branch import branch as follow_branch
from vesicle_opt.errors import InputError, VesicleError
from vesicle_opt.flows.run import write_flow
from vesicle_opt.io import output
from vesicle_opt.scene import load as load_scene
from vesicle_opt.studies import STUDIES, run_study, study


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2
        print(f"vesicle-opt: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def out_dir(arg: str) -> Path:
    """The output directory, created now: a one-line InputError (``--out``) before any work when it
    cannot be (a file of that name, no permission)."""
    path = Path(arg)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError("--out", f"cannot use {arg!r} as the output directory ({exc.strerror or exc})") from None
    return path


def cmd_solve(args) -> int:
    sc = load_scene(args.scene, args.set)
    out = out_dir(args.out)
    result = solve(sc)
    summary = output.write_result(out, sc, result.disc, result)
    print(f"{sc.name}: {result.status}, converged={result.converged}, energy={result.energy:.10g}, "
          f"iterations={result.iterations}, wall={result.wall_time_s:.2f}s -> {args.out}/summary.json")
    if result.converged and summary.get("second_order") == "saddle":
        print(f"vesicle-opt: warning: the KKT point is a saddle, not a minimiser (smallest tangent "
              f"Hessian eigenvalue {summary['second_order_min_eigenvalue']:.3g} mu_ref, mass metric, "
              f"{summary.get('second_order_excluded', 'none')} excluded); try another initial shape",
              file=sys.stderr)
    if summary.get("wraps"):
        print(f"vesicle-opt: warning: the inside {summary['topology']}: a slab or tube joined to its "
              f"periodic image, not a closed vesicle", file=sys.stderr)
    if not result.converged:
        reason = f" ({summary['reason']})" if summary.get("reason") else ""
        print(f"vesicle-opt: not converged{reason}: status {summary['status']}, kkt_residual "
              f"{summary['kkt_residual']}, volume_residual {summary['volume_residual']}, "
              f"area_residual {summary['area_residual']}", file=sys.stderr)
        return 1
    return 0


def cmd_study(args) -> int:
    if args.list:
        print("\n".join(STUDIES))
        return 0
    if args.name is None:
        raise InputError("study", f"give a study name or --list; one of {', '.join(STUDIES)}")
    study(args.name)  # an unknown name is refused before the directory is made
    return run_study(args.name, out_dir(args.out), quick=args.quick)


def cmd_flow(args) -> int:
    overrides = list(args.set)
    for key, value in (("flow.scheme", args.scheme), ("flow.dt", args.dt), ("flow.steps", args.steps),
                       ("flow.t_end", args.t_end)):
        if value is not None:
            overrides.append(f"{key}={value!r}" if isinstance(value, str) else f"{key}={value}")
    if args.adaptive:
        overrides.append('flow.stepping="adaptive"')
    sc = load_scene(args.scene, overrides)
    run = write_flow(sc, out_dir(args.out), restart=args.restart, progress=not args.quiet)
    s = run.summary
    print(f"{sc.name} {s['scheme']}: {s['status']} after {s['steps']} steps, t = {s['t']:.6g}, "
          f"energy = {s['energy']:.10g}, rejections = {s['rejections']}, wall = {s['wall_time_s']:.2f}s "
          f"-> {args.out}/history.csv")
    if s["status"] == "failed":
        print(f"vesicle-opt: flow failed: {s['message']}", file=sys.stderr)
        return 1
    return 0


def cmd_branch(args) -> int:
    """``vesicle-opt branch SCENE --param reduced_volume|c0 --to VALUE [--step DS] [--out DIR]``:
    one line per point on stderr, branch.csv and the snapshots in --out (resumed after a kill)."""
    sc = load_scene(args.scene, args.set)

    def show(row):
        print(f"point {row['point']} [{row['branch']}] {row['param']} = {row['target']:.6g}: "
              f"converged={row['converged']}, reduced_energy={row.get('reduced_energy')}, "
              f"{row.get('second_order')}, iterations={row['iterations']}", file=sys.stderr)
    b = follow_branch(sc, args.param, args.to, args.step, Path(args.out), progress=show)
    pts = b.points()
    print(f"{sc.name}: {len(pts)} points, stopped {b.stopped}, all certified="
          f"{all(r['converged'] for r in pts)} -> {args.out}/branch.csv")
    return 0 if b.converged else 1


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
    f.add_argument("--quiet", action="store_true", help="no progress line")
    f.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key (dotted, value parsed as TOML); repeatable")
    f.set_defaults(func=cmd_flow)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="vesicle-opt", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="verb", required=True, parser_class=_Parser)
    s = sub.add_parser("solve", help="solve the equilibrium problem of a scene")
    s.add_argument("scene", help="scene TOML file or bundled scene name")
    s.add_argument("--out", default="out", help="output directory (default: out)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key (dotted, value parsed as TOML); repeatable")
    s.set_defaults(func=cmd_solve)
    st = sub.add_parser("study", help="run a study from studies/ writing CSV and figures")
    st.add_argument("name", nargs="?", help="the study (- or _ alike); see --list")
    st.add_argument("--list", action="store_true", help="print the study names, one per line")
    st.add_argument("--out", default="out", help="output directory (default: out)")
    st.add_argument("--quick", action="store_true", help="small, fast variant")
    st.set_defaults(func=cmd_study)
    _flow_parser(sub)
    b = sub.add_parser("branch", help="follow a branch of equilibria in reduced_volume or c0")
    b.add_argument("scene", help="scene TOML file or bundled scene name")
    b.add_argument("--param", required=True, help="reduced_volume or c0")
    b.add_argument("--to", required=True, type=float, help="end value (reduced_volume in (0, 1])")
    b.add_argument("--step", type=float, help="first parameter step, signed towards --to (default: range/25)")
    b.add_argument("--out", default="out", help="output directory, resumed when it holds the same run")
    b.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key (dotted, value parsed as TOML); repeatable")
    b.set_defaults(func=cmd_branch)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)

    def one_line_warning(message, category, filename, lineno, file=None, line=None):
        print(f"vesicle-opt: warning: {message}", file=sys.stderr)

    warnings.showwarning = one_line_warning
    try:
        code = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, inside the handler, not at interpreter exit
        return code
    except VesicleError as exc:
        print(f"vesicle-opt: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:  # stdout piped into a reader that closed early (`| head`): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0


if __name__ == "__main__":
    sys.exit(main())
