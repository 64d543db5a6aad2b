"""The transition line in two parameters (``branch.transition``) on a closed form: two branches whose
energy crossing p*(q) = c(q) is known, continued in q; and the line's files resumed after a kill."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from vesicle_opt.branch.transition import Sample, continue_line, plan
from vesicle_opt.branch.transition_store import LineStore


def c_of(q):  # the crossing's closed form: nonlinear in q, so the secant predictor is not exact
    return 0.65 - 0.17 * q + 0.05 * q * q


class Crossing:
    """Branches a and b of E_x(u; p, q) = e_x(p, q) + |u - u_x(p, q)|^2 / 2 on R^2, with
    e_a = p^2 + q and e_b = e_a - (p - c(q)) exp(p): Delta = e_a - e_b = (p - c(q)) exp(p), zero at
    p = c(q) only; u_a = (p, q), u_b = (-p, q). A solve is one Newton step (exact: E is quadratic in
    u); ``fail_at``: a q where branch b's solve fails (an honest failure)."""

    disc = SimpleNamespace(grid_shape=None, box=[[0.0, 1.0]], nodes=[[0.0], [1.0]], dim=1)

    def __init__(self, fail_at=None):
        self.fail_at, self.solves = fail_at, 0

    def solve(self, x, p, q, phi0, lam0):
        self.solves += 1
        u = np.array([p if x == "a" else -p, q])
        e = p * p + q
        de_dp, de_dq = 2 * p, 1.0
        if x == "b":
            e -= (p - c_of(q)) * math.exp(p)
            de_dp -= (1 + p - c_of(q)) * math.exp(p)
            de_dq += (-0.17 + 0.1 * q) * math.exp(p)
        ok = not (x == "b" and self.fail_at is not None and abs(q - self.fail_at) < 1e-12)
        row = {"outcome": "converged" if ok else "max_iterations", "reason": None if ok else "toy failure",
               "reduced_energy": e, "f": e, "c0_reduced": 2 * q}
        return Sample(p, q, u, e, ok, (de_dp, 0.0), de_dp, de_dq, row)


VALUES = [-0.5, -0.25, 0.25, 0.5, 0.75, 1.0]


def test_the_continued_line_is_the_closed_form():
    toy = Crossing()
    rows = continue_line(toy, 0.0, 0.70, 0.5, VALUES, 0.02, LineStore(None, {}, toy.disc, "q", "p"))
    assert [r["value"] for r in rows] == [q for _, q in plan(0.0, VALUES)]
    assert all(r["converged"] and r["a_converged"] and r["b_converged"] for r in rows)
    for r in rows:
        # 4-point cubic spline of Delta = (p - c) e^p with samples dp = 0.02 apart: interpolation
        # error ~ |Delta''''| dp^4 / 24 ~ 3e-8 in Delta, / |Delta'| ~ e^0.65 in p (measured: 8e-9 at
        # the start, whose samples are not centred; <= 2e-11 after)
        assert r["target"] == pytest.approx(c_of(r["value"]), abs=2e-8)
        assert r["gap"] < 1e-7  # the same error in Delta, relative to E ~ 0.4 .. 1.4
    # the predictor (tangent, then secant) lands within the Newton step's reach: 4 samples a q
    assert all(r["samples"] == 4 for r in rows[1:]), [r["samples"] for r in rows]
    up = [r for r in rows if r["direction"] == "up"]
    # the tangent from the envelope derivatives is exact to first order: its error is c''/2 dq^2
    assert up[0]["predicted"] - up[0]["target"] == pytest.approx(-0.05 * 0.25**2, abs=1e-7)
    # the secant through q - dq, q - 2 dq misses the quadratic c by c''/2 (dq)(2 dq) exactly
    assert all(r["predicted"] - r["target"] == pytest.approx(-0.05 * 0.25 * 0.5, abs=1e-7) for r in up[1:])


def test_a_failure_ends_its_direction_only():
    toy = Crossing(fail_at=0.5)
    rows = continue_line(toy, 0.0, 0.70, 0.5, VALUES, 0.02, LineStore(None, {}, toy.disc, "q", "p"))
    bad = [r for r in rows if not r["converged"]]
    assert [r["value"] for r in bad] == [0.5] and bad[0]["reason"].startswith("branch b not certified")
    assert bad[0]["outcome"] == "max_iterations" and bad[0]["target"] is None  # never a crossing
    assert [r["value"] for r in rows if r["direction"] == "up"] == [0.25, 0.5]  # 0.75, 1.0 not tried
    assert [r["value"] for r in rows if r["direction"] == "down"] == [-0.25, -0.5]


@pytest.mark.parametrize("cut, fail_at", [(1, None), (3, None), (5, None), (1, 0.5), (2, 0.5), (3, 0.5)])
def test_resume_after_a_kill_loses_and_duplicates_no_row(tmp_path, cut, fail_at):
    # fail_at 0.5: the up direction stops at its second value, so the plan indices of the rows skip
    def run(out):
        toy = Crossing(fail_at)
        store = LineStore(out, {"toy": "crossing", "values": VALUES}, toy.disc, "q", "p")
        return continue_line(toy, 0.0, 0.70, 0.5, VALUES, 0.02, store), toy.solves

    whole, solves = run(tmp_path / "whole")
    out = tmp_path / "cut"
    run(out)
    lines = (out / "transition_line.csv").read_text().splitlines(keepends=True)
    # killed while writing row `cut`: the rows before it whole, half of its line
    (out / "transition_line.csv").write_text("".join(lines[: cut + 1]) + lines[cut + 1][:25])
    resumed, more = run(out)
    key = lambda r: {k: v for k, v in r.items() if k != "wall_time_s"}  # noqa: E731
    assert [key(r) for r in resumed] == [key(r) for r in whole]
    assert more < solves  # the rows before the cut were not recomputed
    assert (out / "transition_line.csv").read_text().count("\n") == len(whole) + 1


