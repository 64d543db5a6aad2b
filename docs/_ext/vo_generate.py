"""Sphinx extension: the tables of the site that the code holds, written into docs/_generated/ at
build time so that they cannot drift from it.

* ``scene_keys.md``: every scene key of ``vesicle_opt.scene.schema.SCHEMA`` (kind, default, allowed)
  and the shape keys of ``scene.shape_spec``;
* ``npz_keys.md``: the npz layout of ``vesicle_opt.io.fields.KEYS`` and its format version;
* ``branch_columns.md`` / ``flow_columns.md``: ``branch.store.COLUMNS``, ``flows.run.COLUMNS`` (+ extras);
* ``solve_files.md`` / ``flow_files.md``: the files and summary.json keys of a real run of each verb
  (ellipse-2d at 24^2, about a second), with the value each took;
* ``studies.md``: the study registry with its one-line descriptions;
* ``study_columns.md``: the columns of every study CSV (``studies.runner``'s ``COLUMNS``, ``BOOKKEEPING``,
  ``FAILURE``) and, per registered study, the ``extra_columns`` it passes to the runner, read from the
  module's source and data (``study_extra_columns``; no study is run);
* ``bundled_scenes.md``: the bundled scenes with the first line of each file;
* ``cli_help.md``: ``vesicle-opt --help`` and every verb's, as argparse prints them;
* ``results_<study>.md``: each benchmark CSV committed under ``docs/results/`` as a table of the
  columns ``RESULT_TABLES`` names for it (a CSV without an entry, or a named column the CSV lacks,
  stops the build), so the benchmarks page cannot drift from the CSVs.

Docstrings are shown as written (plain text with the paper's equation numbers, not reStructuredText):
``autodoc-process-docstring`` turns each into a literal block.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path


def _table(header: list[str], rows: list[list[str]]) -> str:
    def cell(v) -> str:
        return str(v).replace("|", "\\|").replace("\n", " ")
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(cell(v) for v in r) + " |" for r in rows]
    return "\n".join(out) + "\n"


def _code(v) -> str:
    return f"`{v}`" if v not in (None, "") else ""


def scene_keys() -> str:
    from vesicle_opt.scene.schema import SCHEMA, _REQ
    from vesicle_opt.scene.shape_spec import SHAPE_KEYS, SHAPES
    rows = []
    for key, (kind, default, allowed) in SCHEMA.items():
        d = "required" if default is _REQ else _code(json.dumps(default)) if default is not None else "unset"
        a = ", ".join(f"`{x}`" for x in allowed) if isinstance(allowed, tuple) else allowed
        rows.append([f"`{key}`", kind, d, a])
    text = _table(["key", "kind", "default", "allowed"], rows)
    text += ("\nShape tables (`initial`, `constraints.target`) take `shape`, one of "
             + ", ".join(f"`{s}`" for s in SHAPES) + ", and the keys " + ", ".join(f"`{k}`" for k in SHAPE_KEYS)
             + ".\n")
    return text


def npz_keys() -> str:
    from vesicle_opt.io import fields
    rows = [[f"`{k}`", when, what] for k, (when, what) in fields.KEYS.items()]
    return (f"Format version **{fields.FORMAT_VERSION}**; kinds: " + ", ".join(f"`{k}`" for k in fields.KINDS)
            + ".\n\n" + _table(["key", "in", "meaning"], rows))


def columns(cols) -> str:
    return ", ".join(f"`{c}`" for c in cols) + "\n"


def _files(out: Path) -> list[str]:
    return sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and not p.name.startswith("."))


def _summary_rows(summary: dict) -> list[list[str]]:
    def val(v):
        if isinstance(v, float):
            return f"{v:.6g}"
        return json.dumps(v)
    return [[f"`{k}`", type(v).__name__ if v is not None else "null", f"`{val(v)}`"] for k, v in summary.items()]


def runs() -> tuple[str, str]:
    from vesicle_opt import cli
    with tempfile.TemporaryDirectory() as tmp:
        s, f = Path(tmp) / "solve", Path(tmp) / "flow"
        assert cli.main(["solve", "ellipse-2d", "--set", "mesh.n=24", "--out", str(s), "-q"]) == 0
        assert cli.main(["flow", "ellipse-2d", "--steps", "2", "--set", "mesh.n=24", "--out", str(f), "-q"]) == 0
        out = []
        for d in (s, f):
            summary = json.loads((d / "summary.json").read_text())
            text = ("Files (`vesicle-opt " + ("solve" if d is s else "flow --steps 2") + " ellipse-2d --set mesh.n=24`): "
                    + ", ".join(f"`{x}`" for x in _files(d)) + ".\n\n`summary.json` keys, with the values of that run:\n\n"
                    + _table(["key", "type", "value (example)"], _summary_rows(summary)))
            out.append(text)
    return out[0], out[1]


def cli_help() -> str:
    """``vesicle-opt --help`` and each verb's ``--help``, as argparse prints them."""
    import os
    from vesicle_opt.cli import build_parser
    os.environ["COLUMNS"] = "100"  # argparse wraps at the terminal's width: the same text everywhere
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    parts = [("vesicle-opt --help", parser.format_help())]
    parts += [(f"vesicle-opt {verb} --help", p.format_help()) for verb, p in sub.choices.items()]
    return "".join(f"## `{cmd}`\n\n```text\n{text.rstrip()}\n```\n\n" for cmd, text in parts)


