"""Start-up cost: ``import vesicle_opt`` loads no library that only some paths need (CasADi for an
IPOPT solve, matplotlib or Pillow for a PNG, scipy.signal, scipy.optimize): checked in a fresh interpreter,
where the module table says what an import pulled in."""

import subprocess
import sys

import pytest

HEAVY = ("casadi", "matplotlib", "PIL", "scipy.signal", "scipy.optimize")


def test_import_loads_no_heavy_optional_library():
    code = f"import sys, vesicle_opt; print(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"import vesicle_opt loaded: {out.stdout.strip()}"


def test_the_ipopt_path_still_finds_casadi():
    """The lazy import is where the NLP is built: a small IPOPT solve works and loads CasADi."""
    code = ("import sys, vesicle_opt as vo; sc = vo.load_scene('ellipse-2d', ['mesh.n=16', "
            "\"solver.backend='ipopt'\", 'solver.second_order=false']); r = vo.solve(sc); "
            "print(r.converged, 'casadi' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split()[-2:] == ["True", "True"], out.stdout + out.stderr


def test_the_solve_verb_loads_no_flow_code():
    """``vesicle_opt.flow`` / ``FlowResult`` load the flows package on first use (PEP 562), the CLI's
    flow verb imports it itself: ``import vesicle_opt.cli.app`` (the parser and the verbs) does not, and
    the attributes still work."""
    code = ("import sys, vesicle_opt.cli.app, vesicle_opt as vo; print('vesicle_opt.flows' in sys.modules); "
            "from vesicle_opt.flows.api import flow, FlowResult; "
            "print(vo.flow is flow, vo.FlowResult is FlowResult, 'flow' in vo.__all__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "True", "True", "True"], out.stdout + out.stderr


def test_a_pyfftw_solve_loads_no_scipy_fft():
    """scipy.fft (and the scipy.special it imports) loads with its first use (``mesh.spectral``): a
    spectral solve on pyFFTW never imports it, one on scipy's FFTs does, and both converge."""
    pytest.importorskip("pyfftw")
    code = ("import sys, vesicle_opt as vo; sc = vo.load_scene('torus-table1-3d', [\"mesh.kind='spectral'\", "
            "'mesh.n=16', 'solver.second_order=false', \"solver.fft='{}'\"]); r = vo.solve(sc); "
            "print(r.converged, 'scipy.fft' in sys.modules)")
    for fft, loaded in (("pyfftw", "False"), ("scipy", "True")):
        out = subprocess.run([sys.executable, "-c", code.format(fft)], capture_output=True, text=True, check=True)
        assert out.stdout.split()[-2:] == ["True", loaded], (fft, out.stdout + out.stderr)


def test_nested_iteration_resamples_without_scipy_fft():
    """The coarse-to-fine step of nested iteration (``mesh.spectral.resample``) uses numpy.fft, so a
    nested solve on pyFFTW (64^3 from 32^3) does not load scipy.fft either (it did, inside the
    solve's wall time: ~0.05 s)."""
    code = ("import sys, numpy as np; from vesicle_opt.mesh.spectral import resample; "
            "x = np.random.default_rng(0).random(8 * 8 * 8); y = resample(x, (8, 8, 8), (16, 16, 16)); "
            "print(y.shape[0], 'scipy.fft' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["4096", "False"], out.stdout + out.stderr


def test_the_command_entry_imports_nothing_heavy():
    """``vesicle_opt`` and ``vesicle_opt.cli`` (what the ``vesicle-opt`` script imports before ``cli.run``
    installs its interrupt handling) load no numpy: every public name loads with its first use (PEP 562),
    so a Ctrl-C during the 0.6 s of imports meets the handler, not a traceback
    (``test_interrupt_startup.py``); the names still resolve, ``vo.branch`` to the function."""
    code = ("import sys, vesicle_opt, vesicle_opt.cli; heavy = [m for m in ('numpy', 'scipy', 'vesicle_opt.api') "
            "if m in sys.modules]; from vesicle_opt.branch import run as r; import vesicle_opt as vo; "
            "print(heavy, vo.branch is r.branch, vesicle_opt.cli.main.__module__, vo.__version__ == vo.package_version())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[]", "True", "vesicle_opt.cli.app", "True"], out.stdout + out.stderr
