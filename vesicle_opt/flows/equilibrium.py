"""A flow that ends at a certified equilibrium: the one certificate (``verify.certify``) as a tracker.

``EquilibriumTracker(scene, model)`` certifies the field after every accepted step (or every
``every`` steps) as a stationary point of the flow's own energy: the penalty problem (11) at the
flow's M, i.e. ``verify.certify.build_result`` with method ``penalty``, lambda = -M (A - alpha,
B - beta) recomputed from the field, the relative L2 KKT residual from the hand-derived gradients
(sharing nothing with the step's Newton-CG), the penalty round-off floor and, on Fourier grids, the
L2 floor of ``nk.solve.l2_floor``. The first field that the certificate passes ends the run
(``Status.STOPPED`` from the stepper: the caller's criterion was met) and is kept as ``result``
(a ``Result``, ``converged`` True). The "solver" of the certificate is the flow: its success is the
accepted step (converged Newton, law verified: the stepper accepts no other).

Cost: one energy and one gradient evaluation per certified step (a few Laplacian applications),
small beside a step's Newton-CG.
"""

from __future__ import annotations

from vesicle_opt.model import functionals as F
from vesicle_opt.nk.solve import l2_floor
from vesicle_opt.verify.certify import build_result
from vesicle_opt.flows.discrete import FlowModel
from vesicle_opt.flows.trackers import Tracker


class EquilibriumTracker(Tracker):
    """Stop the flow at the first certified stationary point of E_M (module docstring)."""

    def __init__(self, scene, model: FlowModel, *, tol: float | None = None, every: int = 1):
        self.scene, self.model = scene, model
        self.tol = float(scene.solver.tol if tol is None else tol)
        self.every = int(every)
        self.result = None  # the certified Result, once found
        self.last = None  # the last certificate evaluated (converged or not)

    def certify(self, phi, steps: int = 0, wall_time_s: float = float("nan")):
        md = self.model
        dE = F.gradients(md.disc, phi, md.epsilon, md.C)[0]
        floor = l2_floor(md.disc, md.rigidity, dE, md.epsilon)
        return build_result(scene=self.scene, disc=md.disc, alpha=md.alpha, beta=md.beta, phi=phi, tol=self.tol,
                            solver_status="steady", solver_success=True, method="penalty", M=(md.M, md.M),
                            floor=floor, iterations=steps, wall_time_s=wall_time_s,
                            extra={"backend": "flow", "mesh_kind": md.disc.kind})

    def handle(self, state, row):
        if state.step % self.every:
            return None
        res = self.certify(state.phi, state.step, state.wall_time_s)
        self.last = res
        row["kkt_residual"] = res.kkt_residual
        if res.converged:
            self.result = res
            return True
        return None
