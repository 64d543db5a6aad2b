"""The energy and multipliers of the exact problem (6)-(8) from the stages of a penalty continuation
(penalty form (11), Theorem 3.2): a multiplier-corrected stage energy and extrapolation in 1/M.

Stage k minimises E_{M,h} of (11) at M = M_k; call its minimiser phi_M, its residuals
g_M = (A - alpha, B - beta)(phi_M) and its multiplier estimates lambda_M = -M g_M (the code's
convention, ``nlp.lifted``: rigidity grad E_h = lambda_A grad A + lambda_B grad B).

* **Plain** (``richardson``): Theorem 3.2's law E(phi_M) = v* + a/M + b/M^2 + ..., extrapolated by
  the polynomial in 1/M through the last stages. Its leading error is O(1/M) before elimination, so
  the stages' first (pre-asymptotic) M costs digits, and the last M is capped by the round-off floor
  (``penalty.roundoff_floor``).
* **Multiplier-corrected** (``corrected_energy``; standard sensitivity theory): phi_M is also the
  minimiser of rigidity E_h subject to the *perturbed* constraints g(phi) = g_M (its stationarity
  condition is that problem's KKT condition with multiplier lambda_M). So E(phi_M) = v(g_M), where
  v(u) = min {rigidity E_h : g = u} is the value function, smooth near 0 at a regular minimiser,
  with v'(u) = lambda(u). A Taylor step back to u = 0:

      v(0) = v(g_M) - lambda_M . g_M + 1/2 g_M . v''(g_M) g_M + O(|g_M|^3),

  so C(M) = E(phi_M) - lambda_M . g_M = E(phi_M) + M |g_M|^2 has error -1/2 g.v''.g = O(1/M^2): no 1/M
  term (g_M is smooth in 1/M, g_M = -lambda*/M + O(1/M^2)), C(M) = v* + c2/M^2 + c3/M^3 + ...
  ``polynomial_limit`` with the powers (0, 2, 3) through the last three stages (or (0, 2) through two)
  then leaves O(1/M^4) (measured on the bundled scenes, see docs: e.g. circle-2d 8e-10 against the
  plain 7.5e-8). C is first order in a stage's own solve error delta phi (through lambda . grad g
  delta phi), as E(phi_M) is; the stages' certificate bounds it.

``extrapolation`` reports both, and the observed order of C (``observed_order``) as a check that the
stages are in the asymptotic range.

**One branch** (``same_branch``): the expansions hold along one branch of minimisers phi_M. A
continuation may change branch between stages (the Table-1 torus: the stages at M = 1e2 ... 1e4 follow
the symmetric saddle, C -> 330.5325, the one at 1e5 leaves for the minimum, C = 330.1976), and a fit
through both is meaningless. On one branch C - v* = O(1/M^2) while E - v* = lambda* . g = O(1/M), so
between two stages |delta C| / |delta E| = O(1/M) -> 0 (measured 0.0001 ... 0.41 on the bundled scenes'
stages, the largest at circle-2d's pre-asymptotic M = 100 -> 1e3); across a change of branch both
move by the energy gap, the ratio ~ 1 (the torus 1.18). ``BRANCH_RATIO`` = 1/2 separates the two: only
the trailing stages on the last stage's branch are used. (Where lambda* = 0, E = C and the ratio is 1
too: the last stage alone is used, its C then O(1/M^2) off as well; a lost order, not a wrong value.)
"""

from __future__ import annotations

import math

import numpy as np

CORRECTED_POWERS = (0, 2, 3)  # the expansion of C(M) in 1/M: no linear term (module docstring)
BRANCH_RATIO = 0.5  # |delta C| / |delta E| above it: two stages on different branches (module docstring)


def polynomial_limit(Ms, values, powers) -> float:
    """The value at 1/M = 0 of sum_k c_k (1/M)^p_k (``powers``, the first 0) through the last
    len(powers) points (M_i, v_i): a linear solve, columns scaled by the largest 1/M."""
    n = len(powers)
    x = 1.0 / np.asarray(Ms[-n:], float)
    v = np.asarray(values[-n:], float)
    V = np.column_stack([(x / x.max()) ** p for p in powers])
    return float(np.linalg.solve(V, v)[list(powers).index(0)])


def richardson(Ms, values, order: int) -> float:
    """The value at 1/M = 0 of the polynomial of degree ``order`` in 1/M through the last
    order + 1 points (M_i, v_i): Richardson's extrapolation of Theorem 3.2's expansion
    v(M) = v* + a/M + b/M^2 + ... (order 1: (M2 v2 - M1 v1) / (M2 - M1))."""
    x = 1.0 / np.asarray(Ms[-(order + 1):], float)
    v = np.asarray(values[-(order + 1):], float)
    total = 0.0
    for i in range(order + 1):
        w = np.prod([x[j] / (x[j] - x[i]) for j in range(order + 1) if j != i])
        total += w * v[i]
    return float(total)


