"""The README's opening commands: the main job must run on the default scene and converge."""

import json
import re
import shlex
from pathlib import Path

from vesicle_opt import cli

README = Path(__file__).resolve().parent.parent / "README.md"


def test_readme_opens_with_install_and_test_commands():
    block = re.search(r"```bash\n(.*?)```", README.read_text(), re.S).group(1).strip().splitlines()
    assert len(block) == 2 and "vesicle-opt solve" in block[0] and "pytest" in block[1]


def test_readme_main_job_runs(tmp_path):
    first = re.search(r"```bash\n(.*?)\n", README.read_text(), re.S).group(1)
    argv = shlex.split(first.split("&&")[-1])
    assert argv[0] == "vesicle-opt"
    args = argv[1:]
    args[args.index("--out") + 1] = str(tmp_path)
    args[1] = str(README.parent / args[1])
    assert cli.main(args) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["converged"] and summary["scene"] == "ellipse-2d"
    assert (tmp_path / "phi.vtu").exists() and (tmp_path / "phi.png").exists()


def test_readme_python_example_runs():
    code = re.search(r"```python\n(.*?)```", README.read_text(), re.S).group(1)
    namespace: dict = {}
    exec(compile(code.replace("problems/", str(README.parent / "problems") + "/"), "README", "exec"), namespace)
    res = namespace["res"]
    assert res.converged and res.extra["second_order"] == "minimum"


def test_readme_is_short_and_its_links_exist():
    text = README.read_text()
    assert len(text.encode()) <= 10_000  # issue 28: a short README, the rest in docs/
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    missing = [p for p in links if not p.startswith("http") and not (README.parent / p).exists()]
    assert links and not missing, missing


def test_readme_states_no_unreproduced_timing():
    # every timing lives in docs/benchmarks.md with its machine and load; the README names none
    assert not re.search(r"\b\d+(\.\d+)?\s*(s|ms|min|minutes|seconds)\b", README.read_text())
