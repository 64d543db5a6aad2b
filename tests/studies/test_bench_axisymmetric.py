"""The ``bench_axisymmetric`` study's quick run: both modes solve the same warm points (the start and
the check's factorisation change the cost, not the answer)."""

import csv

import pytest

import vesicle_opt as vo


def test_quick_run_old_and_new_reach_the_same_points(tmp_path):
    vo.run_study("bench_axisymmetric", tmp_path, quick=True)
    rows = list(csv.DictReader(open(tmp_path / "bench_axisymmetric.csv")))
    assert [r["mode"] for r in rows] == ["old", "new", "old", "new"]
    assert all(r["status"] == "converged" and r["verdict"] == "minimum" for r in rows)
    for old, new in zip(rows[::2], rows[1::2]):
        assert old["reduced_volume"] == new["reduced_volume"]
        # one point from two starts: IPOPT's tol 1e-8 on a stationary energy (measured ~4e-12 relative)
        assert float(new["energy"]) == pytest.approx(float(old["energy"]), rel=1e-9)
    assert rows[-1]["median_cpu_s"] and rows[-2]["median_cpu_s"]  # each mode's medians on its last row
