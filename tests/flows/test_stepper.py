"""The time loop's execution environment: every step runs with one BLAS thread (``flows.stepper.run``),
whatever the process default, and the default is back after the run."""

import numpy as np
from threadpoolctl import threadpool_info, threadpool_limits

from vesicle_opt.flows.base import StepOutcome
from vesicle_opt.flows.stepper import StepperOptions, run


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


class _Recorder:
    """A scheme that decays phi and records the BLAS thread counts its steps saw."""

    def __init__(self):
        self.seen = []

    def step(self, phi, k, guess):
        self.seen.append(_blas_threads())
        return StepOutcome(phi / (1 + k), True, 1, "ok", 0.0, law_ok=True)

    def observe(self, phi):
        return {"energy": float(phi @ phi)}


def test_steps_run_with_one_blas_thread():
    with threadpool_limits(limits=2, user_api="blas"):  # a two-thread default, as on a 2-core machine
        before = _blas_threads()
        sch = _Recorder()
        out = run(sch, np.ones(8), StepperOptions(dt=0.1, t_end=0.3, max_steps=10))
        after = _blas_threads()
    assert out.status.value == "t_end" and len(sch.seen) == 3
    assert all(counts and set(counts) == {1} for counts in sch.seen), sch.seen  # every step: one thread
    assert after == before  # restored after the run