def corrected_energy(stage: dict) -> float:
    """C(M) = E(phi_M) - lambda_M . g_M of a stage record (module docstring): the value function at
    g = 0 to O(1/M^2), where E(phi_M) is off by O(1/M)."""
    return float(stage["energy"] - stage["lambda_volume"] * stage["volume_residual"]
                 - stage["lambda_area"] * stage["area_residual"])


def observed_order(Ms, values) -> float:
    """p with v(M) = v_inf + c M^-p through the last three points (M increasing), from the ratio of
    successive differences (bisection on p in [0.25, 8]); nan when no p fits (differences of mixed
    sign, or at round-off)."""
    if len(values) < 3:
        return math.nan
    x = 1.0 / np.asarray(Ms[-3:], float)
    v = np.asarray(values[-3:], float)
    d1, d2 = v[1] - v[0], v[2] - v[1]
    if not (d1 * d2 > 0):
        return math.nan
    q = d1 / d2

    def f(p):
        return (x[1] ** p - x[0] ** p) / (x[2] ** p - x[1] ** p) - q

    lo, hi = 0.25, 8.0
    if f(lo) * f(hi) > 0:
        return math.nan
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(lo) * f(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def same_branch(a: dict, b: dict) -> bool:
    """Whether two stage records lie on one branch of minimisers: |delta C| <= ``BRANCH_RATIO``
    |delta E| (module docstring)."""
    return abs(corrected_energy(b) - corrected_energy(a)) <= BRANCH_RATIO * abs(b["energy"] - a["energy"])


def extrapolation(stages: list[dict]) -> dict:
    """Theorem 3.2's law from the certified stages of a continuation (``history['stages']`` records,
    M increasing; each with energy, residuals and multiplier estimates). Empty with fewer than two.

    * ``energy_extrapolated``: the multiplier-corrected energies (``corrected_energy``) extrapolated by
      ``polynomial_limit`` with ``CORRECTED_POWERS`` through the last three stages (powers (0, 2)
      through two); ``energy_extrapolation_error``: its change from one term less ((0, 2) through the
      last two; from two stages, the last stage's C itself);
    * ``energy_corrected``: the last stage's C; ``energy_corrected_order``: the observed order of C
      through the last three stages (``observed_order``; 2 in the asymptotic range);
    * ``energy_extrapolated_plain``: the plain Richardson of E(phi_M) in 1/M (degree 2 through the last
      three, 1 through two), the value ``energy_extrapolated`` had before the correction;
    * ``lambda_volume_extrapolated``, ``lambda_area_extrapolated``: plain Richardson of the multiplier
      estimates (their error is O(1/M) with no correction at hand: it needs v'');
    * ``extrapolation_order`` (the plain degree), ``extrapolation_M`` (the M used).

    Only the trailing stages on the last stage's branch are used (``same_branch``); where an earlier
    converged stage lies on another branch, ``extrapolation_branch_change`` is the M of the first stage
    after the change. With the last stage alone: its C and multipliers, order 0, and an error
    estimate of nan (none can be made from one stage).
    """
    good = [s for s in stages if s.get("converged") and s.get("M")]
    if len(good) < 2:
        return {}
    k = len(good) - 1
    while k > 0 and len(good) - k < 3 and same_branch(good[k - 1], good[k]):
        k -= 1
    out = {} if k == 0 or same_branch(good[k - 1], good[k]) else {"extrapolation_branch_change": good[k]["M"]}
    good = good[k:]
    order = min(2, len(good) - 1)
    Ms = [s["M"] for s in good]
    out.update({"extrapolation_order": order, "extrapolation_M": " ".join(f"{M:.6g}" for M in Ms[-(order + 1):])})
    if order == 0:
        out.update({"energy_extrapolated_plain": good[-1]["energy"], "energy_extrapolated": corrected_energy(good[-1]),
                    "energy_extrapolation_error": math.nan, "energy_corrected": corrected_energy(good[-1]),
                    "energy_corrected_order": math.nan, "lambda_volume_extrapolated": good[-1]["lambda_volume"],
                    "lambda_area_extrapolated": good[-1]["lambda_area"]})
        return out
    for key in ("lambda_volume", "lambda_area"):
        out[f"{key}_extrapolated"] = richardson(Ms, [s[key] for s in good], order)
    out["energy_extrapolated_plain"] = richardson(Ms, [s["energy"] for s in good], order)
    C = [corrected_energy(s) for s in good]
    powers = CORRECTED_POWERS[:order + 1]
    out["energy_extrapolated"] = polynomial_limit(Ms, C, powers)
    less = polynomial_limit(Ms, C, powers[:-1])  # from two stages: (0,), the last C itself
    out["energy_extrapolation_error"] = abs(out["energy_extrapolated"] - less)
    out["energy_corrected"] = C[-1]
    out["energy_corrected_order"] = observed_order(Ms, C)
    return out
