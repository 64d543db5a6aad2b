"""The operating system's refusals at the boundary (injected OSErrors): before the work (--out on a
read-only file system, full, not permitted, a name too long) one line and exit 2; during the work
(the disk fills while a solve writes its result, or in the middle of a flow) exit 1 with one line,
a solve's computed result written to a temporary directory instead, and the finished run already
in --out keeping its files."""

import errno
import json
from pathlib import Path

import pytest

from vesicle_opt import cli
from vesicle_opt.io import outdir, output

SCENE = ["solve", "ellipse-2d", "--set", "mesh.n=16", "--set", "solver.second_order=false"]


def test_no_space_left_while_writing_keeps_the_result_elsewhere(tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    assert cli.main([*SCENE, "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and not p.name.startswith(".")}
    real = output.write_png

    def full_disk(path, *args, **kwargs):
        if Path(path).is_relative_to(out):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, *args, **kwargs)
    monkeypatch.setattr(output, "write_png", full_disk)
    capsys.readouterr()
    code = cli.main([*SCENE, "--set", "model.epsilon=0.3", "--out", str(out)])
    # the log and its warnings apart (eps / h = 0.6 and the bulk offset: right for this coarse toy, not the subject)
    err = [ln for ln in capsys.readouterr().err.splitlines()
           if ln.startswith("vesicle-opt:") and not ln.startswith("vesicle-opt: warning")]
    assert code == 1 and len(err) == 1 and "No space left on device" in err[0] and str(out) in err[0], err
    spare = Path(err[0].split("written to '")[1].split("'")[0])
    assert json.loads((spare / "summary.json").read_text())["converged"] is True
    assert (spare / "phi.npz").exists() and (spare / "phi.png").exists()
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and not p.name.startswith(".")}
    assert after == before and not (out / ".vesicle-opt-partial").exists()


@pytest.mark.parametrize("code, why", [(errno.EROFS, "Read-only file system"), (errno.ENOSPC, "No space left on device"),
                                       (errno.EACCES, "Permission denied"), (errno.ENAMETOOLONG, "File name too long")])
def test_an_unusable_out_is_one_line_exit_2_before_any_work(tmp_path, capsys, monkeypatch, code, why):
    """The probe of --out (io.outdir: a file created and removed) meets the file system's refusal."""
    def refuse(*args, **kwargs):
        raise OSError(code, why)
    monkeypatch.setattr(outdir.tempfile, "mkstemp", refuse)
    out = tmp_path / "out"
    rc = cli.main([*SCENE, "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("vesicle-opt: error: --out:"), err
    assert str(out) in err[0] and why in err[0]


def test_the_disk_failing_during_a_flow_is_one_line_exit_1_and_the_finished_run_kept(tmp_path, capsys, monkeypatch):
    argv = ["flow", "ellipse-2d", "--scheme", "penalty", "--dt", "1e-3", "--steps", "4", "-q",
            "--set", "mesh.n=16", "--set", "solver.M=100"]
    out = tmp_path / "out"
    assert cli.main([*argv, "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and not p.name.startswith(".")}
    real = output.write_png

    def full_disk(path, *args, **kwargs):
        if "frame_002" in str(path):  # a snapshot in the middle of the run
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, *args, **kwargs)
    monkeypatch.setattr(output, "write_png", full_disk)
    capsys.readouterr()
    rc = cli.main([*argv, "--set", "model.epsilon=0.3", "--out", str(out)])
    # the eps / h = 0.6 warning apart (right for this coarse toy, not the subject)
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if not ln.startswith("vesicle-opt: warning")]
    assert rc == 1 and len(err) == 1 and "No space left on device" in err[0] and "frame_002" in err[0], err
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and not p.name.startswith(".")}
    assert after == before
