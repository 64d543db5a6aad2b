"""The sharp_limit study in quick mode (slow: ~10 s on 2 idle cores, 80 s loaded): certified points,
the monotone approach to the elastica as eps halves, the summary, and resume (a second run
recomputes nothing); a cut-down fast variant runs the two coarsest quick levels."""

from __future__ import annotations

import csv
import math
from concurrent.futures import ThreadPoolExecutor

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
    """Two levels (eps = 0.6, 0.3; under 2 s): rows appended, too few levels to extrapolate."""
    monkeypatch.setitem(mod.QUICK, "epsilons", (0.6, 0.3))
    with ThreadPoolExecutor(1) as pool:  # in this process: no spawned interpreter to start
        assert mod.main(tmp_path, quick=True, executor=pool) == 0
    rows = _read(tmp_path / "sharp_limit.csv")
    assert len(rows) == 2 and all(r["converged"] == "True" for r in rows)
    summary = _read(tmp_path / "sharp_limit_summary.csv")
    assert summary[0]["extrapolated"] == "nan"  # three levels are needed for an order


@pytest.mark.slow
def test_quick_study(tmp_path, monkeypatch):
    assert mod.main(tmp_path, quick=True) == 0
    rows = sorted(_read(tmp_path / "sharp_limit.csv"), key=lambda r: -float(r["epsilon"]))
    assert len(rows) == 3 and all(r["converged"] == "True" and r["second_order"] == "minimum" for r in rows)
    # h proportional to eps with eps/h = 3 (the issue: >= 3)
    assert all(float(r["eps_over_h"]) == pytest.approx(3.0, rel=1e-12) for r in rows)
    ref = elastica.solve(0.8, 24).reduced_energy
    assert all(float(r["reference_energy"]) == pytest.approx(ref, rel=1e-14) for r in rows)
    err = [float(r["error_vs_reference"]) for r in rows]
    # the diffuse energy approaches the elastica from above as eps halves (measured 3.58, 0.44, 0.080)
    assert err[0] > err[1] > err[2] > 0, err
    summary = _read(tmp_path / "sharp_limit_summary.csv")
    assert len(summary) == 1 and float(summary[0]["reference_energy"]) == pytest.approx(ref, rel=1e-14)
    # the coarsest quick level (eps = 0.6) joins its periodic image: no extrapolation, said so
    assert rows[0]["topology"] != "disk-like" and "topology" in summary[0]["status"]
    before = (tmp_path / "sharp_limit.csv").read_bytes()
    monkeypatch.setattr(mod, "run", lambda case: (_ for _ in ()).throw(AssertionError("recomputed")))
    assert mod.main(tmp_path, quick=True) == 0
    assert (tmp_path / "sharp_limit.csv").read_bytes() == before
