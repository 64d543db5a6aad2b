"""``branch.detour`` on a closed form: E(x, y; q) = (x - 1)^2 / 2 + (a0 + q) y^2 / 2 - y^4 / 4 + y^6 / 6.

The y = 0 branch ("A", up-down symmetric) is stable for a0 + q > 0; for 0 < a = a0 + q < 1/4 a second,
disconnected pair of minima ("B") sits at y^2 = (1 + sqrt(1 - 4 a)) / 2 (E_y = y (a - y^2 + y^4) = 0;
the roots of y^2 with the minus sign are the barriers), and for a < 0 y = 0 is a saddle whose critical
mode is (0, 1). At q0 = 0, a0 = 0.2, B is reached from A only by the detour in q below -a0.
"""

import math

import numpy as np
import pytest

from vesicle_opt.branch.detour import detour
from vesicle_opt.errors import InputError


def _problem(a0):
    def grad(u, q):
        x, y = u
        return np.array([x - 1, (a0 + q) * y - y**3 + y**5])

    def hess(u, q):
        y = u[1]
        return np.diag([1.0, a0 + q - 3 * y**2 + 5 * y**4])

    def solve(q, start):
        u = np.array([0.0, 0.0]) if start is None else np.array(start["u"], float)
        for _ in range(200):  # Newton with the Hessian shifted to be positive: a minimiser (as IPOPT is)
            g, h = grad(u, q), hess(u, q)
            d = -g / np.maximum(np.diag(h), 0.05)
            u = u + d
            if np.linalg.norm(g) < 1e-13:
                break
        return {"u": u, "q": q, "converged": bool(np.linalg.norm(grad(u, q)) < 1e-12)}

    def check(s):
        w, vec = np.linalg.eigh(hess(s["u"], s["q"]))
        return s["converged"], float(w[0]), vec[:, 0]

    def push(s, mode, a):
        return {"u": s["u"] + a * mode}

    return solve, check, push, (lambda s: abs(s["u"][1]) > 0.1)


def test_detour_reaches_the_disconnected_minimum_at_q0():
    """Out to q = -0.3 (a = -0.1: A a saddle, mu = -0.1), the push lands on B, back to q0 = 0: y^2
    = (1 + sqrt(0.2)) / 2 there (Newton to 1e-13 of a unit-size gradient: 1e-12)."""
    d = detour(*_problem(0.2), q_out=[0.0, -0.1, -0.2, -0.3, -0.4], amplitude=0.1)
    assert d.reached and d.stopped is None
    assert d.switched_at == pytest.approx(-0.3)  # a = -0.1: the first decidedly unstable A
    assert [s.q for s in d.leg("back")] == pytest.approx([-0.2, -0.1, 0.0])
    y = d.end.state["u"][1]
    assert y**2 == pytest.approx((1 + math.sqrt(1 - 4 * 0.2)) / 2, abs=1e-12)
    assert all(abs(s.state["u"][1]) < 1e-12 for s in d.leg("out"))  # A stays symmetric on the way out


def test_detour_says_where_b_ends_short_of_q0():
    """a0 = 0.3: at q0 B does not exist (a > 1/4; it folds at a = 1/4, q = -0.05), so the way back
    stops there and the detour is not reached."""
    d = detour(*_problem(0.3), q_out=[0.0, -0.1, -0.2, -0.3, -0.4], amplitude=0.1)
    assert not d.reached and d.end is None
    assert d.switched_at == pytest.approx(-0.4)
    assert "q = 0.0" in d.stopped  # q -0.1 (a 0.2) still on B; q 0 (a 0.3) falls back to A
    assert d.leg("back")[-2].target and not d.leg("back")[-1].target


def test_detour_without_an_unstable_point_finds_nothing():
    d = detour(*_problem(0.2), q_out=[0.0, -0.1], amplitude=0.1)
    assert not d.reached and d.switched_at is None and "no switch" in d.stopped


@pytest.mark.parametrize("q_out,amp", [([0.0], 0.1), ([0.0, -0.1, 0.0], 0.1), ([0.0, -0.1], 0.0)])
def test_detour_bad_input(q_out, amp):
    with pytest.raises(InputError):
        detour(*_problem(0.2), q_out=q_out, amplitude=amp)


def test_detour_stops_where_a_leaves_its_form():
    """A point of A that ``is_source`` rejects (here every q <= -0.1) ends the detour there, before
    any push: no switch is made from a state that is not A."""
    solve, check, push, is_b = _problem(0.2)
    d = detour(solve, check, push, is_b, q_out=[0.0, -0.1, -0.2, -0.3], amplitude=0.1,
               is_source=lambda s: s["q"] > -0.05)
    assert not d.reached and d.stopped == "A left its form at q = -0.1" and not d.leg("switch")
