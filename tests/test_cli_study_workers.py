"""``vesicle-opt study NAME --workers N`` and ``--scheduler ADDRESS``: bad values are one line and exit 2
before any work (the output directory is not made); a dask scheduler's workers run the cases."""

import types

import pytest

from vesicle_opt import cli
from vesicle_opt import studies as studies_pkg
from vesicle_opt.studies import runner
from vesicle_opt.studies.runner import run_cases


def _one_line(capsys, flag):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and flag in err[0] and "Traceback" not in err[0], err
    return err[0]


@pytest.mark.parametrize("value", ["0", "-2", "two", "1.5"])
def test_bad_worker_counts_are_one_line(value, tmp_path, capsys):
    out = tmp_path / "o"
    assert cli.main(["study", "phase_diagram", "--quick", "--out", str(out), "--workers", value]) == 2
    _one_line(capsys, "--workers")
    assert not out.exists()  # refused before the directory is made


def test_workers_on_a_one_process_study_names_the_parallel_ones(tmp_path, capsys):
    out = tmp_path / "o"
    assert cli.main(["study", "table1", "--quick", "--out", str(out), "--workers", "2"]) == 2
    line = _one_line(capsys, "--workers")
    assert "table1" in line and "phase_diagram" in line and "energy_diagram" in line
    assert not out.exists()


def test_workers_and_scheduler_exclude_each_other(tmp_path, capsys):
    argv = ["study", "phase_diagram", "--quick", "--out", str(tmp_path / "o"), "--workers", "2",
            "--scheduler", "tcp://127.0.0.1:1"]
    assert cli.main(argv) == 2
    _one_line(capsys, "--scheduler")


def test_a_scheduler_that_does_not_answer_is_one_line(tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(runner, "SCHEDULER_TIMEOUT_S", 1.0)  # nothing listens on port 1: fail fast
    called = []

    def main(out, quick=False, executor=None, workers=1):
        called.append(1)

    monkeypatch.setattr(studies_pkg, "study", lambda name: types.SimpleNamespace(main=main))
    assert cli.main(["study", "phase_diagram", "--out", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "no dask scheduler" in _one_line(capsys, "--scheduler") and not called


def _square(case):
    return [{"method": "m", "energy": case["k"] ** 2, "scene": str(case["k"])}]


def test_scheduler_runs_the_cases_on_dask_workers(tmp_path, monkeypatch):
    """The CLI's --scheduler reaches the study's main as an executor of that cluster: the cases run
    there, their rows in the study CSV (a stand-in study, so that the check takes ~2 s)."""
    distributed = pytest.importorskip("distributed")
    seen = {}

    def main(out, quick=False, executor=None, workers=1):
        seen["executor"] = type(executor).__name__
        rows = run_cases("fake", [{"case": f"c{k}", "k": k} for k in range(4)], _square, out / "fake.csv",
                         executor=executor, show_progress=False)
        seen["energies"] = sorted(float(r["energy"]) for r in rows)
        return 0

    monkeypatch.setattr(studies_pkg, "study", lambda name: types.SimpleNamespace(main=main))
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster:
        assert cli.main(["-q", "study", "phase_diagram", "--out", str(tmp_path / "o"),
                         "--scheduler", cluster.scheduler_address]) == 0
    assert seen == {"executor": "ClientExecutor", "energies": [0.0, 1.0, 4.0, 9.0]}
