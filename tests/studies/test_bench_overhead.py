"""bench_overhead's whole-process rows: real ``vesicle-opt solve`` processes, their solve and check
times read from the summary they wrote (no timing is asserted: the machine is shared)."""

import pytest

from vesicle_opt.studies import bench_overhead


def test_cli_rows_time_whole_processes_beside_their_solves():
    rows = bench_overhead.cli_rows({"n": 16, "repeats": 1})
    assert [r["mode"] for r in rows] == ["bare", "default"]
    bare, default = rows
    for r in rows:
        assert r["converged"] is True and r["status"] == "converged"
        assert r["whole_process_s"] > r["solve_s"] > 0  # the process holds the solve
        assert r["whole_over_solve"] == pytest.approx(r["whole_process_s"] / r["solve_s"], rel=1e-15)
        assert r["median_whole_process_s"] == r["whole_process_s"]  # one repeat: its own median
    assert bare["certificate_s"] is None and default["certificate_s"] > 0  # the check ran by default only
    assert bare["whole_over_bare_solve"] == pytest.approx(bare["whole_over_solve"], rel=1e-15)
    assert default["whole_over_bare_solve"] == pytest.approx(default["whole_process_s"] / bare["solve_s"], rel=1e-15)
    assert default["energy"] == pytest.approx(bare["energy"], rel=1e-12)  # the same solve, checked or not
