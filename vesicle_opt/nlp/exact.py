"""The discrete equilibrium problem (6)-(8) as a CasADi NLP: ``build_nlp(scene)``.

Unknowns x = phi (lumped mass, FD) or x = (phi, w) (consistent mass, with the linear equality
M w + K phi = 0 of Definition 2.2 among the constraints). Built once with MX and sparse constant
matrices; the Hessian of the Lagrangian stays sparse (the bi-Laplacian stencil).

Scaling (documented contract): the stopping test means the same at every eps, M, mesh and size.
    f = rigidity E_h / k,   k = rigidity * m_bar * G_ref,   m_bar = |Omega| / N,
    G_ref = 2 (E_ref / V) sqrt(|Omega| / (eps |Gamma|))                    (``gradient_scale``)
    g_A = (A - alpha) / |Omega|,  g_B = (B - beta) / beta,  g_w = eps^2 (M w + K phi) / m_bar
E_ref: sharp circle/sphere energy of area beta; V = (|Omega| + alpha)/2 the enclosed volume;
|Gamma| = 3 sqrt2 beta / 4. Why: IPOPT's dual test is a max-norm over nodal components of
grad f + J^T lam_g, i.e. max_i (m_i / m_bar) |r(x_i)| / (rigidity G_ref) <= tol with r the L2
representative of the Lagrangian gradient rigidity dE - lambda_A dA - lambda_B dB. The independent
test (``verify.kkt``) is the relative L2 norm |r| / D with D = |rigidity dE| + |lambda_A dA| +
|lambda_B dB|. At a solution D is dominated by the volume pressure lambda_A ~ E / V acting on all of
Omega, D ~ 2 (E / V) sqrt|Omega|, while r lives on the interface band, |r|_L2 ~ |r|_max
sqrt(eps |Gamma|). G_ref = D_ref / sqrt(eps |Gamma|) is that conversion, so IPOPT's tol and
kkt_residual measure the same relative stationarity (measured kkt_residual / IPOPT's final dual
infeasibility: 0.19 - 0.55 for exact solves of ellipse-2d over eps = 0.1 - 0.4, h = 1/16 - 1/4,
1.3 for the penalty at M = 1e4; 7 - 12 for a sphere, whose gradient terms nearly vanish). Every factor has the units of
rigidity dE / dphi per volume, so a geometrically similar problem (box, shape, eps scaled by s)
takes the same iterations to the same relative residuals. The constraint rows are relative to
|Omega| and beta, as in the certificate's feasibility test (``verify.certify``). IPOPT's own gradient-based rescaling is off
(``IpoptOptions``): it would rescale f by 100 / |grad f(x0)|, a test that depends on the start.
The penalty NLP (``nlp.lifted``) reuses k and the g scales, so the test is the same at every M.
IPOPT's multipliers lam_g of these scaled rows convert to the physical convention
    rigidity * grad E_h = lambda_A grad A + lambda_B grad B
by lambda_A = -k lam_g[0] / |Omega|, lambda_B = -k lam_g[1] / beta (``NLP.multipliers``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from vesicle_opt.mesh import Discretization, discretize
from vesicle_opt.model import functionals as F
from vesicle_opt.model.feasibility import check_feasible
from vesicle_opt.model.problem import constraint_data, initial_guess, objective_scale
from vesicle_opt.scene.schema import Scene


@dataclass(frozen=True, eq=False)
class NLP:
    """The CasADi pieces of one discrete problem; ``as_dict()`` goes to any ``ca.nlpsol``."""

    scene: Scene
    disc: Discretization
    alpha: float
    beta: float
    x: ca.MX
    f: ca.MX
    g: ca.MX
    p: ca.MX
    x0: np.ndarray
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    f_scale: float  # f = energy / f_scale
    g_scale: np.ndarray  # g[:2] = (A - alpha, B - beta) / g_scale

    def as_dict(self, *, scaled: bool = True) -> dict:
        """The NLP as ``{"x", "f", "g", "p"}`` for ``casadi.nlpsol``.

        The objective is scaled: ``f = rigidity * E_h(phi) / f_scale`` (``model.problem.objective_scale``,
        so that f is O(1) at the start), and so are IPOPT's printed ``objective`` / ``f`` values and
        ``sol["f"]``: multiply by ``nlp.f_scale`` for the energy (e.g. ``sol["f"]`` 65.70 with
        f_scale 0.0419 is E = 2.7528). ``scaled=False`` returns ``f * f_scale`` itself (the energy;
        the penalty NLPs: the penalised energy) for callers that want physical units. The first two
        rows are scaled too: ``g[:2] = (A - alpha, B - beta) / g_scale``; ``multipliers(lam_g)``
        turns IPOPT's ``lam_g`` into the physical (lambda_volume, lambda_area)."""
        f = self.f if scaled else self.f * self.f_scale
        return {"x": self.x, "f": f, "g": self.g, "p": self.p}

    @property
    def n_phi(self) -> int:
        """The number of phi's entries in x (the mesh's nodes)."""
        return self.disc.n_nodes

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(phi, w) of an NLP vector x; w (the mixed form's Delta_h phi) None with lumped mass."""
        x = np.asarray(x, float).ravel()
        n = self.n_phi
        return x[:n], (x[n:] if self.disc.consistent else None)

    def from_phi(self, phi: np.ndarray) -> np.ndarray:
        """The NLP vector of a field phi: phi itself, or (phi, Delta_h phi) with consistent mass."""
        phi = np.asarray(phi, float).ravel()
        return np.concatenate([phi, self.disc.apply_laplacian(phi)]) if self.disc.consistent else phi

    def multipliers(self, lam_g: np.ndarray) -> tuple[float, float]:
        """Physical (lambda_A, lambda_B) from IPOPT's lam_g (see the module docstring)."""
        k = self.f_scale
        lam = np.asarray(lam_g, float).ravel()[:2]
        return float(-k * lam[0] / self.g_scale[0]), float(-k * lam[1] / self.g_scale[1])


def build_exact(scene: Scene, disc: Discretization | None = None, check: bool = True,
                parametric: bool = False) -> NLP:
    """The exact-constraint NLP (6)-(8) of a scene, whatever its ``solver.method`` (``nlp.build_nlp``
    lifts it into the penalty NLP (11) for the other methods).

    ``parametric``: the targets, C and the objective scale are the NLP's parameters
    p = (alpha, beta, C, f_scale) (``parameter_values``) instead of constants, so that one graph and
    one IPOPT solver serve every point of a branch (``vesicle_opt.branch``); ``at_point`` gives the
    NLP of another scene on it. With p = ``parameter_values(scene, ...)`` it is the same NLP."""
    import casadi as ca  # third-party, lazy: only IPOPT paths need it (0.25 s at import)
    disc = disc or discretize(scene)
    alpha, beta = constraint_data(scene, disc)
    if check:
        check_feasible(alpha, beta, scene, disc)
    eps, C = scene.model.epsilon, scene.model.C
    ops = F.CasadiOps(disc)
    n = disc.n_nodes
    m_bar = disc.volume / n
    x = ca.MX.sym("x", 2 * n if disc.consistent else n)
    phi = x[:n]
    if disc.consistent:
        lap = x[n:]
    else:
        lap = ca.mtimes(F.sparse_dm(disc.laplacian), phi)
    f_scale = objective_scale(disc, scene.model.rigidity, eps, alpha, beta)
    g_scale = np.array([disc.volume, beta])
    p = ca.MX.sym("p", 4 if parametric else 0)
    a_, b_, c_, k_ = (p[0], p[1], p[2], p[3]) if parametric else (alpha, beta, C, f_scale)
    E = F.energy(ops, phi, lap, eps, c_)
    A = F.volume_functional(ops, phi)
    B = F.area_functional(ops, phi, eps)
    rows = [(A - a_) / g_scale[0], (B - b_) / b_]
    if disc.consistent:
        rows.append(eps**2 / m_bar * (ca.mtimes(F.sparse_dm(disc.M), lap) + ca.mtimes(ops.K, phi)))
    g = ca.vertcat(*rows)
    ng = g.shape[0]
    inf = np.full(x.shape[0], np.inf)
    return NLP(scene=scene, disc=disc, alpha=alpha, beta=beta, x=x,
               f=scene.model.rigidity * E / k_, g=g, p=p,
               x0=initial_guess(scene, disc), lbx=-inf, ubx=inf, lbg=np.zeros(ng), ubg=np.zeros(ng),
               f_scale=f_scale, g_scale=g_scale)


def parameter_values(scene: Scene, disc: Discretization, alpha: float, beta: float) -> np.ndarray:
    """p = (alpha, beta, C, f_scale) of a parametric NLP (``build_exact(parametric=True)``) for a
    scene's targets (alpha, beta) and C; f_scale is the scaling contract's k at those targets."""
    k = objective_scale(disc, scene.model.rigidity, scene.model.epsilon, alpha, beta)
    return np.array([alpha, beta, scene.model.C, k], float)


def at_point(nlp: NLP, scene: Scene, alpha: float, beta: float, x0: np.ndarray | None = None) -> NLP:
    """The parametric ``nlp`` (same graph) as the NLP of ``scene`` with targets (alpha, beta): its
    scales and multiplier conversion at those targets (pass ``parameter_values`` as p to IPOPT)."""
    k = parameter_values(scene, nlp.disc, alpha, beta)[3]
    return replace(nlp, scene=scene, alpha=float(alpha), beta=float(beta), f_scale=float(k),
                   g_scale=np.array([nlp.disc.volume, beta]), x0=nlp.x0 if x0 is None else x0)
