"""Scheme (23) without matrices: each backward Euler step as the minimising movement of
Proposition 4.1, solved by the matrix-free Newton-CG minimiser (``nk.newton_cg``).

Each step minimises

    Phi(phi) = E_M(phi) + 1/(2 gamma k) ||phi - phi^n||^2,
    E_M = kappa E_h + M/2 (A - alpha)^2 + M/2 (B - beta)^2,   ||v||^2 = sum m v^2 (lumped L2),

the objective of ``nk.newton_cg.Objective`` with lam = 0, rho = (M, M) plus the proximal term of
``nk.proximal.ProximalObjective`` (gradient + c m (phi - phi^n), Hessian shifted by c diag(m),
c = 1/(gamma k)). The Euler-Lagrange equation of Phi is (23); ``flows.backward_euler`` solves the
same minimisation with IPOPT (assembled matrices, FD and P1), this module on FD and Fourier-spectral
grids (FD grids go to FFT, ``nk.setup.on_fourier_grid``, equal to the sparse stencil to round-off).

The descent starts at phi^n, or at the stepper's extrapolated guess when Phi is lower there; Newton-CG
with its Armijo line search only decreases Phi, so Phi(phi^{n+1}) <= Phi(phi^n) = E_M(phi^n), which
is (24):
    E_M(phi^{n+1}) - E_M(phi^n) + 1/(2 gamma k) ||phi^{n+1} - phi^n||^2 <= 0,
checked after every step with the flow model's own E_M (``flows.discrete.FlowModel``, sparse or FFT
Laplacian, not the minimiser's arithmetic), relative to |E_M^n| with ``law_tol`` of round-off. A
step whose Newton-CG does not reach ``tol`` (relative dual stationarity of Phi) is reported not
converged: the stepper rejects it and halves k. (23) is L-stable, so the adaptive stepper may grow
k without bound as the flow relaxes; as k -> infinity a step becomes Newton on E_M itself, and the
flow's steady state is a stationary point of E_M (the penalty equilibrium (11) at this M).
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.model.lumped import LumpedOperators, PhaseField
from vesicle_opt.model.penalty import penalised_energy
from vesicle_opt.nk.newton_cg import Counters, newton_minimize
from vesicle_opt.nk.precond import FourierPreconditioner, SparsePreconditioner
from vesicle_opt.nk.proximal import ProximalObjective
from vesicle_opt.nk.setup import on_fourier_grid
from vesicle_opt.flows.backward_euler import LAW, law_outcome
from vesicle_opt.flows.base import Scheme, StepOutcome
from vesicle_opt.flows.discrete import FlowModel

STEP_TOL = 1e-9  # relative dual stationarity of each step: below the 1e-8 of the equilibrium solves,
# so the flow's steady state meets the certificate's tol (measured step residuals then ~1e-10)
MAX_NEWTON = 50  # Newton steps per time step (measured 1-8 on the Section 5 flow); more: reject, k/2


class BackwardEulerNKScheme(Scheme):
    name = "backward-euler"
    law = LAW
    # adaptive k (``flows.stepper``): Newton-CG to STEP_TOL from the extrapolated guess takes 3-5
    # steps on a smooth stretch (quadratic convergence from ~1e-3), so <= 5 is easy (grow k), > 12 hard
    controller = {"easy_iters": 5, "hard_iters": 12}

    def __init__(self, model: FlowModel, law_tol: float, tol: float = STEP_TOL, max_iter: int = MAX_NEWTON,
                 max_cg: int = 200):
        self.model, self.law_tol, self.tol = model, law_tol, float(tol)
        self.max_iter, self.max_cg = int(max_iter), int(max_cg)
        disc = on_fourier_grid(model.disc)
        self.pf = PhaseField(LumpedOperators(disc), model.epsilon, model.C)
        fourier = getattr(disc, "fourier", None)
        self.prec = FourierPreconditioner(fourier, disc.weights[0], model.epsilon) if fourier is not None \
            else SparsePreconditioner(disc.K, disc.weights, model.epsilon, disc.dim)
        self.mu = np.zeros(2)  # multiplier shift: the flow of E_M - mu . (A - alpha, B - beta) (below)

    def energy(self, phi):
        """The energy whose law (24) is checked: E_M, or with a multiplier shift mu (set between flow
        stages by ``flows.equilibrium.flow_to_equilibrium``) the augmented Lagrangian
        E_M - mu_A (A - alpha) - mu_B (B - beta) (``penalty.penalised_energy``), the functional the
        steps then minimise (Proposition 4.1 holds for it unchanged)."""
        md = self.model
        if not np.any(self.mu):
            return md.E_M(phi)
        return penalised_energy(md.rigidity, md.E_h(phi), md.residuals(phi), md.M, md.M, self.mu)

    def objective(self, phi_n: np.ndarray, k: float) -> ProximalObjective:
        """Phi of the step phi^n -> phi^{n+1} with step k (k = inf: E_M itself)."""
        md = self.model
        c = 0.0 if np.isinf(k) else 1.0 / (md.gamma * k)
        return ProximalObjective(self.pf, self.prec, lambda phi: None, md.rigidity, md.alpha, md.beta,
                                 self.mu.copy(), np.array([md.M, md.M], float), Counters(), anchor=phi_n, c=c)

    def step(self, phi_n: np.ndarray, k: float, guess: np.ndarray) -> StepOutcome:
        md = self.model
        obj = self.objective(phi_n, k)
        start = phi_n
        if guess is not None and guess is not phi_n and np.all(np.isfinite(guess)):
            if obj.value(guess)[0] < obj.value(phi_n)[0]:
                start = guess
        pt, status = newton_minimize(obj, start, self.tol, self.max_iter, self.max_cg)
        phi, cnt = pt.phi, obj.cnt
        if status != "converged" or not np.all(np.isfinite(phi)):
            return StepOutcome(phi, False, cnt.newton, f"newton-cg: {status} (dual {pt.rel:.2e})",
                               linear_iterations=cnt.cg)
        return law_outcome(md, self.energy, phi_n, phi, k, self.law_tol, cnt.newton,
                           linear_iterations=cnt.cg)