def studies() -> str:
    from vesicle_opt.studies import DESCRIPTIONS, STUDIES
    return _table(["study", "what it does"], [[f"`{n}`", DESCRIPTIONS[n]] for n in STUDIES])


_RUNNER_CALLS = ("run_cases", "run_into", "run_study")  # the runner's entry points that take extra_columns


def _column_expr(node, module):
    """The value of an ``extra_columns`` expression made of string lists, module-level names and ``+``;
    None for anything else (a call, a comprehension written at the call): nothing is executed."""
    import ast
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.List, ast.Tuple)):
        parts = [_column_expr(e, module) for e in node.elts]
        return None if any(p is None for p in parts) else [c for p in parts for c in p]
    if isinstance(node, ast.Name):
        value = getattr(module, node.id, None)
        ok = isinstance(value, (list, tuple)) and all(isinstance(c, str) for c in value)
        return list(value) if ok else None
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        left, right = _column_expr(node.left, module), _column_expr(node.right, module)
        return None if left is None or right is None else left + right
    return None


def study_extra_columns(name: str) -> list[str] | None:
    """The columns study ``name`` adds to the runner's, in the CSV's order: every ``extra_columns``
    its module passes to ``run_cases`` / ``run_into`` / ``run_study`` (keyword or position), found in
    its source and resolved against the imported module's data. None where a call's columns are
    built in a way this cannot read (or no call is found): the study's docstring says them."""
    import ast
    import importlib
    import inspect
    from vesicle_opt.studies import runner
    module = importlib.import_module(f"vesicle_opt.studies.{name}")  # a study's import runs no study
    found: list[list[str]] = []
    for node in ast.walk(ast.parse(inspect.getsource(module))):
        if not isinstance(node, ast.Call):
            continue
        fname = getattr(node.func, "id", getattr(node.func, "attr", None))
        if fname not in _RUNNER_CALLS:
            continue
        params = list(inspect.signature(getattr(runner, fname)).parameters)
        pos = params.index("extra_columns")
        expr = next((k.value for k in node.keywords if k.arg == "extra_columns"),
                    node.args[pos] if len(node.args) > pos else None)
        if any(isinstance(a, ast.Starred) for a in node.args) or any(k.arg is None for k in node.keywords):
            return None
        cols = [] if expr is None else _column_expr(expr, module)
        if cols is None:
            return None
        found.append(cols)
    if not found:
        return None
    out: list[str] = []
    for cols in found:  # the same CSV from two calls (a resumed pass): the union, first order kept
        out += [c for c in cols if c not in runner.COLUMNS and c not in out]
    return out


def study_columns() -> str:
    """The study CSVs' columns: the runner's, then each study's extras (``runner.CsvLog`` order)."""
    from vesicle_opt.studies import STUDIES, runner
    text = ("Every study CSV written through `vesicle_opt.studies.runner` (`<study>.csv` in its `--out`) has, "
            "in this order, the common columns\n\n" + columns(runner.COLUMNS)
            + "\nthen the study's own columns (below), then the bookkeeping columns\n\n" + columns(runner.BOOKKEEPING)
            + "\nand the failure columns (those a study does not already hold)\n\n" + columns(runner.FAILURE)
            + "\nA CSV written by an older version keeps its header; new columns are added at its end.\n\n")
    rows = []
    for name in STUDIES:
        extra = study_extra_columns(name)
        cell = ("see the study's docstring (`vesicle-opt study " + name + " --help`)" if extra is None
                else ", ".join(f"`{c}`" for c in extra) or "none")
        rows.append([f"`{name}`", cell])
    return text + _table(["study", "its own columns"], rows)


