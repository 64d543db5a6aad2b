"""The energy_diagram study, --quick (2D only): both branches run through the study runner, every
accepted point is certified and checked, the files are written, and the crossing finder works."""

import csv
import json

import numpy as np

from vesicle_opt.studies import energy_diagram as ed
from vesicle_opt.studies import run_study


def test_quick_runs_and_writes_its_files(tmp_path):
    code = run_study("energy_diagram", tmp_path, quick=True)
    info = json.loads((tmp_path / "energy_diagram.json").read_text())
    el = info["elastica-2d"]
    assert el["points"] == 3 and el["certified"] == 3 and el["stopped"] == "reached", el
    assert el["minimum"] == 3  # the ellipse start lies on the stable elastica branch
    assert info["symmetric-2d"]["saddle"] >= 1  # the circle start: the symmetric saddle
    assert code == 0
    # the envelope identity holds to O(step^2): measured 1.5e-3 at step 0.05 (residual / step^2 ~ 0.6)
    assert el["envelope_residual_max"] < 10 * el["max_step"] ** 2
    assert el["min_image_gap_over_eps"] > 4  # far from the periodic image (measured ~10)
    # the sharp-interface column (vesicle_opt.sharp.elastica) on the elastica branch, none on the
    # saddle branch; the elastica's energy grows as nu falls (de/dnu = lam < 0), to round-off
    rows = list(csv.DictReader((tmp_path / "energy_diagram.csv").open()))
    sharp = [(float(r["reduced_volume"]), float(r["sharp_reduced_energy"])) for r in rows
             if r["scene"] == "elastica-2d" and r["accepted"] == "True"]
    assert len(sharp) == 3 and all(e > 1 for _, e in sharp)
    assert all(e1 < e2 for (_, e1), (_, e2) in zip(sorted(sharp, reverse=True), sorted(sharp, reverse=True)[1:]))
    assert all(r["sharp_reduced_energy"] == "" for r in rows if r["scene"] == "symmetric-2d")
    for name in ("energy_diagram.csv", "energy_diagram-2d.png", "elastica-2d/branch.csv",
                 "elastica-2d/points/point-0002.npz"):
        assert (tmp_path / name).stat().st_size > 0, name


def test_crossing_of_two_lines_is_where_they_meet():
    """Two straight branches e = 1 + v and e = 2 - v cross at v = 0.5, e = 1.5 (exact for the linear
    interpolation), also on different v grids."""
    a = [{"reduced_volume": v, "reduced_energy": 1 + v} for v in np.linspace(0.2, 0.9, 8)]
    b = [{"reduced_volume": v, "reduced_energy": 2 - v} for v in np.linspace(0.1, 0.95, 5)]
    x = ed.crossing(a, b)
    assert abs(x["reduced_volume"] - 0.5) < 1e-12 and abs(x["reduced_energy"] - 1.5) < 1e-12  # round-off
    assert ed.crossing(a, [{"reduced_volume": v, "reduced_energy": 5 + v} for v in (0.3, 0.6)]) is None
