"""The study runner (resume, one writer, executors) and each study's quick mode."""

import csv
import inspect
import struct
import subprocess
import sys
import textwrap
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from vesicle_opt.verify.metrics import observed_order, restrict, richardson, richardson_fixed, trig_matrix
import vesicle_opt
from vesicle_opt import cli
from vesicle_opt.errors import InputError
from vesicle_opt.studies import NOT_STUDIES, STUDIES, run_study, study
from vesicle_opt.studies.runner import CsvLog, run_cases

ROOT = Path(__file__).resolve().parents[2]  # the repository (tests/studies/ -> root)


def square_rows(case):
    return [{"scene": "s", "method": "m", "n": case["k"], "energy": case["k"] ** 2},
            {"scene": "s", "method": "m2", "n": case["k"], "energy": -case["k"]}]


def _read(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_resume_after_partial_csv(tmp_path):
    path = tmp_path / "t.csv"
    cases = [{"case": f"c{k}", "k": k} for k in range(5)]
    run_cases("t", cases[:2], square_rows, path, executor=ThreadPoolExecutor(1), show_progress=False)
    header = path.read_text().splitlines()[0].split(",")  # the file's own layout (columns grow over time)
    whole = {"study": "t", "scene": "s", "method": "m", "n": "2", "energy": "4", "case": "c2", "case_rows": "2"}
    with open(path, "a") as f:  # a kill mid-write: one whole row of case c2 and a torn line
        f.write(",".join(whole.get(c, "") for c in header) + "\nt,s,m2,2,,,-")
    rows = run_cases("t", cases, square_rows, path, executor=ThreadPoolExecutor(2), show_progress=False)
    keys = [(r["case"], r["method"]) for r in rows]
    assert len(keys) == len(set(keys)) == 10  # every row of every case exactly once
    assert {r["case"] for r in rows} == {c["case"] for c in cases}


def test_resume_after_killed_process(tmp_path):
    """Kill a real study process mid-run, rerun, and find every row once."""
    path = tmp_path / "k.csv"
    script = textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(ROOT)!r})
        from concurrent.futures import ThreadPoolExecutor
        from vesicle_opt.studies.runner import run_cases
        def slow(case):
            time.sleep(0.3)
            return [{{"n": case["k"], "energy": case["k"]}}]
        run_cases("k", [{{"case": f"c{{k}}", "k": k}} for k in range(20)], slow, {str(path)!r},
                  executor=ThreadPoolExecutor(1), show_progress=False)
    """)
    p = subprocess.Popen([sys.executable, "-c", script])
    deadline = time.time() + 30
    while time.time() < deadline and (not path.exists() or len(path.read_text().splitlines()) < 4):
        time.sleep(0.1)
    p.kill()
    p.wait()
    partial = len(_read(path))
    assert 0 < partial < 20
    rows = run_cases("k", [{"case": f"c{k}", "k": k} for k in range(20)],
                     lambda c: [{"n": c["k"], "energy": c["k"]}], path,
                     executor=ThreadPoolExecutor(1), show_progress=False)
    assert sorted(r["case"] for r in rows) == sorted(f"c{k}" for k in range(20))


def test_failing_case_is_recorded_not_dropped(tmp_path):
    def boom(case):
        raise RuntimeError("no")
    rows = run_cases("b", [{"case": "x"}], boom, tmp_path / "b.csv", executor=ThreadPoolExecutor(1),
                     show_progress=False)
    assert rows[0]["status"].startswith("error: RuntimeError")


def test_process_pool_default_executor(tmp_path):
    rows = run_cases("p", [{"case": f"c{k}", "k": k} for k in range(3)], square_rows, tmp_path / "p.csv",
                     workers=2, show_progress=False)
    assert sorted(float(r["energy"]) for r in rows if r["method"] == "m") == [0.0, 1.0, 4.0]


def test_dask_local_cluster_executor(tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        rows = run_cases("d", [{"case": f"c{k}", "k": k} for k in range(3)], square_rows,
                         tmp_path / "d.csv", executor=client.get_executor(), show_progress=False)
    assert len(rows) == 6 and len({(r["case"], r["method"]) for r in rows}) == 6


def test_csv_has_required_columns(tmp_path):
    log = CsvLog(tmp_path / "c.csv")
    need = ("study scene method n h M energy volume_residual area_residual lambda_volume lambda_area "
            "error_h1 error_energy iterations wall_time_s status").split()
    assert all(c in log.columns for c in need)


def test_trig_restriction_exact_on_trig_polynomials():
    from vesicle_opt.mesh.fd import grid
    box = ((-1.0, 3.0), (0.0, 2.0))
    f, c = grid(box, (36, 24)), grid(box, (20, 16))
    u = lambda X: np.sin(2 * np.pi * (X[:, 0] + 1) / 4 * 3) * np.cos(2 * np.pi * X[:, 1] / 2 * 5)  # noqa: E731
    # modes 3 and 5 are below both Nyquist limits: exact up to round-off (measured ~1e-15)
    assert np.max(np.abs(restrict(f, c, u(f.nodes)) - u(c.nodes))) < 1e-12
    assert np.allclose(trig_matrix(8, 8), np.eye(8), atol=1e-13)  # identity to round-off


def test_richardson_recovers_limit_and_order():
    """E = E_inf + C h^p through three meshes gives back E_inf and p (exact data: to round-off);
    oscillating differences fit no order and give nan."""
    h = np.array([0.2, 0.15, 0.1, 0.075])
    E_inf, p = richardson(h, 3.0 + 0.7 * h**2.0)
    assert E_inf == pytest.approx(3.0, abs=1e-12) and p == pytest.approx(2.0, abs=1e-8)  # brentq xtol 2e-12, cancellation ~1e-13
    E_inf, p = richardson(h[:3], 1.0 - 2.0 * h[:3] ** 1.5)  # from below, p = 1.5
    assert E_inf == pytest.approx(1.0, abs=1e-12) and p == pytest.approx(1.5, abs=1e-8)  # as above
    assert all(map(np.isnan, richardson(h[:3], [1.0, 1.1, 1.0])))


def test_fixed_order_richardson_is_exact_on_its_own_model():
    """E = E_inf + C h^p with p known: the two finest points give E_inf back (to round-off, 1e-13 at
    these magnitudes); with the wrong p it does not (the remaining error is O(h^2 - h^p))."""
    h = np.array([0.2, 0.14, 0.1])
    assert richardson_fixed(h, 1.5 + 0.3 * h**2, 2.0) == pytest.approx(1.5, abs=1e-13)
    assert richardson_fixed(h, 1.5 + 0.3 * h**1.5, 1.5) == pytest.approx(1.5, abs=1e-13)
    assert abs(richardson_fixed(h, 1.5 + 0.3 * h**1.5, 2.0) - 1.5) > 1e-3


def test_observed_order_of_fd_energy_on_a_quick_sequence():
    """Successive energy differences on n = 54, 72, 96 (ratio 4/3): slope = the order.

    Two differences only (fast); the h_refinement quick study fits four meshes (slow test)."""
    from vesicle_opt.studies._common import nlp_for
    from vesicle_opt.api import solve
    ns = [54, 72, 96]
    E, h = [], []
    for n in ns:
        nlp = nlp_for("ellipse-2d", [f"mesh.n={n}"])
        r = solve(nlp)
        assert r.converged
        E.append(r.energy)
        h.append(nlp.disc.h)
    d = np.abs(np.diff(E))
    p = observed_order(h[:-1], d)
    print("FD energies", E, "observed order", p)
    # second-order FD/lumped scheme (Definition 2.2): measured 2.0-2.1 on these meshes; 0.3 allows
    # the O(h^3) terms at the coarse end
    assert abs(p - 2) < 0.3, f"observed order {p:.3f}"


# the figure of each quick study: figsize (inches) x dpi 110 of _common.savefig, in pixels (w, h)
FIGURE_PX = {"penalty_continuation": (660, 495), "diagonal": (1320, 495), "h_refinement": (1650, 495),
             "penalty_vs_exact": (1430, 550)}


@pytest.mark.parametrize("name", ["penalty_continuation",  # ~8 s; the others 30-45 s on 2 shared cores
                                  pytest.param("diagonal", marks=pytest.mark.slow),
                                  pytest.param("h_refinement", marks=pytest.mark.slow),
                                  pytest.param("penalty_vs_exact", marks=pytest.mark.slow)])
def test_quick_study_runs(name, tmp_path):
    mod = study(name)
    status = mod.main(tmp_path, quick=True)
    assert status == 0
    rows = _read(tmp_path / f"{name}.csv")
    assert rows and all(r["status"] and not r["status"].startswith("error") for r in rows)
    png = (tmp_path / f"{name}.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and png[12:16] == b"IHDR"  # a PNG, IHDR first
    assert struct.unpack(">II", png[16:24]) == FIGURE_PX[name]  # its pixel size
    image = imread(tmp_path / f"{name}.png")  # decodes (a truncated file raises)
    assert image.shape[:2] == FIGURE_PX[name][::-1] and np.ptp(image[..., :3]) > 0.5  # not blank: drawn lines
    n_before = len(rows)
    mod.main(tmp_path, quick=True)  # resume: nothing recomputed, nothing duplicated
    assert len(_read(tmp_path / f"{name}.csv")) == n_before


def test_translation_alignment_recovers_a_known_shift():
    from vesicle_opt.mesh.fd import grid
    from vesicle_opt.verify.metrics import field_errors, shift, translation
    d = grid(((-4.0, 4.0), (-4.0, 4.0)), (64, 64))
    # smooth and periodic to ~exp(-25) = 1e-11 at the box edge, resolved (width 0.7 > 5 h)
    u = lambda X: np.exp(-((X[:, 0] / 0.8) ** 2) - (X[:, 1] / 0.7) ** 2)  # noqa: E731
    s = np.array([0.0375, -0.2])
    moved = u(d.nodes - s)  # u(x - s): centred at s
    # the first-mode phase of a shifted field gives the shift up to its periodicity defect (1e-11)
    assert np.allclose(translation(d, moved, u(d.nodes)), s, atol=1e-9)
    # the Fourier shift is spectrally accurate for this resolved field (same 1e-11 defect)
    assert np.max(np.abs(shift(d, moved, s) - u(d.nodes))) < 1e-9
    e = field_errors(d, moved, u(d.nodes))
    assert e["error_h1"] < 1e-8 < 0.1 < e["error_h1_raw"]
    assert e["shift"] == pytest.approx(np.linalg.norm(s), rel=1e-8)


def test_study_list_names_every_registered_study_each_with_a_main(capsys):
    assert cli.main(["study", "--list"]) == 0
    listed = [line.split()[0] for line in capsys.readouterr().out.splitlines()]  # name, then its one line
    assert listed == list(STUDIES)
    for name in listed:
        main = study(name).main
        assert callable(main) and {"out", "quick"} <= set(inspect.signature(main).parameters)
    # every module of vesicle_opt/studies is registered or named as no study
    modules = {p.stem for p in Path(study("table1").__file__).parent.glob("*.py")} - {"__init__"}
    assert modules == set(STUDIES) | set(NOT_STUDIES) and not set(STUDIES) & set(NOT_STUDIES)
    assert study("time-step-convergence") is study("time_step_convergence")
    assert vesicle_opt.run_study is run_study and "run_study" in vesicle_opt.__all__


def test_unknown_study_is_one_line_naming_study_and_the_allowed_names(capsys):
    assert cli.main(["study", "no-such-study", "--out", "unused"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("vesicle-opt: error: study: unknown study 'no-such-study'")
    assert all(name in err for name in STUDIES)
    with pytest.raises(InputError, match="runner"):  # a helper module is no study
        run_study("runner", "unused")


def _children(pid: int) -> list:
    import psutil
    try:
        return psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def _alive(procs) -> list:
    import psutil
    out = []
    for p in procs:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p.pid)
        except psutil.NoSuchProcess:
            pass
    return out


SLEEPY_STUDY = """
import importlib.util, sys, time
# the runner alone (stdlib and numpy), loaded by path: the spawned workers re-run this file and get
# the same module under the same name, without the package's imports (seconds on a loaded machine)
spec = importlib.util.spec_from_file_location("_runner", sys.argv[2])
runner = importlib.util.module_from_spec(spec)
sys.modules["_runner"] = runner
spec.loader.exec_module(runner)
run_cases = runner.run_cases