def bundled() -> str:
    from vesicle_opt.scene import bundled as b
    rows = []
    for name in b.names():
        head = []
        for ln in b.text(name).splitlines():
            if not ln.startswith("#"):
                break
            head.append(ln.lstrip("# ").strip())
        rows.append([f"`{name}`", " ".join(head)])
    return _table(["scene", "what it is (the file's opening comment)"], rows)


# study -> (column, header, format) shown on the benchmarks page; the CSV may hold more columns.
RESULT_TABLES = {
    "bench_equilibrium": [("case", "case", ""), ("n_nodes", "nodes", "d"), ("iterations", "iterations", "d"),
                          ("wall_time_s", "wall (s)", ".3g"), ("derivative_fraction", "derivative share", ".2f"),
                          ("hessian_nnz_per_row", "Hessian nnz/row", ".3g"), ("peak_memory_mb", "peak (MB)", ".0f"),
                          ("energy", "energy", ".10g"), ("status", "status", "")],
    "bench_stationarity": [("case", "case", ""), ("h", "h", ".3g"), ("converged", "converged", ""),
                           ("kkt_residual", "L2 residual", ".2e"), ("kkt_floor", "L2 floor", ".2e"),
                           ("kkt_dual", "natural residual", ".2e"), ("kkt_dual_floor", "natural floor", ".2e"),
                           ("certified_l2", "old rule", ""), ("newton", "Newton", "d"), ("wall_s", "wall (s)", ".3g")],
    "bench_overhead": [("case", "case", ""), ("method", "method", ""), ("mode", "mode", ""),
                       ("repeat", "repeat", ""), ("iterations", "iterations", ""),
                       ("wall_time_s", "wall (s)", ".3g"), ("ratio_to_bare", "ratio to bare", ".3f"),
                       ("derivative_fraction", "derivative share", ".3f"),
                       ("whole_process_s", "whole process (s)", ".3g"), ("solve_s", "solve (s)", ".3g"),
                       ("whole_over_solve", "whole / solve", ".2f"), ("load_average", "load", ".1f")],
    "bench_3d": [("case", "case", ""), ("n_nodes", "nodes", "d"), ("fft", "FFT", ""), ("newton", "Newton", "d"),
                 ("cg", "CG", "d"), ("solve_wall_s", "solve (s)", ".3g"), ("total_wall_median_s", "total, median (s)", ".3g"),
                 ("solve_over_fft_floor", "solve / FFT floor", ".2f"), ("peak_rss_mb", "peak RSS (MB)", ".0f"),
                 ("energy", "energy", ".10g"), ("converged", "converged", "")],
    "bench_certificate": [("case", "case", ""), ("solve_s", "solve (s)", ".3g"), ("certificate_s", "certificate (s)", ".3g"),
                          ("certificate_ratio", "ratio", ".2f"), ("bare_peak_mb", "bare peak (MB)", ".0f"),
                          ("certified_peak_mb", "certified peak (MB)", ".0f"), ("memory_ratio", "memory ratio", ".2f"),
                          ("verdict", "verdict", ""), ("min_eigenvalue", "least eigenvalue", ".7g"),
                          ("iterations", "iterations", ""), ("load_average", "load", ".1f")],
    "bench_jax": [("case", "case", ""), ("variant", "variant", ""), ("devices", "devices", "d"), ("newton", "Newton", "d"),
                  ("cg", "CG", "d"), ("total_wall_median_s", "wall, warm median (s)", ".3g"),
                  ("total_wall_cold_s", "cold (s)", ".3g"), ("ratio_to_numpy", "ratio to numpy", ".2f"),
                  ("peak_rss_mb", "peak RSS (MB)", ".0f"), ("energy_rel_to_numpy", "energy vs numpy", ".1e"),
                  ("load_1min", "load", ".1f"), ("status", "status", "")],
    "bench_methods": [("scene", "scene", ""), ("method", "method", ""), ("exit", "exit", ""),
                      ("outcome", "outcome", ""), ("repeats", "runs", "d"), ("wall_median", "wall, median (s)", ".3g"),
                      ("ratio_vs_exact", "× exact", ".2f"), ("compared", "energy compared", ""),
                      ("rel_diff_vs_exact", "rel. diff. to exact", ".1e"), ("same_point", "exact's point", ""),
                      ("load_runs", "load per run", "")],
    "bench_branch_3d": [("case", "case", ""), ("nodes", "nodes", "d"), ("point", "point", "d"),
                        ("target", "v", ".5f"), ("cpu_s", "CPU (s)", ".3g"), ("check_cpu_s", "check CPU (s)", ".3g"),
                        ("transforms", "DCTs", "d"), ("newton", "Newton", "d"), ("krylov", "GMRES", "d"),
                        ("second_order", "second order", ""), ("load_average", "load", ".1f")],
    "crossing_3d": [("case", "case", ""), ("epsilon", "ε", ".3g"), ("n", "grid", ""), ("start", "start", ""),
                    ("reduced_volume", "v", ".4f"), ("reduced_energy", "reduced energy", ".6f"),
                    ("sharp_reduced_energy", "sharp reference", ".6f"), ("iterations", "iterations", "d"),
                    ("wall_time_s", "wall (s)", ".3g"), ("second_order", "second order", ""),
                    ("converged", "converged", "")],
}


