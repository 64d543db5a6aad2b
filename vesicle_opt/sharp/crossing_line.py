"""The prolate/oblate energy crossing of the spontaneous-curvature model as a line in (c0, v): the
sharp-interface reference of the phase field's transition line (``branch.transition``).

At each c0 (= C0 R0, the literature's units: Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182
(1991)) the up-down symmetric prolate and oblate of ``sharp.spontaneous`` (the general-c0 code; its
start the symmetric shape of ``sharp.axisymmetric`` at c0 = 0, wavenumber 2j at index 2j - 1, with no
odd mode: the symmetric shapes stay symmetric, the odd modes' gradient vanishes there by symmetry)
are solved along the way of a brentq on f_prolate(v) - f_oblate(v), each solve warm from the last of
its branch. At c0 = 0 this is ``sharp.axisymmetric.crossing`` (0.6511, 1.8235 with 16 modes).
numpy and scipy only.
"""

from __future__ import annotations

import numpy as np
from scipy import optimize

from vesicle_opt.sharp import axisymmetric as A
from vesicle_opt.sharp import spontaneous as S

BRANCHES = ("prolate", "oblate")


def _start(v: float, which: str, n_modes: int) -> np.ndarray:
    ref = A.solve(v, which, n_modes // 2, second_order=False)
    a = np.zeros(n_modes)
    a[1::2] = ref.a[: n_modes // 2]
    return a


def crossing(c0: float, bracket: tuple[float, float] = (0.55, 0.75), n_modes: int = 16,
             starts: dict | None = None) -> dict:
    """{c0, v, f, f_prolate, f_oblate, converged} where the symmetric prolate and oblate at c0 have
    equal f (brentq in ``bracket`` to 1e-10 in v); ``starts`` (branch -> coefficients, updated in
    place) warm-start the solves, e.g. from the previous c0 of a line."""
    starts = {} if starts is None else starts
    for b in BRANCHES:
        if b not in starts:
            starts[b] = _start(float(np.mean(bracket)), b, n_modes)
    sols = {}

    def diff(v):
        for b in BRANCHES:
            sols[b] = S.solve(float(v), float(c0), starts[b], n_modes)
            if not sols[b].converged:  # the warm start left the shapes: from the c0 = 0 shape at v
                sols[b] = S.solve(float(v), float(c0), _start(float(v), b, n_modes), n_modes)
            if sols[b].converged:
                starts[b] = sols[b].a
        return sols["prolate"].f - sols["oblate"].f

    v = float(optimize.brentq(diff, *bracket, xtol=1e-10))
    diff(v)
    return {"c0": float(c0), "v": v, "f": sols["prolate"].f, "f_prolate": sols["prolate"].f,
            "f_oblate": sols["oblate"].f, "converged": all(s.converged for s in sols.values())}


def line(c0s, bracket: tuple[float, float] = (0.55, 0.75), n_modes: int = 16, width: float = 0.03) -> list[dict]:
    """``crossing`` at each c0 in order, the solves warm from the previous c0's; after the first,
    in the bracket v_pred +- ``width`` around the secant (the previous v with one) of the line."""
    starts: dict = {}
    out: list[dict] = []
    for c in c0s:
        if out:
            v = out[-1]["v"] if len(out) < 2 else out[-1]["v"] + (c - out[-1]["c0"]) * (
                out[-1]["v"] - out[-2]["v"]) / (out[-1]["c0"] - out[-2]["c0"])
            bracket = (v - width, v + width)
        out.append(crossing(c, bracket, n_modes, starts))
    return out
