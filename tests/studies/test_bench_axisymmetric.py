"""The ``bench_axisymmetric`` study's quick run: the three modes solve the same warm points (the start
and the check's factorisation change the cost, not the answer), and the new check's least eigenvalue
is the SuperLU check's on the same point to within its error bound."""

import csv

import pytest

import vesicle_opt as vo


def test_quick_run_old_schur_and_new_reach_the_same_points(tmp_path):
    vo.run_study("bench_axisymmetric", tmp_path, quick=True)
    rows = list(csv.DictReader(open(tmp_path / "bench_axisymmetric.csv")))
    assert [r["mode"] for r in rows] == ["old", "schur", "new"] * 2
    assert all(r["status"] == "converged" and r["verdict"] == "minimum" for r in rows)
    for trio in (rows[:3], rows[3:]):
        assert len({r["reduced_volume"] for r in trio}) == 1
        for r in trio[:2]:
            # one point from three starts: IPOPT's tol 1e-8 on a stationary energy (measured ~4e-12 relative)
            assert float(r["energy"]) == pytest.approx(float(trio[2]["energy"]), rel=1e-9)
        # one point's pencil through the LDL^T and through SuperLU: apart by less than the bound
        assert float(trio[2]["eigenvalue_gap"]) < 1
    assert all(rows[i]["median_cpu_s"] for i in (-3, -2, -1))  # each mode's medians on its last row
