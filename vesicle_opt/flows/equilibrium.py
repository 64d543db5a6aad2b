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

The flow of E_M ends at the *penalty* equilibrium, O(lambda^2 / M) away in energy from the
exact-constraint one. ``flow_to_equilibrium(..., exact=True)`` reaches the latter with the flow
itself: an augmented Lagrangian of flows. Stage j runs the (23) flow of the shifted energy
E_M - mu_j . c (``BackwardEulerNKScheme.mu``; law (24) holds for it) to its certified stationary
point, then mu_{j+1} = mu_j - M c (the first-order multiplier update of ``nlp``/``nk``'s
``augmented``), until the certificate with exact constraints (|A - alpha| <= tol |Omega|,
|B - beta| <= tol beta, lambda = mu - M c, method ``augmented``) passes. With M = 1e4 the
constraint residual drops by orders of magnitude per stage, and each later stage starts relaxed
(k already large), so it costs a few Newton steps.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from vesicle_opt.model import functionals as F
from vesicle_opt.model.penalty import residuals
from vesicle_opt.nk.solve import l2_floor
from vesicle_opt.verify import shape, topology
from vesicle_opt.verify.certify import build_result
from vesicle_opt.result import Status
from vesicle_opt.flows.api import flow, make_scheme
from vesicle_opt.flows.discrete import FlowModel
from vesicle_opt.flows.trackers import Tracker


class EquilibriumTracker(Tracker):
    """Stop the flow at the first certified stationary point of E_M (module docstring)."""

    def __init__(self, scene, model: FlowModel, *, tol: float | None = None, every: int = 1, mu=(0.0, 0.0)):
        self.scene, self.model = scene, model
        self.mu = tuple(float(v) for v in mu)  # the flow's multiplier shift (0: E_M itself)
        self.tol = float(scene.solver.tol if tol is None else tol)
        self.every = int(every)
        self.result = None  # the certified Result, once found
        self.last = None  # the last certificate evaluated (converged or not)

    def certify(self, phi, steps: int = 0, wall_time_s: float = float("nan"), exact: bool = False):
        """The certificate of ``phi`` as a stationary point of the shifted E_M (``exact``: and with the
        constraints held to tol, the augmented Lagrangian's exact-constraint certificate)."""
        md = self.model
        grads = F.gradients(md.disc, phi, md.epsilon, md.C)
        res = residuals(md.disc, phi, md.epsilon, md.alpha, md.beta)
        lam = (self.mu[0] - md.M * res[0], self.mu[1] - md.M * res[1])  # as build_result computes them
        floor = l2_floor(md.disc, md.rigidity, md.epsilon, grads, lam)
        return build_result(scene=self.scene, disc=md.disc, alpha=md.alpha, beta=md.beta, phi=phi, tol=self.tol,
                            solver_status="steady", solver_success=True,
                            method="augmented" if exact else "penalty", M=(md.M, md.M), mu=self.mu,
                            exact_constraints=exact, floor=floor, iterations=steps, wall_time_s=wall_time_s,
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


def flow_to_equilibrium(scene, model: FlowModel, *, exact: bool = False, resume_from=None, phi0=None,
                        trackers=(), max_stages: int = 12, tol: float | None = None,
                        constraint_margin: float = 1.0):
    """Run the (23) flow of ``scene`` to a certified equilibrium (module docstring): the penalty one
    (``exact`` False: one stage) or the exact-constraint one (multiplier shifts between stages).

    Returns (result, flow_result, stages): ``result`` the last certificate (a ``Result``; its
    ``converged`` says whether the equilibrium was certified, and a wrong shape is not:
    ``verify.shape``, with the topology keys), ``flow_result`` the last stage's
    ``FlowResult`` (its ``state`` continues the run), ``stages`` one dict per stage (mu, steps,
    constraint residuals, kkt_residual). Needs the Newton-Krylov (23) scheme (``flows.api.make_scheme``
    with ``flow.scheme = 'backward-euler'`` on FD with solver.backend = 'newton-krylov' or spectral).
    ``constraint_margin``: the stages go on until also |A - alpha| <= margin tol |Omega| and
    |B - beta| <= margin tol beta (0.1: the margin of the exact Newton-Krylov solve,
    ``NewtonKrylovOptions.constraint_margin``, so both carry the same constraint error)."""
    scheme = make_scheme(scene, model)
    if not hasattr(scheme, "mu"):
        raise TypeError("flow_to_equilibrium needs the Newton-Krylov backward Euler scheme (23)")
    mu, state, stages, result, res = np.zeros(2), resume_from, [], None, None
    for _ in range(max_stages):
        scheme.mu = mu.copy()
        tracker = EquilibriumTracker(scene, model, tol=tol, mu=mu)
        res = flow(scene, trackers=[tracker, *trackers], model=model, scheme=scheme, resume_from=state,
                   x0=phi0 if state is None else None)
        state, phi0 = res.state, None
        result = tracker.result if tracker.result is not None else tracker.last
        if tracker.result is None:  # the flow ended (steps, failure) before a certified point
            break
        c = np.array(model.residuals(res.phi))
        stages.append({"mu": mu.tolist(), "steps": res.steps, "t": res.t, "volume_residual": c[0],
                       "area_residual": c[1], "kkt_residual": result.kkt_residual})
        if not exact:
            break
        result = tracker.certify(res.phi, res.steps, res.wall_time_s, exact=True)
        tight = abs(c[0]) <= constraint_margin * tracker.tol * model.disc.volume and \
            abs(c[1]) <= constraint_margin * tracker.tol * abs(model.beta)
        if (result.converged and tight) or res.status is Status.FAILED:
            break
        mu = mu - model.M * c  # the first-order multiplier update
    if result is not None:  # the equilibrium's shape against its targets, as the front door's (verify.shape)
        topo = topology.report(result.disc, result.phi)
        result = shape.apply(dataclasses.replace(result, extra={**result.extra, **topo}))
    return result, res, stages
