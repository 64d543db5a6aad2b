"""The disk failing during a run (injected: ENOSPC from the writer of a result file): exit 1, one
line naming --out and the temporary directory the computed result was written to instead; the
finished run already in --out keeps its files."""

import errno
import json
from pathlib import Path

from vesicle_opt import cli
from vesicle_opt.io import output

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
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("vesicle-opt:")]  # the log apart
    assert code == 1 and len(err) == 1 and "No space left on device" in err[0] and str(out) in err[0], err
    spare = Path(err[0].split("written to '")[1].split("'")[0])
    assert json.loads((spare / "summary.json").read_text())["converged"] is True
    assert (spare / "phi.npz").exists() and (spare / "phi.png").exists()
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and not p.name.startswith(".")}
    assert after == before and not (out / ".vesicle-opt-partial").exists()
