"""The verbs of the command line (``vesicle_opt.cli``): ``cmd_solve``, ``cmd_study``, ``cmd_flow``
and ``cmd_branch``, each given the parsed arguments and returning the exit code (0 converged, 1 not
converged, results still written); bad input raises InputError before any work (``_preflight``:
the memory estimate, then ``--out`` and its lock). The final result line goes to stdout, warnings
(a saddle, a marginal second order, a wrapping inside, a kept run) to stderr.
"""

from __future__ import annotations

import sys
from pathlib import Path

from vesicle_opt import resources
from vesicle_opt.api import solve
from vesicle_opt.backends import choose_backend
from vesicle_opt.branch import branch as follow_branch
from vesicle_opt.branch.lines import check_line, sweep
from vesicle_opt.branch.reference import reference as sharp_reference
from vesicle_opt.errors import InputError
from vesicle_opt.io import interrupt, outdir, output, staging
from vesicle_opt.scene import load as load_scene
from vesicle_opt.scene import bundled, resolved
from vesicle_opt.studies import DESCRIPTIONS, STUDIES, check_workers, run_study, study


def out_dir(arg: str) -> Path:
    """The output directory, created and probed now (``io.outdir.check``): a one-line InputError
    (``--out``) before any work when it cannot be used (a file, below a file, not writable)."""
    return outdir.check(arg)


def _preflight(scene, out: str | None, path: str | None):
    """Everything checked before any work: the scene's memory estimate on ``path`` (a backend or
    "flow"; ``resources``), then ``--out`` (``io.outdir``); returns the context that holds the
    directory's lock for the run (a second run into it is refused with one line)."""
    if scene is not None and path is not None:
        resources.check(scene, path)
    return outdir.locked(out_dir(out))


def cmd_solve(args) -> int:
    if args.list:  # the bundled scenes, one line each (the first line of each file's comment)
        print("\n".join(bundled.describe()))
        return 0
    if args.scene is None:
        raise InputError("scene", "give a scene (a TOML path or a bundled name) or --list")
    sc = load_scene(args.scene, args.set)
    with _preflight(sc, args.out, choose_backend(sc)) as out:
        interrupt.note("during the solve", resume=False)
        result = solve(sc)
        interrupt.check()  # a signal a C extension swallowed: the result is not written

        def write(d: Path) -> dict:
            summary = output.write_result(d, sc, result.disc, result)
            resolved.write(d / "scene.resolved.toml", sc)  # the run, repeatable: vesicle-opt solve DIR/scene.resolved.toml
            return summary
        summary, where = staging.write_run(out, write, lambda s: result.converged, sc.name)
    print(f"{sc.name}: {result.status}, converged={result.converged}, energy={result.energy:.10g}, "
          f"iterations={result.iterations}, wall={result.wall_time_s:.2f}s -> {where}/summary.json")
    _kept(where, out)
    if result.converged and summary.get("second_order") == "saddle":
        # the reason names the negative direction: the least eigenvalue, or an excluded mode's
        # Rayleigh quotient (then the least eigenvalue on the rest of T may be positive)
        why = summary.get("second_order_reason") or "a negative tangent direction"
        if not why.startswith("least eigenvalue"):
            why += f"; least eigenvalue on the rest {summary['second_order_min_eigenvalue']:.3g} mu_ref"
        # a meridian mesh whose least mode is the axial slide (verdict.axial_note): no other shape helps
        advice = ("the vesicle slides along the axis, its shape is not unstable; mesh.refine = 'interface' pins "
                  "the slide" if "axial slide" in why else "try another initial shape")
        print(f"vesicle-opt: warning: the KKT point is a saddle, not a minimiser ({why}, "
              f"{summary.get('second_order_excluded', 'none')} excluded); {advice}",
              file=sys.stderr)
    if result.converged and summary.get("second_order") == "marginal":
        print(f"vesicle-opt: warning: second order marginal, not a strict minimum: "
              f"{summary.get('second_order_reason', '')} (rotation_rayleigh "
              f"{summary.get('rotation_rayleigh', float('nan')):.3g}); a flat direction such as a "
              f"nearly free rotation in the periodic box", file=sys.stderr)
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


def _kept(where: Path, out: Path) -> None:
    """The warning of a failed run whose files stayed in the staging directory (``io.staging``)."""
    if Path(where) != Path(out):
        print(f"vesicle-opt: warning: this run failed and {out} holds a good run, which was kept; "
              f"this run's files are in {where}", file=sys.stderr)


