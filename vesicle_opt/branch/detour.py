"""A disconnected branch reached without a seed: a detour in a second parameter q.

At q = q0 the wanted branch B (the stomatocyte at c0 = 0) is not connected to the branch A that one
can start (the up-down symmetric oblate, started from its own sharp shape): A has no branch point
towards B at q0 in reach (at c0 = 0 the sharp oblate's odd branch point is at v = 0.51044, its poles
0.0198 R0 apart: no phase field resolves that). In a second parameter q (c0) the branch point of A
moves (``sharp.stomatocyte_switch.branch_point``: at c0 = -1 / -2 / -3 to v = 0.621 / 0.704 / 0.767,
the poles 0.27 / 0.48 / 0.65 R0 apart), so at fixed p (v) the detour is

1. **out**: A walked in q (``q_out``: q0 first, then away from it), each solve warm from the last,
   until it is no longer a minimum: the least eigenvalue of the reduced Hessian (the check of every
   solve) is negative: A has passed a branch point in q, and its critical mode points off it;
2. **switch**: at the first such point with q beyond ``push_beyond``, the solve from A's field
   pushed by +-a times that mode (``push``); the first that converges to a certified minimum of
   B's form (``is_target``) is on B (a minimiser started off an unstable A leaves it). If neither
   does, the walk goes on to the next q of ``q_out`` and tries again there;
3. **back**: B walked in q to q0 over the values of ``q_out`` passed on the way out (in reverse),
   each warm from the last, every point a certified minimum of B's form, else the detour stops
   there and says why (B may have no stable point at q0: then it did not reach it).

This is the same minimiser-based switch as ``branch.switch`` uses with a fixed-p corrector, made
in a second parameter where the branch point is resolvable; nothing here knows about vesicles:
``solve(q, start) -> state`` (start None: the problem's own start of A), ``check(state) ->
(converged, least eigenvalue, its mode)``, ``push(state, mode, a) -> start``, ``is_target(state)``.
``tests/branch/test_detour.py`` runs it on a closed form.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from vesicle_opt.errors import InputError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Step:
    """One solve of the detour: its leg (out / switch / back), q, the state and its check."""

    leg: str
    q: float
    state: Any = field(repr=False)
    converged: bool
    eigenvalue: float
    target: bool
    sign: int = 0  # the push's sign on the switch leg


@dataclass(frozen=True)
class Detour:
    """The detour's steps in order; ``reached``: B's certified minimum at q0 is ``steps[-1]``;
    ``switched_at``: q of the switch (None: none); ``stopped``: why it ended short (None: reached)."""

    steps: tuple[Step, ...]
    reached: bool
    switched_at: float | None
    stopped: str | None

    @property
    def end(self) -> Step | None:
        return self.steps[-1] if self.reached else None

    def leg(self, name: str) -> list[Step]:
        return [s for s in self.steps if s.leg == name]


def _check_grid(q_out: Sequence[float]) -> list[float]:
    qs = [float(q) for q in q_out]
    if len(qs) < 2 or not all(np.isfinite(qs)):
        raise InputError("q_out", f"at least two finite values (q0 first), got {list(q_out)!r}")
    d = np.diff(qs)
    if not (np.all(d < 0) or np.all(d > 0)):
        raise InputError("q_out", f"strictly monotone away from q0 = {qs[0]}, got {qs!r}")
    return qs


def detour(solve: Callable, check: Callable, push: Callable, is_target: Callable, q_out: Sequence[float],
           amplitude: float, push_beyond: float | None = None, is_source: Callable | None = None) -> Detour:
    """The detour of the module docstring. ``q_out``: q0 first, then monotone away from it;
    ``amplitude``: a of the push; ``push_beyond``: no switch is tried before q passes this value
    (None: at the first unstable point), where A's least eigenvalue is still small and a minimiser
    leaves it slowly; ``is_source(state)``: A still of its form (else the detour stops: it would
    switch from something else, e.g. an oblate whose dimples met)."""
    qs = _check_grid(q_out)
    if not (isinstance(amplitude, (int, float)) and amplitude > 0):
        raise InputError("amplitude", f"a positive number, got {amplitude!r}")
    away = 1.0 if qs[1] > qs[0] else -1.0
    steps: list[Step] = []

    def record(leg, q, state, sign=0) -> Step:
        ok, mu, _ = check(state)
        s = Step(leg, q, state, bool(ok), float(mu), bool(ok) and mu > 0 and bool(is_target(state)), sign)
        steps.append(s)
        log.info("detour %s q = %g%s: converged %s, least eigenvalue %.4g, B %s", leg, q,
                 f" (push {sign:+d})" if sign else "", s.converged, s.eigenvalue, s.target)
        return s

    start, landed, k_land = None, None, None
    for k, q in enumerate(qs):
        s = record("out", q, solve(q, start))
        if not s.converged:
            return Detour(tuple(steps), False, None, f"A not converged at q = {q}")
        start = s.state
        if is_source is not None and not s.target and not is_source(s.state):
            return Detour(tuple(steps), False, None, f"A left its form at q = {q}")
        if s.target:  # A turned into B by itself (a warm solve off an unstable A)
            landed, k_land = s, k
            break
        if s.eigenvalue >= 0 or (push_beyond is not None and away * (q - push_beyond) < 0):
            continue
        _, _, mode = check(s.state)
        for sign in (1, -1):
            t = record("switch", q, solve(q, push(s.state, mode, sign * amplitude)), sign)
            if t.target:
                landed, k_land = t, k
                break
        if landed is not None:
            break
    if landed is None:
        return Detour(tuple(steps), False, None, f"no switch to B on q_out up to q = {qs[-1]}")
    start = landed.state
    for q in reversed(qs[:k_land]):
        s = record("back", q, solve(q, start))
        if not s.target:
            why = "not converged" if not s.converged else "not a minimum" if s.eigenvalue <= 0 else "left B's form"
            return Detour(tuple(steps), False, landed.q, f"B {why} at q = {q} on the way back")
        start = s.state
    return Detour(tuple(steps), True, landed.q, None)
