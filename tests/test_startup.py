"""Start-up cost: ``import vesicle_opt`` loads no library that only some paths need (CasADi for an
IPOPT solve, matplotlib or Pillow for a PNG, scipy.signal, scipy.optimize): checked in a fresh interpreter,
where the module table says what an import pulled in."""

import subprocess
import sys

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