def cmd_study(args) -> int:
    if args.list:
        width = max(map(len, STUDIES))
        print("\n".join(f"{name:<{width}}  {DESCRIPTIONS[name]}" for name in STUDIES))
        return 0
    if args.name is None:
        raise InputError("study", f"give a study name or --list; one of {', '.join(STUDIES)}")
    study(args.name)  # an unknown name is refused before the directory is made
    if args.out is None:  # the README's contract: a study writes many files, so it names its directory
        raise InputError("--out", "a study needs --out DIR (the directory for its CSV and figures)")
    workers = None
    if args.workers is not None:  # the flag's text: one line naming --workers, before any work
        try:
            workers = int(args.workers)
        except ValueError:
            raise InputError("--workers", f"allowed: an integer >= 1 (local worker processes), got {args.workers!r}") from None
        check_workers(args.name, workers, "--workers")
    if args.scheduler is not None and args.workers is not None:
        raise InputError("--scheduler", "give --workers (local processes) or --scheduler (a dask cluster), not both")
    with _preflight(None, args.out, None) as out:
        try:
            return run_study(args.name, out, quick=args.quick, workers=workers, scheduler=args.scheduler)
        except InputError as exc:  # the API's keys as the flags that set them
            if exc.key in ("scheduler", "workers"):
                raise InputError(f"--{exc.key}", str(exc)[len(exc.key) + 2:]) from None
            raise


def cmd_flow(args) -> int:
    # the flows package with the flow verb only: the solve verb does not need it (start-up, 0.02 s)
    from vesicle_opt.flows.api import check_supported as check_flow_supported
    from vesicle_opt.flows.run import write_flow  # the same reason: the flow verb only
    overrides = list(args.set)
    for key, value in (("flow.scheme", args.scheme), ("flow.dt", args.dt), ("flow.steps", args.steps),
                       ("flow.t_end", args.t_end)):
        if value is not None:
            overrides.append(f"{key}={value!r}" if isinstance(value, str) else f"{key}={value}")
    if args.adaptive:
        overrides.append('flow.stepping="adaptive"')
    sc = load_scene(args.scene, overrides)
    check_flow_supported(sc)  # the flows' own refusals, before the directory is touched
    with _preflight(sc, args.out, "flow") as out:  # write_flow warns on eps / h after its own refusals
        run = write_flow(sc, out, restart=args.restart, progress=not getattr(args, "quiet", False))
    s = run.summary
    print(f"{sc.name} {s['scheme']}: {s['status']} after {s['steps']} steps, t = {s['t']:.6g}, "
          f"energy = {s['energy']:.10g}, rejections = {s['rejections']}, wall = {s['wall_time_s']:.2f}s "
          f"-> {run.where}/history.csv")
    _kept(run.where, out)
    if s["status"] == "failed":
        print(f"vesicle-opt: flow failed: {s['message']}", file=sys.stderr)
        return 1
    return 0


def cmd_branch(args) -> int:
    """``vesicle-opt branch SCENE --param reduced_volume|c0 --to VALUE [--step DS] [--out DIR]``:
    one line per point on stderr, branch.csv and the snapshots in --out (resumed after a kill)."""
    for flag, v in (("--depth", args.depth), ("--deflate", args.deflate)):  # before any work
        if v < 0:
            raise InputError(flag, f"allowed range: an integer >= 0, got {v!r}")
    if args.fold_line and args.transition is not None:
        raise InputError("--fold-line", "not with --transition (a crossing line, not a fold line)")
    if args.transition is not None:
        return _transition(args)
    if args.fold_line and args.second is None:
        raise InputError("--second", "missing: --fold-line needs the second parameter its fold is continued in")
    check_line(args.param, args.second, args.values)
    sc = load_scene(args.scene, args.set)
    if args.fold_line:
        from vesicle_opt.branch import ordinary_fold_vesicle  # the line's module only
        ordinary_fold_vesicle.check_kind(sc, args.param, args.second, args.fold_kind)
    sharp = None if args.sharp is None else sharp_reference(args.sharp, sc, args.param)  # checked first

    def show(row):
        why = "" if row["converged"] or not row.get("reason") else f" ({row['reason']})"  # the outcome's line
        print(f"point {row['point']} [{row['branch']}] {row['param']} = {row['target']:.6g}: "
              f"converged={row['converged']}, outcome={row.get('outcome')}{why}, reduced_energy="
              f"{row.get('reduced_energy')}, {row.get('second_order')}, iterations={row['iterations']}",
              file=sys.stderr)
    if args.fold_line:
        return _fold_line(args, sc, show)
    if args.second is not None:
        with _preflight(sc, args.out, choose_backend(sc)) as out:
            line = sweep(sc, args.param, args.to, args.step, args.second, args.values, out, progress=show,
                         switch=args.switch, depth=args.depth, deflate=args.deflate)
        for r in line:
            print(f"fold at {r['second']} = {r['value']:.6g}: {r['param']} = {r['target']:.8g}, "
                  f"reduced_energy = {r['reduced_energy']}, located by {r['located_by']}")
        print(f"{sc.name}: {len(line)} folds over {len(args.values)} values of {args.second} -> {args.out}/fold_line.csv")
        return 0
    with _preflight(sc, args.out, choose_backend(sc)) as out:  # memory, --out and its lock first
        b = follow_branch(sc, args.param, args.to, args.step, out, progress=show, switch=args.switch,
                          depth=args.depth, deflate=args.deflate, reference=sharp)
    pts = b.points()
    # "all certified" only of a run that has certified points (before: "0 points, ..., all certified=True")
    verdict = (f"all certified={all(r['converged'] for r in pts)}" if pts else
               "no certified point" + "".join(f"; last failure: {r.get('outcome')} ({r.get('reason')})"
                                              for r in b.rows[-1:] if not r["converged"]))
    print(f"{sc.name}: {len(pts)} points, stopped {b.stopped}, {verdict} -> {args.out}/branch.csv")
    return 0 if b.converged else 1


