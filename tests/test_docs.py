"""The documentation site's sources (the build itself runs in .ci/run with -W): every example is a
gallery page (an RST title in its docstring) and pinned by tests/test_examples.py, the quick ones
are executed by the gallery, and the user guide's toctree takes every docs/guide page."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))


def _conf() -> dict:
    tree = ast.parse((ROOT / "docs" / "conf.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "sphinx_gallery_conf":
            return ast.literal_eval(node.value)
    raise AssertionError("no sphinx_gallery_conf in docs/conf.py")


def test_every_example_is_a_titled_gallery_page_pinned_by_a_test():
    tests = (ROOT / "tests" / "test_examples.py").read_text()
    assert EXAMPLES
    for path in EXAMPLES:
        doc = ast.get_docstring(ast.parse(path.read_text()), clean=False).strip().splitlines()
        assert len(doc) >= 2 and set(doc[1]) == {"="} and len(doc[1]) == len(doc[0]), path.name  # RST title
        assert f'_load("{path.stem}")' in tests, f"{path.name} is not pinned by tests/test_examples.py"


def test_the_gallery_executes_the_quick_examples_only():
    pattern = re.compile(_conf()["filename_pattern"])
    executed = {p.stem for p in EXAMPLES if pattern.search("/" + p.name)}
    assert executed == {p.stem for p in EXAMPLES} - {"torus_surface"}  # the 3D torus: tens of seconds


def test_the_user_guide_globs_its_pages():
    index = (ROOT / "docs" / "index.md").read_text()
    assert ":glob:" in index and "guide/*" in index
    for page in (ROOT / "docs" / "guide").glob("*.md"):
        first = page.read_text().lstrip().splitlines()[0]
        assert first.startswith("# "), page.name  # one top-level heading: its title in the toctree


def _generator():
    import importlib.util
    spec = importlib.util.spec_from_file_location("vo_generate", ROOT / "docs" / "_ext" / "vo_generate.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    return gen


def test_every_results_csv_renders_as_a_table_of_its_named_columns():
    gen = _generator()
    csvs = sorted((ROOT / "docs" / "results").glob("*.csv"))
    assert {p.stem for p in csvs} <= set(gen.RESULT_TABLES)  # a CSV without a table spec would stop the build
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    for path in csvs:
        text = gen.results_table(path)  # raises KeyError where a named column is missing
        n_rows = sum(1 for _ in path.open()) - 1
        assert text.count("\n| ") == n_rows + 1, path.name  # the header and one line per CSV row
        assert f"_generated/results_{path.stem}.md" in page, f"{path.name} is not shown on the benchmarks page"


def test_the_study_columns_table_holds_the_runners_columns_and_every_study():
    from vesicle_opt.studies import STUDIES, runner
    gen = _generator()
    text = gen.study_columns()
    assert gen.columns(runner.COLUMNS) in text  # the common columns, in the runner's order
    assert all(f"| `{name}` |" in text for name in STUDIES)  # a row per registered study
    assert gen.study_extra_columns("sharp_limit")[:2] == ["nu", "epsilon"]  # its own COLUMNS, minus n and h
    assert "_generated/study_columns.md" in (ROOT / "docs" / "guide" / "outputs.md").read_text()
