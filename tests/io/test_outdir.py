"""The output directory (io.outdir): refused before any work when unusable; locked for the run."""

import os
import signal
import subprocess
import sys

import pytest

from vesicle_opt import cli
from vesicle_opt.errors import InputError
from vesicle_opt.io import outdir

SOLVE = ["solve", "ellipse-2d", "--set", "mesh.n=16"]


def _cli(argv, capsys):
    rc = cli.main(argv)
    return rc, capsys.readouterr().err.strip().splitlines()


def test_a_file_or_a_path_below_a_file_is_refused(tmp_path):
    f = tmp_path / "f"
    f.write_text("keep\n")
    for arg, why in ((f, "is a file"), (f / "sub" / "deeper", "lies below the file")):
        with pytest.raises(InputError) as exc:
            outdir.check(arg)
        assert str(exc.value).startswith("--out:") and why in str(exc.value)
    assert f.read_text() == "keep\n"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_an_unwritable_directory_is_refused(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        for arg in (ro, ro / "sub"):
            with pytest.raises(InputError, match="--out"):
                outdir.check(arg)
    finally:
        ro.chmod(0o755)


def test_an_unwritable_file_system_is_refused():
    """/proc refuses new files for every user, root included (the probe, not the mode bits, decides)."""
    with pytest.raises(InputError, match="--out"):
        outdir.check("/proc/vesicle-opt-out")


@pytest.mark.parametrize("verb", [SOLVE, ["flow", "ellipse-2d", "--set", "mesh.n=16", "--steps", "1"],
                                  ["study", "table1", "--quick"]])
def test_a_second_run_into_a_locked_directory_is_refused(verb, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text("{\"kept\": true}\n")
    with outdir.locked(out):  # another run holds it
        rc, err = _cli([*verb, "--out", str(out)], capsys)
    assert rc == 2 and len(err) == 1 and "--out" in err[0] and "in use" in err[0]
    assert (out / "summary.json").read_text() == "{\"kept\": true}\n"  # nothing lost


def test_the_lock_dies_with_its_process_even_by_sigkill(tmp_path):
    # the child takes the same lock file as outdir.locked with filelock alone (importing the package
    # would take seconds on a loaded machine)
    code = ("import sys, time, filelock\n"
            "with filelock.FileLock(sys.argv[1], timeout=0):\n    print('held', flush=True); time.sleep(60)\n")
    lock = str(tmp_path / outdir.LOCK_NAME)
    p = subprocess.Popen([sys.executable, "-c", code, lock], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    with pytest.raises(InputError, match="in use"):
        with outdir.locked(tmp_path):
            pass
    os.kill(p.pid, signal.SIGKILL)
    p.wait(timeout=10)
    with outdir.locked(tmp_path):  # released by the kernel: no stale lock to clean up
        pass


def test_a_study_needs_out(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, err = _cli(["study", "table1", "--quick"], capsys)
    assert rc == 2 and len(err) == 1 and "--out" in err[0]
    assert not (tmp_path / "out").exists()  # the old default wrote ./out silently
    rc, err = _cli(["study", "../tests/conftest", "--out", str(tmp_path / "s")], capsys)
    assert rc == 2 and len(err) == 1 and "unknown study" in err[0]  # names come from the registry only


def test_a_directory_as_the_scene_is_bad_input(tmp_path, capsys):
    rc, err = _cli(["solve", str(tmp_path), "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and len(err) == 1 and err[0].startswith("vesicle-opt: error: scene")