def sleepy(case):
    open(sys.argv[1] + "." + case["case"] + ".started", "w").close()
    time.sleep(120)
    return [{"scene": "s"}]

if __name__ == "__main__":
    run_cases("sleepy", [{"case": str(k)} for k in range(4)], sleepy, sys.argv[1], workers=2,
              show_progress=False)
"""


def _kill_and_watch(argv, tmp_path, expect_workers: int, started, start_timeout: float = 300.0):
    """Start argv, wait for its pool workers and until ``started()`` (the workers are inside their
    cases: past their imports, which on a loaded machine take seconds, and during which no watcher
    runs yet), SIGKILL it, return the workers alive 5 s later."""
    import os
    import signal
    p = subprocess.Popen(argv, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    workers = []
    while time.time() - t0 < start_timeout:
        workers = [c for c in _children(p.pid) if "multiprocessing" in " ".join(c.cmdline())
                   and "resource_tracker" not in " ".join(c.cmdline())]
        if len(workers) >= expect_workers and started():
            break
        time.sleep(0.2)
    assert len(workers) >= expect_workers and started(), "the pool's workers did not start their cases"
    os.kill(p.pid, signal.SIGKILL)
    p.wait(timeout=10)
    deadline = time.time() + 5.0  # "a few seconds": the workers poll their parent every 0.5 s
    while time.time() < deadline and _alive(workers):
        time.sleep(0.1)
    left = _alive(workers)
    for pid in left:  # never leave them behind, even when the test fails
        os.kill(pid, signal.SIGKILL)
    return left


def test_sigkill_of_a_study_leaves_no_worker(tmp_path):
    script = tmp_path / "sleepy_study.py"
    script.write_text(SLEEPY_STUDY)
    csv_path = tmp_path / "s.csv"
    runner_file = Path(vesicle_opt.__file__).parent / "studies" / "runner.py"
    left = _kill_and_watch([sys.executable, str(script), str(csv_path), str(runner_file)], tmp_path, expect_workers=2,
                           started=lambda: len(list(tmp_path.glob("s.csv.*.started"))) >= 2)
    assert not left, f"workers outlived the SIGKILLed study by 5 s: {left}"


@pytest.mark.slow
def test_sigkill_of_a_real_study_through_the_cli_leaves_no_worker(tmp_path):
    argv = [sys.executable, "-m", "vesicle_opt.cli", "study", "stress", "--quick", "--out", str(tmp_path / "o")]
    rows = tmp_path / "o" / "stress.csv"
    left = _kill_and_watch(argv, tmp_path, expect_workers=1,  # a case finished: the worker is past its imports
                           started=lambda: rows.exists() and len(rows.read_text().splitlines()) >= 2)
    assert not left, f"workers outlived the SIGKILLed study by 5 s: {left}"
