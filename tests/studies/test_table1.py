"""The topology check of the Table-1 study tells a torus from a sphere and from two blobs; the
quick modes of the large-3D studies append their rows and resume."""

import numpy as np
import pytest

from vesicle_opt.mesh.fd import grid
from vesicle_opt.studies import study
from vesicle_opt.studies._common import torus_check

BOX = [(-np.pi, np.pi)] * 3


def test_torus_check_accepts_a_torus_and_rejects_others():
    disc = grid(BOX, (32, 32, 32))
    X, Y, Z = disc.nodes.T
    rho = np.hypot(X, Y)
    torus = np.tanh(0.6 - np.hypot(rho - 1.5, Z))
    sphere = np.tanh(1.5 - np.sqrt(X**2 + Y**2 + Z**2))
    blobs = np.tanh(0.6 - np.minimum(np.sqrt((X - 1.5) ** 2 + Y**2 + Z**2), np.sqrt((X + 1.5) ** 2 + Y**2 + Z**2)))
    assert torus_check(disc, torus) == {"components": 1, "euler_characteristic": 0, "wraps": "none",
                                        "axis_negative": True, "torus_ok": True}
    s = torus_check(disc, sphere)
    assert s["components"] == 1 and s["euler_characteristic"] == 1 and not s["axis_negative"] and not s["torus_ok"]
    b = torus_check(disc, blobs)
    assert b["components"] == 2 and not b["torus_ok"]
    # a blob cut by the periodic boundary is still one component
    wrapped = np.tanh(0.6 - np.sqrt((np.abs(X) - np.pi) ** 2 + Y**2 + Z**2))
    assert torus_check(disc, wrapped)["components"] == 1
    # a slab across the box with a hole on the axis: one component, axis outside, but it joins its
    # periodic images along x and y -- not a torus (the faces-only check of old said it was)
    slab = np.minimum(np.tanh(0.6 - np.abs(Z)), np.tanh(rho - 1.0))
    sl = torus_check(disc, slab)
    assert sl["components"] == 1 and sl["axis_negative"] and sl["wraps"] == "xy" and not sl["torus_ok"]
    # the check reads a front-door result's topology report when given one
    assert torus_check(disc, torus, {"components": 2, "euler_characteristic": 0, "wraps": []})["torus_ok"] is False


@pytest.mark.slow
@pytest.mark.parametrize("name", ["table1", "bench_3d", "bench_jax", "bench_certificate"])
def test_quick_3d_study_appends_and_resumes(tmp_path, name):
    import csv
    if name == "bench_jax":
        pytest.importorskip("jax")
    module = study(name)
    module.main(tmp_path, quick=True)
    rows = list(csv.DictReader((tmp_path / f"{name}.csv").open()))
    assert rows and all(r["status"] in ("converged", "Solve_Succeeded") for r in rows)
    module.main(tmp_path, quick=True)  # resume: every case is finished, nothing runs twice
    assert len(list(csv.DictReader((tmp_path / f"{name}.csv").open()))) == len(rows)


@pytest.mark.slow
def test_torus_section5_quick_pinches_a_disk_into_a_torus(tmp_path):
    """16^3: the flat disk (chi 1) becomes a torus (chi 0) without wrapping round the box, every step's
    law (24) verified, the flow goes on to a certified equilibrium, and the polish from the path's
    end converges to that torus."""
    import csv

    from vesicle_opt.studies import torus_section5 as T
    assert T.main(tmp_path, quick=True) == 0
    rows = list(csv.DictReader((tmp_path / "torus_section5.csv").open()))
    frames = [r for r in rows if r["row"] == "frame" and r["start"] == "disk"]
    final = next(r for r in rows if r["row"] == "final" and r["start"] == "disk")
    assert frames[0]["euler_characteristic"] == "1" and frames[-1]["euler_characteristic"] == "0"
    assert final["path"].endswith("chi 0, wraps none") and final["torus_ok"] == "True"
    assert float(final["max_law_residual"]) <= 1e-11  # (24) <= 0 up to round-off, as test_schemes.LAW_TOL
    assert final["flow_eq_certified"] == "True" and float(final["flow_eq_kkt_residual"]) <= 1e-6  # 100 tol
    assert T.main(tmp_path, quick=True) == 0  # resume: nothing runs twice
    assert len(list(csv.DictReader((tmp_path / "torus_section5.csv").open()))) == len(rows)
