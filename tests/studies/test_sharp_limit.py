"""The sharp_limit study in quick mode (slow: ~10 s on 2 idle cores): certified points, the
monotone approach to the elastica as eps halves, the summary, and resume (a second run recomputes
nothing); fast: the two coarsest quick levels, the spectral grid error against the eps error, the
order fit on a closed-form sequence, and the per-level tolerance."""

from __future__ import annotations

import csv
import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from vesicle_opt.sharp import elastica
from vesicle_opt.studies import sharp_limit as mod


def _read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_ellipse_start_has_the_perimeter_and_reduced_area():
    a, b = mod.ellipse_axes(0.8, mod.PERIMETER)
    h = ((a - b) / (a + b)) ** 2  # Ramanujan's second formula: relative error ~3h^5/2^17, ~1e-10 here
    per = math.pi * (a + b) * (1 + 3 * h / (10 + math.sqrt(4 - 3 * h)))
    assert per == pytest.approx(mod.PERIMETER, rel=1e-8)
    assert 4 * math.pi * (math.pi * a * b) / mod.PERIMETER**2 == pytest.approx(0.8, rel=1e-12)


def test_two_coarse_levels_fast(tmp_path, monkeypatch):
    """Two levels (eps = 0.6, 0.3; a few s): rows appended, too few levels to extrapolate."""
    monkeypatch.setitem(mod.QUICK, "epsilons", (0.6, 0.3))
    with ThreadPoolExecutor(1) as pool:  # in this process: no spawned interpreter to start
        assert mod.main(tmp_path, quick=True, executor=pool) == 0
    rows = _read(tmp_path / "sharp_limit.csv")
    assert len(rows) == 2 and all(r["converged"] == "True" for r in rows)
    assert all(r["mesh"] == "spectral" and r["backend"] == "newton-krylov" for r in rows)
    summary = _read(tmp_path / "sharp_limit_summary.csv")
    assert summary[0]["extrapolated"] == "nan"  # three levels are needed for an order


def test_spectral_grid_error_is_far_below_the_eps_error():
    """At eps = 0.3, doubling eps/h from 3 to 6 moves the reduced energy by round-off of the solve
    only (measured 5e-9), while halving eps from 0.6 moves it by 3.35: the sequence's error is eps's."""
    run = lambda eps, r: mod.run({"nu": 0.8, "epsilon": eps, "eps_over_h": r})[0]  # noqa: E731
    coarse, fine, wide = run(0.3, 3.0), run(0.3, 6.0), run(0.6, 3.0)
    assert all(p["converged"] and p["second_order"] == "minimum" for p in (coarse, fine, wide))
    grid = abs(fine["reduced_energy"] - coarse["reduced_energy"])
    # 1e-7: ten times the solver's tol (1e-8) bounds the energy's solve error; the tanh profile's
    # spectral error at eps/h = 3 is ~exp(-21) ~ 1e-9 (module docstring)
    assert grid < 1e-7, grid
    assert abs(wide["reduced_energy"] - coarse["reduced_energy"]) > 1e6 * grid


def test_polyfit_order_recovers_a_known_order():
    eps = np.array([0.2, 0.1, 0.05, 0.025])
    e = 1.3 + 2.0 * eps**2  # differences 2 eps_k^2 (1 - 1/4): slope exactly 2 in log-log
    assert mod.polyfit_order(eps, e) == pytest.approx(2.0, abs=1e-12)  # a least-squares line through exact points
    assert math.isnan(mod.polyfit_order(eps[:2], e[:2]))  # one difference fits no line


def test_tolerance_stays_above_the_measured_floor_scaling():
    assert mod.tol_for(0.2) == mod.tol_for(0.1) == 1e-8
    # floors measured at eps/h = 3.2: 1.9e-9 (eps 0.1), 1.6e-8 (eps 0.05); eps^-3 beyond
    assert mod.tol_for(0.05) >= 5 * 1.6e-8 and mod.tol_for(0.025) >= 5 * 1.6e-8 * 8
    assert mod.tol_for(0.2, 6.4) >= 5 * 3.4e-9  # the floor measured at eps = 0.2, eps/h = 6.4


def test_grid_checks_pair_with_their_sequence_point():
    rows = [{"nu": "0.8", "epsilon": "0.2", "eps_over_h": "3.2", "reduced_energy": "1.5", "role": "sequence"},
            {"nu": "0.8", "epsilon": "0.2", "eps_over_h": "6.4", "reduced_energy": "1.5000001",
             "role": "grid_check"}]
    (key, (r, d)), = mod.grid_checks(rows).items()
    assert key == (0.8, 0.2) and r == 6.4 and d == pytest.approx(1e-7, rel=1e-6)  # float parse of "1.5000001"


@pytest.mark.slow
def test_quick_study(tmp_path, monkeypatch):
    assert mod.main(tmp_path, quick=True) == 0
    rows = sorted(_read(tmp_path / "sharp_limit.csv"), key=lambda r: -float(r["epsilon"]))
    assert len(rows) == 3 and all(r["converged"] == "True" and r["second_order"] in mod.ACCEPTED for r in rows)  # marginal: the flat rotation at the finest eps
    # h proportional to eps with eps/h = 3 (the issue: >= 3)
    assert all(float(r["eps_over_h"]) == pytest.approx(3.0, rel=1e-12) for r in rows)
    ref = elastica.solve(0.8, 24).reduced_energy
    assert all(float(r["reference_energy"]) == pytest.approx(ref, rel=1e-14) for r in rows)
    err = [float(r["error_vs_reference"]) for r in rows]
    # the diffuse energy approaches the elastica from above as eps halves (measured 3.80, 0.449, 0.088)
    assert err[0] > err[1] > err[2] > 0, err
    summary = _read(tmp_path / "sharp_limit_summary.csv")
    assert len(summary) == 1 and float(summary[0]["reference_energy"]) == pytest.approx(ref, rel=1e-14)
    assert summary[0]["status"] == "certified" and all(r["topology"] == "disk-like" for r in rows)
    before = (tmp_path / "sharp_limit.csv").read_bytes()
    monkeypatch.setattr(mod, "run", lambda case: (_ for _ in ()).throw(AssertionError("recomputed")))
    assert mod.main(tmp_path, quick=True) == 0
    assert (tmp_path / "sharp_limit.csv").read_bytes() == before