def _fold_line(args, sc, show) -> int:
    """``branch ... --fold-line --second Q --values ... [--fold-kind auto|symmetric|ordinary]``: the
    branch walked once (no switch), its first located fold continued in Q, a symmetric turn in its
    symmetric subspace or an ordinary fold by its index change (``branch.ordinary_fold_vesicle.from_branch``)."""
    from vesicle_opt.branch import ordinary_fold_vesicle  # the line's module only, as cmd_branch's check
    with _preflight(sc, args.out, choose_backend(sc)) as out:
        b = follow_branch(sc, args.param, args.to, args.step, out, progress=show, switch=False)

        def turn(t):
            how = f"{args.param} = {t.p:.8g}, eigenvalue {t.eigenvalue:.3g} (bound {t.error:.3g})" \
                if t.converged else f"not found ({t.reason})"
            print(f"{t.kind} fold at {args.second} = {t.q:.6g}: {how}, {t.solves} solves, {t.wall:.1f} s",
                  file=sys.stderr)
        turns = ordinary_fold_vesicle.from_branch(b, args.second, args.values, kind=args.fold_kind, progress=turn)
    if not turns:
        print(f"{sc.name}: no fold located on the branch in {args.param} -> {args.out}/branch.csv")
        return 1
    ok = sum(t.converged for t in turns)
    print(f"{sc.name}: {ok} of {len(turns)} folds over {args.second} -> {args.out}/fold_line.csv")
    return 0 if ok == len(turns) else 1


def _line_states(r: dict) -> str:
    """The crossing's states and verdicts for its progress line (meridian meshes: ``states``)."""
    so = f", second_order={r.get('a_second_order')}/{r.get('b_second_order')}" if r["converged"] else ""
    return so + (f", states={r['states']}" if r.get("states") else "")


def _transition(args) -> int:
    """``vesicle-opt branch SCENE --param reduced_volume --to V --step DV --transition KEY=VALUE
    --second c0 --values Q1,...``: the transition line (``branch.transition_vesicle``), one line per
    crossing on stderr, transition_line.csv in --out (resumed after a kill)."""
    from vesicle_opt.branch.transition_vesicle import check, transition_line  # the line's modules only
    if args.second is None:  # before any scene is read
        raise InputError("--second", "missing: --transition needs the second parameter (c0) of its line")
    a = load_scene(args.scene, args.set)
    b = load_scene(args.scene, list(args.set) + list(args.transition))
    check(a, b, args.param, args.second, args.values, args.to, args.step)

    def show(r):
        why = "" if r["converged"] else f" ({r.get('outcome')}: {r.get('reason')})"
        print(f"crossing {r['row']} [{r['direction']}] {r['second']} = {r['value']:.6g}: converged={r['converged']}"
              f"{why}, reduced_volume={r.get('target')}, f={r.get('f')}, gap={r.get('gap')}, solves={r['solves']}"
              f"{_line_states(r)}", file=sys.stderr)
    with _preflight(a, args.out, choose_backend(a)) as out:
        line = transition_line(a, b, args.second, args.values, step=args.step, to=args.to, out=out, progress=show)
    pts = line.points()
    saddles = sum(1 for r in pts if "saddle" in (r.get("a_second_order"), r.get("b_second_order")))
    other = sum(1 for r in pts if r.get("states") not in (None, "prolate/oblate"))
    notes = (f" ({saddles} with a saddle" if saddles else "") + (
        f"{'; ' if saddles else ' ('}{other} not between the symmetric prolate and oblate: see states" if other else "")
    print(f"{a.name}: {len(pts)} certified crossings of {len(line.rows)} over {args.second} = "
          f"{', '.join(f'{v:g}' for v in args.values)}{notes}{')' if notes else ''} -> {args.out}/transition_line.csv")
    return 0 if line.converged and len(line.rows) == len(set(args.values) - {a.model.c0}) + 1 else 1
