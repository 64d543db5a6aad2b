"""What a new user meets first: --version, python -m vesicle_opt, --help, study --list / NAME --help,
-v / -q, the default backend "auto", progress lines without carriage returns."""

import json
import subprocess
import sys

import pytest

import vesicle_opt as vo
from vesicle_opt import cli
from vesicle_opt.backends import choose_backend
from vesicle_opt.studies import DESCRIPTIONS, STUDIES


def test_version_and_python_m(capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"vesicle-opt {vo.__version__}"
    out = subprocess.run([sys.executable, "-m", "vesicle_opt", "--version"], capture_output=True, text=True,
                         cwd=tmp_path, check=True).stdout
    assert out.strip() == f"vesicle-opt {vo.__version__}"


def test_help_is_a_clean_description(capsys):
    with pytest.raises(SystemExit):
        cli.main(["--help"])
    text = capsys.readouterr().out
    assert cli.DESCRIPTION[:60] in text.replace("\n", " ") and "``" not in text
    assert all(v in text for v in ("solve", "study", "flow", "--version", "--verbose", "--quiet", "examples:"))


def test_study_list_and_help_come_from_the_registry(capsys):
    assert set(DESCRIPTIONS) == set(STUDIES)
    assert cli.main(["study", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == list(STUDIES)
    assert all(ln.endswith(DESCRIPTIONS[ln.split()[0]]) for ln in lines)
    with pytest.raises(SystemExit) as exc:
        cli.main(["study", "table1", "--help"])
    text = capsys.readouterr().out
    assert exc.value.code == 0 and "study table1:" in text and "Table 1 of the paper" in text
    assert cli.main(["study", "no-such-study"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(name in err[0] for name in STUDIES)


def test_verbose_shows_ipopt_log_and_quiet_shows_nothing(tmp_path, capfd):
    argv = ["solve", "ellipse-2d", "--out", str(tmp_path), "--set", "mesh.n=16", "--set", "solver.second_order=false"]
    assert cli.main(argv + ["-v"]) == 0
    out, err = capfd.readouterr()
    assert "iter    objective    inf_pr" in out  # IPOPT's own iteration table (print_level 5)
    assert "method exact on ipopt (auto: 2D" in err  # which backend and why
    verbose = json.loads((tmp_path / "summary.json").read_text())
    assert cli.main(["-q", *argv]) == 0
    quiet = json.loads((tmp_path / "summary.json").read_text())
    # the iteration log and the progress callback change no number (timings aside)
    assert {k: v for k, v in verbose.items() if not k.endswith("_time_s")} == \
        {k: v for k, v in quiet.items() if not k.endswith("_time_s")}
    out, err = capfd.readouterr()
    # the result line only; -q keeps warnings (16^2 at eps = 0.2 is eps/h = 0.4: the resolution warning)
    assert all(line.startswith("vesicle-opt: warning: ") for line in err.splitlines())
    assert "objective" not in out and len(out.strip().splitlines()) == 1
    assert cli.main(argv) == 0  # default: the phase line on stderr, no iteration log
    out, err = capfd.readouterr()
    assert "objective" not in out and "on ipopt" in err
    assert "IPOPT: " in err and " iterations, " in err and "\r" not in err  # progress, plain lines off a terminal


def test_verbose_newton_krylov_and_flow_lines(tmp_path, capfd):
    """One line per Newton step (spectral 16^3: auto picks Newton-Krylov without --set backend), one
    per flow step; the flow's progress off a terminal is plain lines with an ETA, no carriage return."""
    assert cli.main(["solve", "torus-table1-3d", "--out", str(tmp_path / "s"), "-v", "--set", 'mesh.kind="spectral"',
                     "--set", "solver.second_order=false", "--set", "solver.method='penalty'"]) == 0
    err = capfd.readouterr().err
    assert "on newton-krylov (auto: a spectral mesh" in err and err.count("[nk.newton_cg] Newton") >= 3
    assert cli.main(["flow", "ellipse-2d", "--out", str(tmp_path / "f"), "--steps", "3", "-v",
                     "--set", "mesh.n=16", "--set", "solver.M=100", "--set", "flow.frames=1"]) == 0
    err = capfd.readouterr().err
    assert err.count("[flows.stepper] step ") == 3 and "\r" not in err
    assert "flow: 3/3 steps (100%)" in err and "ETA" in err


def test_auto_is_the_default_backend():
    assert vo.load_scene("ellipse-2d").solver.backend == "auto"
    assert choose_backend(vo.load_scene("ellipse-2d")) == "ipopt"
    assert choose_backend(vo.load_scene("torus-table1-3d")) == "ipopt"  # 16^3 FD: IPOPT fits
    assert choose_backend(vo.load_scene("torus-table1-3d", ["mesh.n=32"])) == "newton-krylov"
    assert choose_backend(vo.load_scene("torus-table1-3d", ["mesh.n=32", "solver.backend='ipopt'"])) == "ipopt"
