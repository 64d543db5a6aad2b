"""SIGINT / SIGTERM of a study's runner while its pool's workers are inside their cases: the parent
ends at once (not after the cases) with 128 + the signal, the workers end with it, and the CSV holds
the finished case only (the rerun resumes after it)."""

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = """
import sys, time
from pathlib import Path
from vesicle_opt.io import interrupt
from vesicle_opt.studies.runner import run_cases

def case_rows(case):
    if case["case"] != "quick":
        Path(sys.argv[1] + "." + case["case"] + ".started").touch()
        time.sleep(120)
    return [{"scene": "s", "energy": 1.0}]

if __name__ == "__main__":
    try:
        with interrupt.handled():
            run_cases("sleepy", [{"case": c} for c in ("quick", "a", "b")], case_rows, sys.argv[1], workers=2,
                      show_progress=False)
    except KeyboardInterrupt as exc:
        print(interrupt.message(exc.signum), file=sys.stderr)
        sys.exit(128 + exc.signum)
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)])  # ~13 s each
def test_an_interrupted_runner_ends_its_workers_and_keeps_only_finished_cases(tmp_path, sig):
    script = tmp_path / "sleepy.py"
    script.write_text(SCRIPT)
    path = tmp_path / "sleepy.csv"
    p = subprocess.Popen([sys.executable, str(script), str(path)], cwd=tmp_path, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    t0 = time.time()
    while time.time() - t0 < 300 and len(list(tmp_path.glob("sleepy.csv.*.started"))) < 1:
        time.sleep(0.1)
    workers = [c for c in psutil.Process(p.pid).children(recursive=True) if "resource_tracker" not in " ".join(c.cmdline())]
    assert workers, "no pool worker started"
    t1 = time.time()
    p.send_signal(sig)
    err = p.stderr.read()
    code = p.wait(timeout=60)
    ended = time.time() - t1
    gone, alive = psutil.wait_procs(workers, timeout=5)  # they were terminated, not left to their 120 s
    for w in alive:
        w.kill()
    assert code == 128 + sig and not alive and ended < 30, (code, err, ended)  # 30 s: imports on a busy machine
    assert "rerun the same command to resume" in err and "Traceback" not in err, err
    with open(path) as fh:
        assert [r["case"] for r in csv.DictReader(fh)] in ([], ["quick"])  # no row of an unfinished case
