"""The proximal (minimising-movement) objective: the Newton-CG objective plus c/2 ||phi - phi^n||^2.

Proposition 4.1 of the paper: a step of the backward Euler scheme (23) with time step k is a
minimiser of

    Phi(phi) = E_M(phi) + 1/(2 gamma k) ||phi - phi^n||^2,     ||v||^2 = sum_i m_i v_i^2 (lumped L2),

E_M = rigidity E_h + M/2 (A - alpha)^2 + M/2 (B - beta)^2 (the penalised energy (11); with multiplier
shifts mu it is the augmented Lagrangian of ``nk.newton_cg``). ``ProximalObjective`` is that
``Objective`` plus the quadratic term with c = 1/(gamma k), so ``newton_cg.newton_minimize`` solves
the step unchanged:

    value    f(phi) + c/2 sum m (phi - phi^n)^2
    gradient g(phi) + c m (phi - phi^n)        (nodal: the derivative with respect to nodal values)
    Hessian  H(phi) + c diag(m)                (a shift by the lumped mass / (gamma k))

The shift makes the step problem strictly convex along the translations of a periodic grid (they
move phi away from phi^n), so no mode is projected out of the steps (``Objective`` removes them
because they are null modes of E_M alone; here they are not, and a projection would leave the
gradient's translation part unreduced). On Fourier grids the preconditioner is the Fourier model of
``nk.precond`` with the same shift c m added to its symbol (exact for the shift); on other meshes
the unshifted model (still SPD, only weaker as c grows).

Stationarity is tested as in ``Objective``: the dual norm of the gradient relative to
rig |dE|_* + |mu_A| |dA|_* + |mu_B| |dB|_* + c |m (phi - phi^n)|_*.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.nk.krylov import SubspacePreconditioner
from vesicle_opt.nk.newton_cg import Objective, Point


class ProximalObjective(Objective):
    """``Objective`` + c/2 ||phi - anchor||^2 in the lumped L2 norm (module docstring)."""

    def __init__(self, *args, anchor: np.ndarray, c: float, **kwargs):
        super().__init__(*args, **kwargs)
        self.anchor = np.asarray(anchor, float)
        self.c = float(c)

    def proximal(self, phi) -> float:
        d = phi - self.anchor
        return 0.5 * self.c * float(self.pf.m @ (d * d))

    def value(self, phi) -> tuple[float, object]:
        f, st = super().value(phi)
        return f + self.proximal(phi), st

    def extra_gradient(self, phi):
        """The proximal gradient c m (phi - anchor), added by ``Objective.point`` (also to the scale)."""
        return self.c * self.pf.m * (phi - self.anchor)

    def hvp(self, pt: Point):
        base = super().hvp(pt)
        cm = self.c * self.pf.m

        def H(v):
            return base(v) + cm * v
        return H

    def fourier_symbol(self, pt: Point) -> np.ndarray:
        """The Fourier model with the shift c m (exact for it)."""
        return super().fourier_symbol(pt) + self.c * self.prec.m

    def stationarity(self, pt: Point) -> float:
        """A step stops on the net-terms quotient (``Point.rel``, the module docstring's): a step of a
        flow is not certified, and its ``tol`` was set against this measure."""
        return pt.rel

    def translation_coordinates(self, pt: Point, w: float):
        return None  # no mode is projected out of a step (module docstring)

    def hessian_shift(self) -> float:
        return self.c * self.pf.uniform_weight

    def preconditioner(self, pt: Point) -> SubspacePreconditioner:
        prec = self.prec
        if hasattr(prec, "symbol"):  # Fourier model: add the shift c m to the symbol
            inv = prec.f.multiplier(1.0 / (prec.symbol(self.rig, -pt.mu[1], self.rho[0]) + self.c * prec.m))
            return SubspacePreconditioner(lambda r: prec.f.apply_symbol(r, inv), None)
        return SubspacePreconditioner(prec.inverse(self.rig, -pt.mu[1], self.rho[0]), None)