def test_a_resume_under_other_arguments_is_refused(tmp_path):
    toy = Crossing()
    LineStore(tmp_path, {"values": [1.0]}, toy.disc, "q", "p")
    with pytest.raises(Exception, match="other values"):
        LineStore(tmp_path, {"values": [2.0]}, toy.disc, "q", "p")


@pytest.mark.parametrize("args, flag", [
    (["--param", "reduced_volume", "--to", "0.7"], "--second"),  # no second parameter
    (["--param", "reduced_volume", "--to", "0.7", "--second", "reduced_volume", "--values", "0.1"], "--second"),
    (["--param", "c0", "--to", "0.7", "--second", "c0", "--values", "0.1"], "--param"),
    (["--param", "reduced_volume", "--to", "0.7", "--second", "c0"], "--values"),
    (["--param", "reduced_volume", "--to", "0.7", "--second", "c0", "--values", "0.1", "--set",
      "mesh.n=[10,20]", "--transition", "model.epsilon=0.2"], "--transition"),  # not the same problem
    (["--param", "reduced_volume", "--to", "1.5", "--second", "c0", "--values", "0.1"], "--to"),
])
def test_bad_transition_input_is_one_line_exit_2_before_any_work(tmp_path, capsys, args, flag):
    from vesicle_opt.cli import main
    out = tmp_path / "out"
    out.mkdir()
    transition = [] if "--transition" in args else ["--transition", "initial.semi_axes=[1.3,1.3,0.5]"]
    code = main(["branch", "prolate-axisymmetric", "--out", str(out), *transition, *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and flag in err[0], err
    assert list(out.iterdir()) == []  # nothing written


def s_of(q):  # the fold's closed form
    return 0.2 + 0.3 * q + 0.2 * q * q


class FoldToy:
    """E(x, y; p, q) = x^3/3 - (p - s(q)) x + (y - 1)^2/2: the stable branch x = sqrt(p - s(q)) for
    p >= s(q), a fold at p = s(q) where the least Hessian eigenvalue mu = 2x vanishes, mu^2 = 4 (p - s)
    exactly; dE/dp = -x, so p = s + (dE/dp)^2 exactly; E = -(2/3) (p - s)^(3/2) on the branch, 0 at
    the fold. No real point below the fold."""

    def __init__(self):
        self.solves = 0

    def solve(self, x, p, q, phi0, lam0):
        self.solves += 1
        d = p - s_of(q)
        if d < 0:
            return Sample(p, q, np.zeros(2), math.nan, False, row={"outcome": "max_iterations", "reason": "toy"})
        u = np.array([math.sqrt(d), 1.0])
        mu = min(2 * u[0], 1.0)
        return Sample(p, q, u, -2 / 3 * d**1.5, True, (0.0, 0.0), -u[0], None,  # dE/dp = -x (envelope)
                      {"second_order_min_eigenvalue": mu})


def test_the_continued_fold_line_is_the_closed_form():
    from vesicle_opt.branch.fold_continuation import fold_line
    toy = FoldToy()
    # the start predicted 0.05 too high, and 0.02 beyond the fold at q = 0 (p = 0.18 < s = 0.2): shifted back
    folds = fold_line(toy, 0.0, 0.25, [0.25, 0.5, -0.25, -0.5], 0.01, +1)
    assert [f.q for f in folds] == [0.0, 0.25, 0.5, -0.25, -0.5] and all(f.converged for f in folds)
    for f in folds:
        # p = s + g^2 exactly: the parabola's vertex is s to round-off (measured <= 1e-15)
        assert f.p == pytest.approx(s_of(f.q), abs=1e-12)
        assert f.energy == pytest.approx(0.0, abs=1e-12)  # dE = g p'(g) dg integrated exactly
        assert f.p_mu == pytest.approx(s_of(f.q), abs=1e-12)  # the cross-check: mu^2 = 4 (p - s)
        assert f.nearest.p > f.p and f.nearest.converged
    overshoot = FoldToy()
    f = fold_line(overshoot, 0.0, 0.18, [], 0.01, +1)[0]
    assert f.p == pytest.approx(0.2, abs=1e-12) and f.samples > 3  # the failed sample's shift


def test_a_branch_without_a_fold_is_not_given_one():
    from vesicle_opt.branch.fold_continuation import local_fold

    class Stable(FoldToy):  # E = p^2 / 2 + ..., dE/dp = p: p(g) = g, no turning point
        def solve(self, x, p, q, phi0, lam0):
            return Sample(p, q, np.zeros(2), p * p / 2, True, (0.0, 0.0), p, None,
                          {"second_order_min_eigenvalue": 1.0})
    f = local_fold(Stable(), 0.0, 0.5, 0.01, None, +1)
    assert not f.converged and f.p is None and "no fold" in f.reason


def test_a_gap_the_polish_cannot_close_is_reported_not_hidden():
    class Jumpy(Crossing):  # branch b's energy carries 1e-3 of state noise (its derivative does not see it)
        def solve(self, x, p, q, phi0, lam0):
            s = super().solve(x, p, q, phi0, lam0)
            if x == "b":
                s.energy += 1e-3 * math.sin(1e6 * p)
            return s
    toy = Jumpy()
    rows = continue_line(toy, 0.0, 0.70, 0.5, [], 0.02, LineStore(None, {}, toy.disc, "q", "p"))
    r = rows[0]
    assert r["converged"] and r["outcome"] == "located_to_gap" and r["gap"] > 1e-6
    assert "uncertain by" in r["reason"]
