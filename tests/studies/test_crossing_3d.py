"""The crossing_3d study's pieces: the crossing finder against a closed form, the octant boxes, the
form and gap of an unfolded octant field; --quick runs through the runner and resumes."""

import csv
import json

import numpy as np
import pytest

from vesicle_opt.mesh import cosine
from vesicle_opt.studies import crossing_3d as cx
from vesicle_opt.studies import run_study


def test_crossing_of_curved_branches_matches_the_closed_form():
    """e = 1/v and e = 2.5 - v cross at v = 0.5, e = 2; the splines through points 0.02 apart (and
    on different grids) find it to their O(dv^4) error (~3e-7 here: dv^4 max|f''''| / 384)."""
    va = np.arange(0.40, 0.61, 0.02)
    vb = np.arange(0.41, 0.60, 0.03)
    x = cx.crossing(va, 1 / va, vb, 2.5 - vb)
    assert x["reduced_volume"] == pytest.approx(0.5, abs=1e-6)
    assert x["reduced_energy"] == pytest.approx(2.0, abs=1e-6)
    assert cx.crossing(va, 1 / va, va, 10 + va) is None  # no crossing on the overlap
    assert cx.crossing(va[:1], 1 / va[:1], vb, 2.5 - vb) is None  # too few points


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
    assert code == 0
    before = (tmp_path / "crossing_3d.csv").read_text()
    assert run_study("crossing_3d", tmp_path, quick=True) == 0  # resumed: nothing re-run, no row twice
    assert (tmp_path / "crossing_3d.csv").read_text() == before


def test_extrapolation_recovers_a_quadratic_limit():
    """y = y0 + c eps^2 exactly: every extrapolation gives y0 to round-off, the free order 2."""
    per_eps = {e: {"reduced_volume": 0.65 + 3 * e**2, "reduced_energy": 1.8 - 2 * e**2}
               for e in (0.07, 0.06, 0.05, 0.035)}
    ex = cx.extrapolate(per_eps)
    for key, y0 in (("reduced_volume", 0.65), ("reduced_energy", 1.8)):
        for how in ("_richardson", "_p2", "_lsq_p2"):
            assert ex[key + how] == pytest.approx(y0, abs=1e-12), key + how  # round-off of O(1) sums
        assert ex["order_" + key] == pytest.approx(2.0, abs=1e-6)  # brentq's tolerance on p