def _fmt(value: str, fmt: str) -> str:
    if value in ("", None) or not fmt:
        return value or ""
    try:
        x = float(value)
    except ValueError:
        return value
    return f"{int(round(x))}" if fmt == "d" else f"{x:{fmt}}"


def results_table(path: Path) -> str:
    """The columns ``RESULT_TABLES`` names for ``path``'s study, one row per CSV row."""
    import csv
    study = path.stem
    if study not in RESULT_TABLES:
        raise KeyError(f"docs/results/{path.name}: no entry in RESULT_TABLES (docs/_ext/vo_generate.py)")
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    spec = RESULT_TABLES[study]
    missing = [c for c, _, _ in spec if rows and c not in rows[0]]
    if missing:
        raise KeyError(f"docs/results/{path.name} lacks the columns {missing}")
    spec = [s for s in spec if any(r.get(s[0]) not in ("", None) for r in rows)]  # all-empty columns: left out
    body = [[_fmt(r[c], f) for c, _, f in spec] for r in rows]
    return (f"From `results/{path.name}` ({len(rows)} rows; `vesicle-opt study {study}` writes it):\n\n"
            + _table([h for _, h, _ in spec], body))


def generate(app) -> None:
    from vesicle_opt.branch.store import COLUMNS
    from vesicle_opt.flows.run import COLUMNS as FLOW, EXTRA
    gen = Path(app.srcdir) / "_generated"
    gen.mkdir(exist_ok=True)
    solve_files, flow_files = runs()
    pages = {"scene_keys.md": scene_keys(), "npz_keys.md": npz_keys(), "branch_columns.md": columns(COLUMNS),
             "flow_columns.md": columns(FLOW) + "\nScheme extras: " + "; ".join(
                 f"`{k}`: " + (", ".join(f"`{c}`" for c in v) or "none") for k, v in EXTRA.items()) + ".\n",
             "solve_files.md": solve_files, "flow_files.md": flow_files, "studies.md": studies(),
             "study_columns.md": study_columns(),
             "bundled_scenes.md": bundled(), "cli_help.md": cli_help()}
    for path in sorted((Path(app.srcdir) / "results").glob("*.csv")):
        pages[f"results_{path.stem}.md"] = results_table(path)
    for name, text in pages.items():
        path = gen / name
        if not path.exists() or path.read_text() != text:  # unchanged files keep their time: no rebuild
            path.write_text(text)


class TourOrder:
    """The gallery's order: the tour's (getting started), simplest first; others after, by name."""

    ORDER = ("solve_and_read", "own_constraint", "penalty_vs_exact", "flow_with_tracker", "branch_2d",
             "torus_surface")

    def __init__(self, src_dir: str):
        self.src_dir = src_dir

    def __call__(self, filename: str):
        stem = Path(filename).stem
        return (self.ORDER.index(stem) if stem in self.ORDER else len(self.ORDER), stem)

    def __repr__(self) -> str:  # sphinx-gallery keys its cache on the repr
        return f"<{type(self).__name__}>"


def literal_docstring(app, what, name, obj, options, lines) -> None:
    """The project's docstrings are plain text (formulas with * and _, equation numbers): shown verbatim."""
    if not lines:
        return
    body = [("    " + ln) if ln.strip() else "" for ln in lines]
    lines[:] = ["::", ""] + body + [""]


def setup(app):
    app.connect("builder-inited", generate)
    app.connect("autodoc-process-docstring", literal_docstring)
    return {"parallel_read_safe": True, "version": "1"}
