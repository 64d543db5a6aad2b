"""The crossing_3d study's pieces: the octant boxes, the
form and gap of an unfolded octant field; --quick runs through the runner and resumes."""

import csv
import json

import numpy as np
import pytest

from vesicle_opt.mesh import cosine
from vesicle_opt.studies import crossing_3d as cx
from vesicle_opt.studies import run_study


def test_octant_box_leaves_the_gap_at_the_spacing():
    box, n = cx.octant_box((2.36, 0.6, 0.6), 0.05)
    h = 0.05 / cx.EPS_OVER_H
    for (lo, hi), k, e in zip(box, n, (2.36, 0.6, 0.6)):
        assert lo == 0 and hi == pytest.approx(k * h, rel=1e-14) and k % 2 == 0
        assert 2 * (hi - e) >= cx.GAP_OVER_EPS * 0.05 - 1e-12  # the free space to the mirror image


def test_form_and_gap_of_an_unfolded_octant_ellipsoid():
    g = cosine.grid([[0.0, 3.0], [0.0, 1.5], [0.0, 1.5]], (30, 15, 15))
    x = g.nodes
    for axes, want in (((2.0, 0.7, 0.7), "prolate"), ((1.2, 1.2, 0.4), "oblate")):
        phi = np.tanh(1 - sum((x[:, i] / a) ** 2 for i, a in enumerate(axes)))
        snap = {"phi": phi, "grid_shape": np.array(g.grid_shape), "box": np.array(g.box)}
        assert cx.form(snap)[0] == want
        # free space across the far x face: 2 (3.0 - last occupied cell's end), within a spacing
        gap, _ = cx.image_gap(snap, 0.1)
        assert gap <= 2 * (1.5 - max(axes[1:])) + 2 * 0.1 + 1e-12


@pytest.mark.slow
def test_quick_runs_resumes_and_writes_its_files(tmp_path):
    code = run_study("crossing_3d", tmp_path, quick=True)
    rows = list(csv.DictReader((tmp_path / "crossing_3d.csv").open()))
    assert len(rows) == 4 and all(r["converged"] == "True" for r in rows)
    assert [r["start"] for r in rows if r["branch_form"] == "prolate"] == ["cold", "warm"]
    assert all(r["second_order_excluded"].startswith("all but mirror-symmetric") for r in rows)
    info = json.loads((tmp_path / "crossing_3d.json").read_text())
    assert info["crossing_sharp"]["reduced_volume"] == pytest.approx(0.651076, abs=1e-6)
    assert code == 0 and (tmp_path / "crossing_3d.png").stat().st_size > 0
    before = (tmp_path / "crossing_3d.csv").read_text()
    assert run_study("crossing_3d", tmp_path, quick=True) == 0  # resumed: nothing re-run, no row twice
    assert (tmp_path / "crossing_3d.csv").read_text() == before
