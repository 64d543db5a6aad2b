"""Scheme (23): backward Euler as the minimising movement of Proposition 4.1, solved by IPOPT.

Each step minimises the modified energy

    Phi(phi) = E_M(phi) + 1/(2 gamma k) ||phi - phi^n||^2,
    E_M = kappa E_h + M/2 (A - alpha)^2 + M/2 (B - beta)^2,

whose Euler-Lagrange equation is (23) (with the sign of the f term as in ``discrete``). The NLP is
built once per run from the core's functionals (``functionals.energy``, ``volume_functional``,
``area_functional`` through ``CasadiOps``) and the one E_M (``penalty.penalised_energy``, which
builds CasADi expressions as well as numbers), with phi^n and 1/(gamma k) as CasADi parameters, and
scaled like the core's NLP (``nlp.exact``): objective / (kappa m_bar G_ref), so IPOPT's tol means the
same relative stationarity as in the equilibrium solves; the same ``nlp.ipopt.IpoptOptions``.
The penalty terms would make the Hessian dense (rank-one M grad A grad A^T), so the NLP is lifted:
unknowns (phi, a, b), objective kappa E_h + M/2 (a - alpha)^2 + M/2 (b - beta)^2 + 1/(2 gamma k)||.||^2,
equality constraints (A(phi) - a)/|Omega| = 0, (B(phi) - b)/beta = 0 (same minimisers, sparse Hessian).
IPOPT starts from the feasible point (phi^n, A^n, B^n), where Phi = E_M(phi^n); a minimiser found from
there satisfies Phi(phi^{n+1}) <= Phi(phi^n), which is (24):
    E_M(phi^{n+1}) - E_M(phi^n) + 1/(2 gamma k) ||phi^{n+1} - phi^n||^2 <= 0.
(24) is checked after every step (relative to |E_M^n|, allowing ``law_tol`` of round-off); the
equality law (22) does not hold for (23) (its defect is O(k), reported in the extra column).
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.io import interrupt
from vesicle_opt.model import functionals as Fn
from vesicle_opt.model.penalty import penalised_energy
from vesicle_opt.model.problem import objective_scale
from vesicle_opt.nlp.ipopt import IpoptOptions
from vesicle_opt.flows.base import Scheme, StepOutcome
from vesicle_opt.flows.discrete import FlowModel

LAW = "(24)"


def law_outcome(md: FlowModel, energy, phi_n, phi, k: float, law_tol: float, iterations: int,
                **kwargs) -> StepOutcome:
    """A solved (23) step checked against law (24), E(phi) - E(phi^n) + |phi - phi^n|^2/(2 gamma k)
    <= 0 relative to |E(phi^n)|, with the defect of the equality law beside it; ``energy`` the step's
    E_M. Both solvers of the step (IPOPT here, Newton-Krylov in ``backward_euler_nk``) end here."""
    dd = md.norm2(phi - phi_n)
    E0, E1 = energy(phi_n), energy(phi)
    law = (E1 - E0 + dd / (2 * md.gamma * k)) / abs(E0)
    ok = bool(np.isfinite(law) and law <= law_tol)
    eq = (E1 - E0 + dd / (md.gamma * k)) / abs(E0)  # the defect of the equality law for (23)
    return StepOutcome(phi, True, iterations, "converged" if ok else f"{LAW} violated: {law:.3g}",
                       law_residual=law, law_ok=ok, rate=float(np.sqrt(dd)) / k,
                       extra={"equality_law_defect": eq}, **kwargs)


class BackwardEulerScheme(Scheme):
    name = "backward-euler"
    law = LAW

    def __init__(self, model: FlowModel, law_tol: float, tol: float = 1e-10, max_iter: int = 200):
        import casadi as ca  # third-party, lazy: only IPOPT paths need it (0.25 s at import)
        self.model, self.law_tol = model, law_tol
        md = model
        disc = md.disc
        n = disc.n_nodes
        ops = Fn.CasadiOps(disc)
        x = ca.MX.sym("x", n + 2)
        phi, a, b = x[:n], x[n], x[n + 1]
        p = ca.MX.sym("p", n + 1)  # (phi^n, 1/(gamma k))
        phi_n, c = p[:n], p[n]
        lap = ca.mtimes(Fn.sparse_dm(disc.laplacian), phi)
        E_h = Fn.energy(ops, phi, lap, md.epsilon, md.C)
        A = Fn.volume_functional(ops, phi)
        B = Fn.area_functional(ops, phi, md.epsilon)
        d = phi - phi_n
        # E_M of the lifted unknowns (a, b) = (A, B): the same lines as FlowModel.E_M and the lifted NLP
        E_M = penalised_energy(md.rigidity, E_h, (a - md.alpha, b - md.beta), md.M, md.M)
        obj = E_M + c / 2 * ca.dot(ops.weights, d * d)
        g = ca.vertcat((A - a) / disc.volume, (B - b) / md.beta)
        self.f_scale = objective_scale(disc, md.rigidity, md.epsilon, md.alpha, md.beta)
        opts = IpoptOptions(tol=tol, max_iter=max_iter).as_dict()
        self.solver = ca.nlpsol("minimising_movement", "ipopt", {"x": x, "p": p, "f": obj / self.f_scale, "g": g},
                                opts)

    def step(self, phi_n: np.ndarray, k: float, guess: np.ndarray) -> StepOutcome:
        """``guess`` is ignored: Proposition 4.1's argument (and (24)) starts the descent at phi^n."""
        md = self.model
        c = 1.0 / (md.gamma * k)
        x0 = np.concatenate([phi_n, [md.A(phi_n), md.B(phi_n)]])
        sol = self.solver(x0=x0, p=np.concatenate([phi_n, [c]]), lbg=0.0, ubg=0.0)
        interrupt.check()  # CasADi turns a Ctrl-C inside IPOPT into a status: never a step (io.interrupt)
        stats = self.solver.stats()
        phi = np.asarray(sol["x"]).ravel()[:phi_n.size]
        iters = int(stats.get("iter_count", 0))
        if not (stats["success"] and np.all(np.isfinite(phi))):
            return StepOutcome(phi, False, iters, f"ipopt: {stats['return_status']}")
        return law_outcome(md, self.energy, phi_n, phi, k, self.law_tol, iters)

    def minimise(self, phi_start: np.ndarray) -> tuple[np.ndarray, bool, str]:
        """The k -> infinity limit of the step: a local minimiser of E_M from phi_start (IPOPT)."""
        md = self.model
        x0 = np.concatenate([phi_start, [md.A(phi_start), md.B(phi_start)]])
        sol = self.solver(x0=x0, p=np.concatenate([phi_start, [0.0]]), lbg=0.0, ubg=0.0)
        interrupt.check()
        stats = self.solver.stats()
        phi = np.asarray(sol["x"]).ravel()[:phi_start.size]
        return phi, bool(stats["success"]) and bool(np.all(np.isfinite(phi))), stats["return_status"]
