"""The interface profile's coordinate, and a secant predictor in it.

A resolved phase-field interface is the tanh profile, phi = tanh(d / (sqrt(2) eps)) with d the signed
distance to phi = 0 (Section 2). A linear extrapolation of phi between two fields whose interfaces are
a distance delta apart does not move the interface: it blends the two profiles, and its error grows
as (delta / eps)^2 (the branch walks' predictor, measured on the octant prolate, eps 0.05, step 0.01 in
v: relative dual residual 0.8-0.96 at the prediction). In the coordinate

    T(phi) = atanh(phi)                                for |phi| <= C,
    T(phi) = atanh(C) + (phi - C) / (1 - C^2)          beyond (and its mirror image below -C),

which is d / (sqrt(2) eps) inside the band, a linear extrapolation moves the interface and keeps its
profile; beyond the band T continues linearly with the slope it has at C (C^1, monotone), as the
tanh tail would. Where the bulk sits off +-1 (a bulk offset) a node can drift across C in the bulk
(-1.0023 -> -0.9975 on the FD ellipse at eps 0.4, whose inside never reaches +1), and that slope,
1 / (1 - C^2) = 500, turns the drift into a jump of the extrapolated field (to -0.76: Newton's error
at the start 4.1 against 0.2 at the linear prediction). A continuation with slope 1 instead, or a
blend towards the linear secant of phi for max(|phi_a|, |phi_b|) in [0.9, 0.99], lost the gain where
it counts (the 3D octant prolate, 205 k nodes: 15-23 and 9-21 Newton steps a point against 5-8). So
the corrector takes this start only where its error is below the linear prediction's
(``branch.krylov_bordered.newton``). ``tests/model/test_profile.py`` checks the secant against two
shifted tanh profiles (exact inside the band).

The same coordinate moves a Newton iterate (``step``): a step dphi = T'(phi)^{-1} a with a uniform
across the band is a shift of the interface by a sqrt(2) eps, which phi + dphi blurs as the linear
secant does, and T^{-1}(T(phi) + a) makes exactly. ``step`` advances T by a = T'(phi) dphi clipped to
+-``STEP_CAP`` and adds the rest of dphi linearly: to first order it is phi + dphi (Newton's local
convergence is unchanged); where T stays linear (beyond the band) it is phi + dphi exactly; the clip
keeps a node near C, where T' is large, from being thrown across the band by a step that is no shift.
Measured (``studies.bench_branch_3d``, the octant prolate walk, against the plain step run just before,
every warm point): Newton 5 / 6 / 7 / 8 -> 5 / 6 / 6 / 7.5 steps a point at eps 0.14 / 0.07 / 0.05 /
0.035 (31 k-525 k nodes), a point 3-8 % less CPU, a unit of v 5-10 % less up to 205 k nodes and 24 %
less at 525 k, where the step control lengthens the step (``docs/guide/large-3d.md``).
"""

from __future__ import annotations

import numpy as np

C = 0.999  # the band's edge in phi: atanh(C) = 3.8, 5.4 eps from the interface; beyond it T is linear
_YC = float(np.arctanh(C))
_SLOPE = 1.0 / (1.0 - C * C)
STEP_CAP = 0.5  # the largest move of a Newton step along the profile, in T (0.5 sqrt(2) eps = 0.71 eps of
# interface); measured at eps 0.035 (525 k nodes): caps 0.5 and 1.5 gave 6-8 Newton steps a point on the same
# walk, 1.5 took 19 at the walk's first step (0.5: 12); unclipped (T' up to 500 at the band's edge) the first
# step diverged (error 0.98 -> 67)


def coordinate(phi: np.ndarray) -> np.ndarray:
    """T(phi) (module docstring)."""
    phi = np.asarray(phi, float)
    c = np.clip(phi, -C, C)
    return np.arctanh(c) + (phi - c) * _SLOPE


def field(y: np.ndarray) -> np.ndarray:
    """T^{-1}(y)."""
    y = np.asarray(y, float)
    c = np.clip(y, -_YC, _YC)
    return np.tanh(c) + (y - c) / _SLOPE


def slope(phi: np.ndarray) -> np.ndarray:
    """T'(phi): 1 / (1 - phi^2) in the band, 1 / (1 - C^2) beyond."""
    phi = np.asarray(phi, float)
    inside = np.abs(phi) <= C
    return np.where(inside, 1.0 / np.where(inside, 1.0 - phi * phi, 1.0), _SLOPE)


def step(phi: np.ndarray, dphi: np.ndarray, cap: float = STEP_CAP) -> np.ndarray:
    """The iterate after the Newton step dphi, moved along the profile (module docstring):
    T^{-1}(T(phi) + a) + (dphi - a / T'(phi)), a = clip(T'(phi) dphi, -cap, cap)."""
    phi, dphi = np.asarray(phi, float), np.asarray(dphi, float)
    t = slope(phi)
    a = np.clip(t * dphi, -cap, cap)
    y = coordinate(phi)
    out = phi + dphi  # the bulk beyond the band, T linear on both ends: the plain step, the same floats
    band = (np.abs(phi) <= C) & (np.abs(y + a) <= _YC)
    # in the band phi + (tanh(y + a) - tanh(y)), the difference as sinh(a) / (cosh(y + a) cosh(y)): no
    # round trip through atanh, so a step at round-off level is phi + dphi to round-off (a branch point
    # certified at tol 1e-10 stalled 6 % above its floor with the round trip)
    yb, ab = y[band], a[band]
    out[band] = phi[band] + (np.sinh(ab) / (np.cosh(yb + ab) * np.cosh(yb)) + (dphi[band] - ab / t[band]))
    bulk = (np.abs(phi) > C) & (np.abs(y + a) > _YC) & (np.sign(y + a) == np.sign(phi))
    cross = ~(band | bulk)  # a node crossing the band's edge
    out[cross] = field(y[cross] + a[cross]) + (dphi[cross] - a[cross] / t[cross])
    return out


def interface_secant(phi_a: np.ndarray, phi_b: np.ndarray, k: float) -> np.ndarray:
    """T^{-1}(T(phi_b) + k (T(phi_b) - T(phi_a))): the secant from phi_a to phi_b extrapolated by k
    of its length in the profile's coordinate (k = ds / |secant| in a pseudo-arclength walk)."""
    ya, yb = coordinate(phi_a), coordinate(phi_b)
    return field(yb + k * (yb - ya))
