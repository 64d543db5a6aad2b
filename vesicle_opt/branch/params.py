"""The continuation parameters of a branch and what they mean for a scene.

``reduced_volume``: the constraint targets follow (alpha(v), beta) = ``geometry.targets(v, S, dim,
|Omega|)`` at the fixed area (perimeter) S of the start (Section 3.1: V = (|Omega| + alpha)/2,
S = 3 sqrt(2) beta / 4), so d alpha/dv = 2 V(1) (V is linear in v at fixed S) and d beta/dv = 0.
``c0``: the spontaneous curvature of (6) (C = sqrt(2) c0), alpha and beta fixed.

The envelope identity (sensitivity of a KKT point; multiplier convention
rigidity grad E_h = lambda_A grad A + lambda_B grad B) reads along a branch

    dE*/dp = lambda_A d alpha/dp + lambda_B d beta/dp + dE/dp|_phi,

the last term the explicit dependence of rigidity E_h on p at fixed phi: zero for the reduced volume,
rigidity dE_h/dc0 for c0 (``explicit_derivative``; E_h is quadratic in C, so a central difference
with step 1 is exact up to round-off).
"""

from __future__ import annotations

import dataclasses
import math

from vesicle_opt import geometry
from vesicle_opt.errors import InputError
from vesicle_opt.mesh import discretize
from vesicle_opt.model import functionals as F
from vesicle_opt.model.feasibility import check_feasible
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.scene.schema import Constraints, Scene

PARAMS = ("reduced_volume", "c0")


@dataclasses.dataclass(frozen=True)
class Parameter:
    """A branch's parameter on one base scene: its start value and the fixed data (alpha0, beta)."""

    name: str
    start: float  # its value at the base scene
    alpha0: float
    beta: float
    dim: int
    domain_volume: float

    @property
    def area(self) -> float:
        return geometry.surface_area(self.beta)

    def scene_at(self, base: Scene, value: float) -> Scene:
        """The base scene with the parameter set to ``value`` (its start shape unchanged)."""
        if self.name == "c0":
            return base.replace(model=dataclasses.replace(base.model, c0=float(value)),
                                constraints=Constraints(self.alpha0, self.beta))
        alpha, beta = geometry.targets(float(value), self.area, self.dim, self.domain_volume)
        return base.replace(constraints=Constraints(alpha, beta, None, float(value), self.area))

    def dalpha(self) -> float:
        """d alpha / dp (constant along the branch for both parameters)."""
        if self.name == "c0":
            return 0.0
        return 2 * geometry.volume_of_reduced(1.0, self.area, self.dim)

    def dbeta(self) -> float:
        return 0.0

    def affine(self, base: Scene) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
        """(alpha, beta, C) as (value at p = 0, slope) pairs: all three are affine in p (the
        bordered corrector's data, ``branch.bordered.Affine``)."""
        if self.name == "c0":
            return (self.alpha0, 0.0), (self.beta, 0.0), (0.0, math.sqrt(2.0))
        a1 = self.dalpha()  # alpha = 2 V(v) - |Omega|, V linear in v through 0
        return (-self.domain_volume, a1), (self.beta, 0.0), (base.model.C, 0.0)


def explicit_derivative(name: str, result, scene: Scene) -> float:
    """dE/dp at fixed phi: 0 for the reduced volume; rigidity dE_h/dc0 = rigidity sqrt(2) dE_h/dC
    for c0 (central difference in C with step 1: exact for the quadratic E_h(C))."""
    if name != "c0":
        return 0.0
    eps, C = scene.model.epsilon, scene.model.C
    e_plus = F.evaluate(result.disc, result.phi, eps, C + 1.0)["E"]
    e_minus = F.evaluate(result.disc, result.phi, eps, C - 1.0)["E"]
    return scene.model.rigidity * math.sqrt(2.0) * (e_plus - e_minus) / 2.0


def parameter(base: Scene, name: str) -> Parameter:
    """The parameter ``name`` of ``base``: its start value from the scene's (alpha, beta) (a target
    shape's are evaluated on the mesh: cheap, no solve). InputError (``--param``) for other names."""
    if name not in PARAMS:
        raise InputError("--param", f"must be one of {', '.join(PARAMS)}, got {name!r}")
    c = base.constraints
    if c.alpha is not None and c.beta is not None and c.target is None:
        alpha, beta = float(c.alpha), float(c.beta)
    else:
        alpha, beta = constraint_data(base, discretize(base))
    vol = base.domain.volume
    if name == "c0":
        start = base.model.c0
    else:
        start = c.reduced_volume if c.reduced_volume is not None else geometry.reduced_volume(
            geometry.enclosed_volume(alpha, vol), geometry.surface_area(beta), base.dim)
    return Parameter(name, float(start), alpha, beta, base.dim, vol)


def _number(value, key: str) -> float:
    """``value`` as a float, or an InputError naming ``key`` (a str, list or None given to the API)."""
    if isinstance(value, (bool, str, bytes)) or value is None:
        raise InputError(key, f"expected a number, got {type(value).__name__} {str(value)[:40]!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(key, f"expected a number, got {type(value).__name__}") from None


def check_range(par: Parameter, to: float, step: float | None) -> float:
    """The step (default: a 25th of the range), after checking ``--to`` and ``--step``: the reduced
    volume lies in (0, 1]; the step is nonzero and points from the start towards ``to``."""
    to = _number(to, "--to")
    if not math.isfinite(to):
        raise InputError("--to", f"must be a finite number, got {to!r}")
    if par.name == "reduced_volume" and not 0 < to <= 1:
        raise InputError("--to", f"allowed range 0 < reduced_volume <= 1, got {to!r}")
    if par.name == "reduced_volume":
        V = geometry.volume_of_reduced(to, par.area, par.dim)
        if not 2 * V - par.domain_volume < par.domain_volume:
            raise InputError("--to", f"volume {V:.6g} at reduced_volume {to!r} exceeds the box")
    if to == par.start:
        raise InputError("--to", f"equals the start value {par.name} = {par.start!r}; give another end")
    direction = math.copysign(1.0, to - par.start)
    if step is None:
        return (to - par.start) / 25
    step = _number(step, "--step")
    if not math.isfinite(step) or step == 0 or math.copysign(1.0, step) != direction:
        sign = "> 0" if direction > 0 else "< 0"
        raise InputError("--step", f"allowed range {sign} (from {par.name} = {par.start:.6g} towards "
                         f"--to {to!r}), nonzero, got {step!r}")
    if abs(step) > abs(to - par.start) * (1 + 1e-9):  # round-off of the difference
        raise InputError("--step", f"allowed range 0 < |step| <= |to - start| = {abs(to - par.start):.6g}, "
                         f"got {step!r}")
    return step


def check_end(base: Scene, par: Parameter, to: float) -> None:
    """InputError (``--to``) when the targets at the end value are infeasible
    (``model.feasibility.check_feasible``), before any solve; the start's are checked by its solve."""
    sc = par.scene_at(base, to)
    disc = discretize(sc)
    try:
        check_feasible(*constraint_data(sc, disc), sc, disc)
    except InputError as exc:
        raise InputError("--to", f"{par.name} = {to!r}: {exc}") from None
