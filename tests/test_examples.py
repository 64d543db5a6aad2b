"""Each script in examples/ runs and gives its number (scikit-fem style: the test imports the
example's ``main`` and checks what it returns; one runs as a script from another directory)."""

import importlib.util
import math
import subprocess
import sys
from pathlib import Path


EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _load(name):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_solve_and_read():
    res = _load("solve_and_read").main()  # 64^2: at 32^2 the grid makes this KKT point a saddle
    s = res.summary("ellipse-2d")
    assert res.converged and res.extra["second_order"] == "minimum"
    # the geometry identity of Section 3.1 on the Result's own numbers (round-off)
    assert math.isclose(s["area"], 3 * math.sqrt(2) * (s["beta"] + res.area_residual) / 4,
                        rel_tol=1e-12)


def test_own_constraint_holds_on_the_solution():
    assert abs(_load("own_constraint").main(n=24, x_center=0.5) - 0.5) < 1e-7  # IPOPT tol 1e-8 on the row


def test_penalty_gap_is_the_first_order_prediction():
    out = _load("penalty_vs_exact").main(n=32, M=1e3)
    gap = out["penalty"].energy - out["exact"].energy
    # Theorem 3.2: gap = -|lambda|^2/M + O(1/M^2); measured 0.2% off at 48^2, M = 1e3
    assert out["penalty"].converged and abs(gap / out["predicted_gap"] - 1) < 0.02


def test_flow_with_tracker_stops_and_keeps_the_law():
    res, worst = _load("flow_with_tracker").main(n=16, stop_below=8.0)
    assert res.status.value == "stopped" and res.energy < 8.0
    assert worst < 1e-11  # law (22) at round-off (tests/flows: measured 1e-15 ... 3e-13)


def test_torus_surface(tmp_path):
    s = _load("torus_surface").main(str(tmp_path / "torus"), n=16)
    assert (tmp_path / "torus" / "surface.ply").exists() and s["surface_closed"]
    assert abs(s["surface_area_rel_diff"]) < 0.05  # 16^3, eps/h = 0.65: measured +2.7% (tests/io)


def test_an_example_runs_as_a_script_from_any_directory(tmp_path):
    out = subprocess.run([sys.executable, str(EXAMPLES / "flow_with_tracker.py")], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.startswith("stopped after"), out.stderr[-2000:]


def test_branch_2d_is_certified_and_obeys_the_envelope_identity():
    b = _load("branch_2d").main()
    pts = b.points()
    assert len(pts) == 3 and all(r["converged"] and r["second_order"] == "minimum" for r in pts)
    # the elastica's reduced energy rises as nu falls (de/dnu = lambda < 0)
    e = [r["reduced_energy"] for r in sorted(pts, key=lambda r: -r["reduced_volume"])]
    assert e[0] < e[1] < e[2]
    # envelope identity to O(step^2): measured 1.5e-3 at step 0.05 (residual / step^2 ~ 0.6)
    env = [r["envelope_residual"] for r in pts if r.get("envelope_residual") not in (None, "")]
    assert env and max(abs(v) for v in env) < 10 * 0.05**2
