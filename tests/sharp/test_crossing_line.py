"""The sharp prolate/oblate crossing line (``sharp.crossing_line``) against the independent
up-down symmetric code at c0 = 0, and the sign of its slope (positive c0 favours the prolate)."""

import pytest

from vesicle_opt.sharp import axisymmetric as A
from vesicle_opt.sharp import crossing_line as L


@pytest.mark.slow  # ~85 CPU-s (measured): two brentq walks of SLSQP solves
def test_the_line_starts_at_the_symmetric_codes_crossing_and_falls_with_c0():
    v_ref, f_ref = A.crossing(12)
    line = L.line([0.0, 0.1], n_modes=24)
    assert all(x["converged"] for x in line)
    # two codes (closure by constraint / by symmetry), the same minimisers: brentq's xtol 1e-10 and
    # 12 vs 12 symmetric modes (the general code's 24 hold the same even wavenumbers)
    assert line[0]["v"] == pytest.approx(v_ref, abs=1e-7) and line[0]["f"] == pytest.approx(f_ref, abs=1e-7)
    # the prolate's larger total mean curvature: df/dc0 = -(1/8 pi) int H dA is more negative for it, so
    # c0 > 0 lowers the prolate more and the crossing moves to lower v (measured -0.0174 at c0 = 0.1)
    assert -0.02 < line[1]["v"] - line[0]["v"] < -0.015
