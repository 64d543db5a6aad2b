"""The flow studies (time_step_convergence, energy_decay, flow_vs_nlp) in quick mode: their outputs'
columns, and resume through ``studies.runner``: a second run recomputes nothing, a killed run
recomputes only its unfinished case and ends with every row once."""

from __future__ import annotations

import csv

import pytest

from vesicle_opt.studies import study as study_module

COLUMNS = {  # the columns each study wrote before it went through studies.runner
    "time_step_convergence.csv": ["scheme", "flow", "n", "T", "k", "steps", "l2_error", "energy_rel_error",
                                  "rejections", "wall_time_s"],
    "energy_decay.csv": ["k", "step", "t", "penalized_energy", "excess", "energy_law_residual"],
    "flow_vs_nlp.csv": ["method", "step", "t", "dt", "wall_time_s", "energy", "energy_rel_error",
                        "phi_distance", "volume_residual", "area_residual"],
}
DERIVED = {  # derived files keep their exact header
    "time_step_orders.csv": ["scheme", "flow", "order_l2", "order_energy", "expected"],
    "flow_vs_nlp_summary.csv": ["method", "wall_time_s", "time_to_target_s", "final_energy",
                                "best_energy_rel_error", "final_phi_distance", "status", "steps",
                                "time_to_energy_only_target_s"],
}


def _read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _header(path):
    with open(path, newline="") as fh:
        return next(csv.reader(fh))


def _never(case):
    raise AssertionError(f"case {case['case']} recomputed on a re-run")


def _check_outputs(out, csv_name):
    assert set(COLUMNS[csv_name]) <= set(_header(out / csv_name))
    assert {"case", "case_rows", "row"} <= set(_header(out / csv_name))
    for name, header in DERIVED.items():
        if (out / name).exists():
            assert _header(out / name) == header
    assert list(out.glob("*.png"))


def _rerun_recomputes_nothing(mod, out, monkeypatch, **kw):
    """Second run: the case function would raise (and its error row would change the CSV), so an
    unchanged CSV with return code 0 means every case was skipped."""
    csv_path = out / f"{mod.__name__.split('.')[-1]}.csv"
    before = csv_path.read_bytes()
    with monkeypatch.context() as m:
        m.setattr(mod, "case_rows", _never)
        assert mod.main(out, quick=True, **kw) == 0
    assert csv_path.read_bytes() == before


@pytest.mark.slow
@pytest.mark.parametrize("study", ["time_step_convergence", "energy_decay"])
def test_study_quick_runs(tmp_path, study, monkeypatch):
    mod = study_module(study)
    assert mod.main(tmp_path, quick=True) == 0
    _check_outputs(tmp_path, f"{study}.csv")
    if study == "time_step_convergence":
        for r in _read(tmp_path / "time_step_orders.csv"):
            # same +-0.15 as test_observed_order_in_k (measured 2.03 / 2.04 / 0.99 in L2)
            assert abs(float(r["order_l2"]) - float(r["expected"])) <= 0.15, r
    _rerun_recomputes_nothing(mod, tmp_path, monkeypatch)


@pytest.mark.slow
def test_time_step_convergence_resumes_after_kill(tmp_path):
    """Cut the CSV as a kill would leave it (a finished case's rows gone, a torn line), delete a
    reference field: the re-run recomputes them and the rows equal the uninterrupted run's."""
    from vesicle_opt.studies import time_step_convergence as mod
    assert mod.main(tmp_path, quick=True) == 0
    path = tmp_path / "time_step_convergence.csv"
    full = _read(path)
    victim = next(r["case"] for r in full if r["scheme"] == "backward-euler")  # the cheapest run
    lines = path.read_text().splitlines(keepends=True)
    kept = [ln for ln in lines if f",{victim}," not in ln]
    assert len(kept) == len(lines) - 1
    path.write_text("".join(kept) + lines[-1][: len(lines[-1]) // 2])
    ref = next(tmp_path.glob("reference-penalty-*.npz"))  # the victim's reference: rebuilt on demand
    ref.unlink()
    assert mod.main(tmp_path, quick=True) == 0
    again = _read(path)
    assert ref.exists()
    assert len(again) == len(full) and len({r["case"] for r in again}) == len(full)

    def key(rows):  # wall times aside, the deterministic numbers agree bitwise (same code path)
        return sorted(tuple(v for k, v in r.items() if k != "wall_time_s") for r in rows)
    assert key(again) == key(full)


@pytest.mark.slow
def test_flow_vs_nlp_small_resumes(tmp_path, monkeypatch):
    """16^2 with a 3 s cap per flow (not the study's settings: just the case plumbing and outputs)."""
    from vesicle_opt.studies import flow_vs_nlp as mod
    assert mod.main(tmp_path, quick=True, n=16, cap=3.0) == 0
    _check_outputs(tmp_path, "flow_vs_nlp.csv")
    summary = _read(tmp_path / "flow_vs_nlp_summary.csv")
    methods = [r["method"] for r in summary]
    assert methods[:4] == ["nlp-exact", "lagrange", "penalty", "backward-euler"]
    assert len(methods) == 5 and methods[4].startswith("nlp-exact from ")
    rows = _read(tmp_path / "flow_vs_nlp.csv")
    for m in methods[1:4]:
        steps = [r for r in rows if r["row"] == "step" and r["method"] == m]
        assert steps and [int(r["step"]) for r in steps] == sorted({int(r["step"]) for r in steps})
    _rerun_recomputes_nothing(mod, tmp_path, monkeypatch, n=16, cap=3.0)
