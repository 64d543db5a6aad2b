"""CasADi's own line for a Ctrl-C it turned into a status (``io.interrupt.casadi_line_absorbed``): gone
inside the block once a signal was received, kept otherwise; every other write passes at once."""

import contextlib
import io
import os
import signal
import sys
import threading

import pytest

from vesicle_opt.io import interrupt

# the pieces CasADi 3.6 writes for it, recorded from a real interrupted IPOPT call (one write each)
PIECES = ["CasADi - ", "2026", "-", "12", "-", "03", " ", "15", ":", "53", ":", "35", ' WARNING("',
          "KeyboardInterruptException", '") [', ".../casadi/interfaces/ipopt/ipopt_nlp.cpp:95", "]\n"]


def _through_filter(writes, signalled: bool) -> str:
    out = io.StringIO()
    f = interrupt._CasadiLineFilter(out)
    interrupt._state["signum"] = signal.SIGINT if signalled else None
    try:
        for w in writes:
            assert f.write(w) == len(w)
        f.release()
    finally:
        interrupt.reset()
    return out.getvalue()


def test_the_interrupt_line_is_dropped_and_everything_else_kept():
    other = ["CasADi - ", "2026-12-03", ' WARNING("', "Some other warning", '")', "\n"]
    bar = ["\r 40%|####      | 4/10", "\r 50%|#####     | 5/10"]
    text = _through_filter(bar + PIECES + other + ["vesicle-opt: interrupted (SIGINT) during the solve\n"], True)
    assert text == "".join(bar + other) + "vesicle-opt: interrupted (SIGINT) during the solve\n"
    # without a signal received the same line is CasADi's to say (it cannot come from us)
    assert _through_filter(PIECES, False) == "".join(PIECES)
    assert _through_filter(["CasADi - ", "held, no newline yet"], True) == "CasADi - held, no newline yet"


def test_a_real_interrupted_ipopt_call_prints_only_our_line(capsys):
    """A small CasADi/IPOPT solve that runs for seconds, SIGINT to this process after 0.2 s: inside
    ``handled()`` CasADi returns a status; without the filter its line reaches stderr (the control),
    with it nothing but what the run says itself."""
    ca = pytest.importorskip("casadi")
    x = ca.MX.sym("x", 200)  # Rosenbrock in 200 variables on L-BFGS: ~600 iterations, 1-3 s (measured)
    f = ca.sumsqr(100 * (x[1:] - x[:-1] ** 2)) + ca.sumsqr(1 - x[:-1])
    solver = ca.nlpsol("s", "ipopt", {"x": x, "f": f},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": 100000,
                        "ipopt.tol": 1e-300, "ipopt.hessian_approximation": "limited-memory"})

    def solve(absorb: bool) -> tuple[str, str]:
        capsys.readouterr()
        timer = threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT))
        with interrupt.handled():
            block = interrupt.casadi_line_absorbed() if absorb else contextlib.nullcontext()
            with block:
                timer.start()
                solver(x0=-1.2)
                timer.join()
                with pytest.raises(interrupt.Interrupted):
                    interrupt.check()  # the record stays after CasADi swallowed the exception
        assert sys.stderr is not None
        return solver.stats()["return_status"], capsys.readouterr().err

    status, err = solve(absorb=False)
    assert status == "NonIpopt_Exception_Thrown" and "KeyboardInterruptException" in err, (status, err)
    status, err = solve(absorb=True)
    assert status == "NonIpopt_Exception_Thrown" and err == "", (status, err)
