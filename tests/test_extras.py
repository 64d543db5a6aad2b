"""Optional extras that are installed but do not load (pyFFTW without its shared library, a broken
JAX), simulated in a fresh process by a meta-path finder that finds the package and fails its
import: "auto" falls back with one warning line naming the extra and the error; an explicit
choice is refused before any work with one line (the key, the error, the install command)."""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = r'''
import contextlib, importlib.abc, importlib.machinery, io, json, sys

ERROR = "libfftw3.so.3: cannot open shared object file: No such file or directory"

class Broken(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """find_spec finds the package (it is installed); its import fails (it does not load)."""
    def find_spec(self, name, path=None, target=None):
        return importlib.machinery.ModuleSpec(name, self) if name in ("pyfftw", "jax") else None
    def create_module(self, spec):
        return None
    def exec_module(self, module):
        raise ImportError(ERROR)

sys.meta_path.insert(0, Broken())
from vesicle_opt import cli
out = {}
for label, argv in json.loads(sys.argv[1]).items():
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli.main(argv)
    out[label] = [code, err.getvalue()]
print(json.dumps(out))
'''


def test_a_broken_extra_falls_back_on_auto_and_is_refused_when_chosen(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text('[domain]\nbox = [[-4.0, 4.0], [-4.0, 4.0]]\nboundary = "periodic"\n[mesh]\n'
                     'kind = "spectral"\nn = 16\n[model]\nepsilon = 0.8\n[constraints]\nreduced_volume = 0.95\n'
                     'area = 8.0\n[initial]\nshape = "ellipse"\nsemi_axes = [1.45, 1.1]\n[solver]\n'
                     'method = "exact"\nsecond_order = false\n')
    runs = {"auto": ["solve", str(scene), "--out", str(tmp_path / "a"), "--set", "solver.fft='auto'"],
            "pyfftw": ["solve", str(scene), "--out", str(tmp_path / "b"), "--set", "solver.fft='pyfftw'"],
            "jax": ["solve", str(scene), "--out", str(tmp_path / "c"), "--set", "solver.array='jax'",
                    "--set", "solver.backend='newton-krylov'"]}
    p = subprocess.run([sys.executable, "-c", SCRIPT, json.dumps(runs)], capture_output=True, text=True,
                       timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"})
    assert p.returncode == 0, p.stderr[-3000:]
    res = json.loads(p.stdout.strip().splitlines()[-1])
    code, err = res["auto"]
    warn = [ln for ln in err.splitlines() if ln.startswith("vesicle-opt: warning:") and "fftw" in ln]
    assert code == 0 and len(warn) == 1, err
    assert "solver.fft" in warn[0] and "cannot open shared object file" in warn[0] and "scipy.fft" in warn[0]
    assert json.loads((tmp_path / "a" / "summary.json").read_text())["converged"] is True
    for label, key, extra in (("pyfftw", "solver.fft", "fftw"), ("jax", "solver.array", "jax")):
        code, err = res[label]
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1, err
        assert lines[0].startswith(f"vesicle-opt: error: {key}:") and "cannot open shared object file" in lines[0]
        assert f"pip install 'vesicle_opt[{extra}]'" in lines[0]
        assert not (tmp_path / label[0]).exists() or not (tmp_path / ("b" if label == "pyfftw" else "c")).exists()
