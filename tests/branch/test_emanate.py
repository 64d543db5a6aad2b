"""``branch.emanate`` on a closed form: E(x, y; p) = p x^2 / 2 - x^4 / 4 + x^6 / 6 + (y - x^2)^2 / 2.

The trivial branch u = 0 is a minimum for p > 0 and loses stability at p* = 0 (mode (1, 0)); the
branch leaving it, y = x^2, p = x^2 - x^4, is subcritical (p > 0 near x = 0, where the trivial branch
is still stable, and a saddle there: E_xx = -2 x^2 + 4 x^4), turns at a fold p = 1/4 (x^2 = 1/2) and
comes back as minima (x^2 > 1/2): a minimiser started off the trivial branch never finds its first
part, a pseudo-arclength walk does. The test corrector is exact Newton on the bordered system."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from vesicle_opt.branch.emanate import follow
from vesicle_opt.errors import InputError

W = np.array([1.0, 1.0])
TOL = 1e-12  # Newton's step tolerance: quadratic convergence from the predictor, round-off below


def grad(u, p):
    x, y = u
    return np.array([p * x - x**3 + x**5 - 2 * x * (y - x**2), y - x**2])


def hess(u, p):
    x, y = u
    return np.array([[p - 3 * x**2 + 5 * x**4 - 2 * (y - x**2) + 4 * x**2, -2 * x], [-2 * x, 1.0]])


class Corrector:
    """Newton on (grad E = 0, theta^2 <u - u_pred, t_u>_W + (p - p_pred) t_p = 0): ``bordered.Newton``'s fields."""

    def solve(self, phi_pred, p_pred, lam_pred, t_phi, t_p, theta):
        u, p = np.array(phi_pred, float), float(p_pred)
        for k in range(1, 31):
            R = np.concatenate([grad(u, p), [theta**2 * W @ ((u - phi_pred) * t_phi) + (p - p_pred) * t_p]])
            J = np.zeros((3, 3))
            J[:2, :2], J[:2, 2] = hess(u, p), [u[0], 0.0]
            J[2, :2], J[2, 2] = theta**2 * W * t_phi, t_p
            try:
                d = np.linalg.solve(J, -R)
            except np.linalg.LinAlgError:
                break
            u, p = u + d[:2], p + d[2]
            if np.max(np.abs(d)) < TOL:
                return SimpleNamespace(phi=u, p=p, lam=np.zeros(0), converged=True, iterations=k)
        return SimpleNamespace(phi=u, p=p, lam=np.zeros(0), converged=False, iterations=30)

    def fixed(self, phi0, p, lam0):
        return self.solve(phi0, p, lam0, np.zeros(2), 1.0, 0.0)


def test_follow_passes_the_fold_to_the_stable_part():
    """From the branch point along +-(1, 0) to p = -0.5: past the fold at p = 1/4, landing at
    x^2 = (1 + sqrt 3) / 2 (p = x^2 - x^4 = -1/2), y = x^2; the turn is where p peaks."""
    for sign in (1, -1):
        f = follow(Corrector(), np.zeros(2), 0.0, np.zeros(0), [sign, 0.0], 0.05, W, -0.5, ds_max=0.1)
        assert f.stopped is None and f.end.converged
        x2 = (1 + math.sqrt(3)) / 2
        assert f.end.phi[0] == pytest.approx(sign * math.sqrt(x2), abs=1e-10)  # Newton's TOL, conditioned O(1)
        assert f.end.phi[1] == pytest.approx(x2, abs=1e-10)
        assert len(f.turns) == 1
        k = f.turns[0]
        assert f.ps[k] == pytest.approx(0.25, abs=0.01)  # the polyline's vertex: within ds_max^2 of the fold
        assert all(q.p == pytest.approx(q.phi[0] ** 2 - q.phi[0] ** 4, abs=1e-10) for q in f.points)
        assert min(f.ps[:k]) > 0  # subcritical: the first part lies where the trivial branch is stable


def test_follow_lands_at_the_first_crossing_of_the_target():
    """Target p = 0.1 (before the fold): the branch's saddle x^2 = (1 - sqrt 0.6) / 2, not the minimum."""
    f = follow(Corrector(), np.zeros(2), 0.0, np.zeros(0), [1.0, 0.0], 0.05, W, 0.1, ds_max=0.1)
    assert f.stopped is None
    assert f.end.phi[0] ** 2 == pytest.approx((1 - math.sqrt(0.6)) / 2, abs=1e-10)
    assert hess(f.end.phi, 0.1)[0, 0] - 4 * f.end.phi[0] ** 2 < 0  # reduced E_xx (y = x^2 eliminated) < 0


def test_refused_points_stop_the_walk():
    """A guard refusing x > 1 (the landing lies at x = 1.169): the steps halve to ds_min and the walk says where."""
    f = follow(Corrector(), np.zeros(2), 0.0, np.zeros(0), [1.0, 0.0], 0.05, W, -0.5, ds_max=0.1,
               accept=lambda nw: nw.phi[0] <= 1.0)
    assert f.end is None and f.stopped.startswith("step below") and f.rejected > 0
    assert max(q.phi[0] for q in f.points) <= 1.0


def test_bad_amplitude_is_an_input_error():
    with pytest.raises(InputError):
        follow(Corrector(), np.zeros(2), 0.0, np.zeros(0), [1.0, 0.0], -1.0, W, 0.1)
