"""The closed elastica reference (vesicle_opt.sharp.elastica) against closed forms, its own
refinement, the sharp Euler-Lagrange equation, the envelope identity and the full-space second-order
check."""

from __future__ import annotations

import numpy as np
import pytest

from vesicle_opt.sharp import elastica as E


@pytest.mark.parametrize("n", [2, 4])
def test_small_deformation_slope_is_n2_minus_1(n):
    """e = 1 + (n^2 - 1)(1 - nu) + O((1 - nu)^2): (e - 1)/(1 - nu) fitted linearly in 1 - nu."""
    d = np.array([1e-3, 2e-3, 4e-3])
    e = np.array([E.solve(1 - x, 8, symmetry=n).reduced_energy for x in d])
    _, intercept = np.polyfit(d, (e - 1) / d, 1)
    # the fit's error is the O(d^2) term of (e - 1)/d (coefficient O(n^2)): < 1e-4 n^2 here
    # (measured |intercept - (n^2 - 1)| = 1.7e-6 for n = 2, 1.4e-5 for n = 4)
    assert intercept == pytest.approx(-E.small_deformation_slope(n), abs=1e-4 * n**2), intercept


@pytest.mark.parametrize("nu", [0.9, 0.7, 0.5])
def test_one_mode_trial_curve_bounds_the_energy_from_above(nu):
    e = E.solve(nu).reduced_energy
    bound = E.one_mode_energy(nu)
    # the one-mode curve is in the same class, so it cannot be lower; the gap is the higher modes'
    # contribution, measured 6e-4 (0.9) ... 3e-2 (0.5), far above the 1e-12 round-off of both
    assert e < bound - 1e-6, (e, bound)
    assert E.one_mode_nu(0.0, 2) == pytest.approx(1.0, abs=1e-15)  # the circle (J_0(0) = 1)


def test_spectral_convergence_in_the_number_of_modes():
    ref = E.solve(0.6, 24).reduced_energy
    N = np.arange(2, 8)
    err = np.array([abs(E.solve(0.6, int(n)).reduced_energy - ref) for n in N])
    slope, _ = np.polyfit(N, np.log10(err), 1)
    # geometric (spectral) decay: measured 1.6 decades per mode (5e-4 at N = 2 -> 6e-12 at N = 7);
    # an algebraic rate would flatten to < 0.5 decades per mode over this range
    assert slope < -1.0, (slope, err)
    assert err[-1] < 1e-10, err  # measured 5.9e-12


@pytest.mark.parametrize("nu", [0.95, 0.7, 0.5])
def test_sharp_euler_lagrange_equation_holds(nu):
    el = E.solve(nu)
    assert el.converged and el.kkt_residual < 1e-12  # Newton on the KKT system: round-off (1e-16 measured)
    r = E.euler_lagrange_residual(el)
    # 2 kappa'' + kappa^3 - sigma kappa - p = 0 is not used by the discretisation; measured 4e-14
    assert r["residual"] < 1e-11, r


def test_envelope_identity_de_dnu_is_the_multiplier():
    el, h = E.solve(0.7), 1e-4
    fd = (E.solve(0.7 + h).reduced_energy - E.solve(0.7 - h).reduced_energy) / (2 * h)
    # central difference error O(h^2 e''') ~ 1e-8 (measured 6.5e-9)
    assert el.lam == pytest.approx(fd, abs=1e-7)


@pytest.mark.parametrize("nu, symmetry, n_modes", [(0.6, 2, 16),
                                                   pytest.param(0.84, 4, 16, marks=pytest.mark.slow)])
def test_full_space_second_order_minimum_for_n2_saddle_for_n4(nu, symmetry, n_modes):
    """n = 2: a minimum among all curves; n = 4 (the square-symmetric branch): a saddle."""
    check = E.full_space_check(E.solve(nu, n_modes, symmetry=symmetry))
    # first order in the full space, multipliers by least squares: the symmetric solve's truncation
    # error at these N, measured 1.5e-13 (n = 2; 9e-8 at N = 10) and 3.7e-15 (n = 4)
    assert check["kkt"] < 1e-10, check
    assert check["closure"] < 1e-14  # closed by construction
    # measured +4.1 and -20.2 (bending units of the 2 pi-perimeter curve): far from 0 either way
    if symmetry == 2:
        assert check["minimum"] and check["min_eigenvalue"] > 1.0
    else:
        assert not check["minimum"] and check["min_eigenvalue"] < -1.0


def test_curve_has_the_perimeter_and_reduced_area():
    el = E.solve(0.7)
    x, y = el.curve(perimeter=3.0, m=4096)
    dx, dy = np.diff(np.append(x, x[0])), np.diff(np.append(y, y[0]))
    length = np.sum(np.hypot(dx, dy))
    area = 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    # polygon through 4096 points of a smooth curve: O(1/m^2) ~ 1e-6 relative (measured ~1e-7)
    assert length == pytest.approx(3.0, rel=1e-5)
    assert 4 * np.pi * area / length**2 == pytest.approx(0.7, rel=1e-5)


def test_bad_reduced_area_refused():
    with pytest.raises(ValueError, match="nu"):
        E.solve(1.2)
    with pytest.raises(ValueError, match="symmetry"):
        E.solve(0.8, symmetry=1)
