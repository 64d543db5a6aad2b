"""The wheel (non-editable): it ships the bundled scenes, every subpackage and module, the licence,
no top-level ``studies`` package, and solves a bundled scene by name from outside the source tree.

The wheel is built from a copy of the repository root without build artefacts (``build/``,
``*.egg-info``): setuptools packs whatever lies in ``build/lib``, so a stale copy of a removed
module there would end up in a wheel built in place.
"""

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from vesicle_opt.studies import STUDIES

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "vesicle_opt"
ARTEFACTS = shutil.ignore_patterns(".git", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache",
                                   "out", "results", "*.pyc")


def _run(cmd, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=900, **kw)


def _build_wheel(src: Path, dist: Path) -> Path:
    """pip wheel without build isolation; with it when that fails (the environment's setuptools
    may be older than pyproject's setuptools>=68, or lack bdist_wheel: setuptools < 70 needs the
    ``wheel`` package)."""
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", str(dist), "."]
    p = _run(cmd[:5] + ["--no-build-isolation"] + cmd[5:], cwd=src)
    if p.returncode != 0:
        p = _run(cmd, cwd=src)
    assert p.returncode == 0, f"pip wheel failed:\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}"
    (wheel,) = dist.glob("vesicle_opt-*.whl")
    return wheel


@pytest.mark.slow
def test_wheel_ships_the_package_and_solves_a_bundled_scene(tmp_path):
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, symlinks=True, ignore=ARTEFACTS)
    wheel = _build_wheel(src, tmp_path / "dist")
    names = zipfile.ZipFile(wheel).namelist()
    dist_info = next(n.split("/")[0] for n in names if n.split("/")[0].endswith(".dist-info"))
    assert {n.split("/")[0] for n in names} == {"vesicle_opt", dist_info}  # no top-level studies/
    scenes = {p.name for p in (PACKAGE / "problems").glob("*.toml")}
    assert scenes and {Path(n).name for n in names if n.startswith("vesicle_opt/problems/")
                       and n.endswith(".toml")} == scenes
    sources = {p.relative_to(ROOT).as_posix() for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts}
    assert {n for n in names if n.endswith(".py")} == sources  # every module and subpackage, nothing stale
    assert f"{dist_info}/licenses/LICENSE" in names or f"{dist_info}/LICENSE" in names
    metadata = zipfile.ZipFile(wheel).read(f"{dist_info}/METADATA").decode()
    assert "License-Expression: MIT" in metadata  # PEP 639 (setuptools >= 77, Metadata 2.4)

    site = tmp_path / "site"
    p = _run([sys.executable, "-m", "pip", "install", "--no-deps", "--target", str(site), str(wheel)])
    assert p.returncode == 0, p.stderr[-3000:]
    cwd = tmp_path / "elsewhere"  # no source tree on sys.path: '' and -m resolve here
    cwd.mkdir()
    env = {**os.environ, "PYTHONPATH": str(site)}
    where = _run([sys.executable, "-c", "import vesicle_opt; print(vesicle_opt.__file__)"], cwd=cwd, env=env)
    assert Path(where.stdout.strip()).resolve().is_relative_to(site.resolve()), where.stdout + where.stderr
    out = tmp_path / "run"
    p = _run([sys.executable, "-m", "vesicle_opt.cli", "solve", "ellipse-2d", "--out", str(out),
              "--set", "mesh.n=32"], cwd=cwd, env=env)
    assert p.returncode == 0, p.stdout + p.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["converged"] is True and summary["scene"] == "ellipse-2d"
    p = _run([sys.executable, "-m", "vesicle_opt.cli", "study", "--list"], cwd=cwd, env=env)
    assert p.returncode == 0 and [ln.split()[0] for ln in p.stdout.splitlines()] == list(STUDIES), p.stderr
    imports = "import vesicle_opt.studies as s; [s.study(n).main for n in s.STUDIES]"  # each study imports
    p = _run([sys.executable, "-c", imports], cwd=cwd, env=env)
    assert p.returncode == 0, p.stderr[-3000:]
