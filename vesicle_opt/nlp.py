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
test (``kkt.py``) is the relative L2 norm |r| / D with D = |rigidity dE| + |lambda_A dA| +
|lambda_B dB|. At a solution D is dominated by the volume pressure lambda_A ~ E / V acting on all of
Omega, D ~ 2 (E / V) sqrt|Omega|, while r lives on the interface band, |r|_L2 ~ |r|_max
sqrt(eps |Gamma|). G_ref = D_ref / sqrt(eps |Gamma|) is that conversion, so IPOPT's tol and
kkt_residual measure the same relative stationarity (measured kkt_residual / IPOPT's final dual
infeasibility: 0.19 - 0.55 for exact solves of ellipse-2d over eps = 0.1 - 0.4, h = 1/16 - 1/4,
1.3 for the penalty at M = 1e4; 7 - 12 for a sphere, whose gradient terms nearly vanish). Every factor has the units of
rigidity dE / dphi per volume, so a geometrically similar problem (box, shape, eps scaled by s)
takes the same iterations to the same relative residuals. The constraint rows are relative to
|Omega| and beta, as in ``solve``'s feasibility test. IPOPT's own gradient-based rescaling is off
(``IpoptOptions``): it would rescale f by 100 / |grad f(x0)|, a test that depends on the start.
The penalty NLP (``penalty.py``) reuses k and the g scales, so the test is the same at every M.
IPOPT's multipliers lam_g of these scaled rows convert to the physical convention
    rigidity * grad E_h = lambda_A grad A + lambda_B grad B
by lambda_A = -k lam_g[0] / |Omega|, lambda_B = -k lam_g[1] / beta (``NLP.multipliers``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from . import functionals as F
from .discretization import Discretization, discretize
from .errors import InputError
from .feasibility import check_feasible
from .scene import Scene
from .shapes import phase_field


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

    def as_dict(self) -> dict:
        return {"x": self.x, "f": self.f, "g": self.g, "p": self.p}

    @property
    def n_phi(self) -> int:
        return self.disc.n_nodes

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        x = np.asarray(x, float).ravel()
        n = self.n_phi
        return x[:n], (x[n:] if self.disc.consistent else None)

    def multipliers(self, lam_g: np.ndarray) -> tuple[float, float]:
        """Physical (lambda_A, lambda_B) from IPOPT's lam_g (see the module docstring)."""
        k = self.f_scale
        lam = np.asarray(lam_g, float).ravel()[:2]
        return float(-k * lam[0] / self.g_scale[0]), float(-k * lam[1] / self.g_scale[1])


def constraint_data(scene: Scene, disc: Discretization) -> tuple[float, float]:
    """(alpha, beta): given directly, or A_h and B_h of the target shape's tanh profile on this mesh."""
    c = scene.constraints
    eps = scene.model.epsilon
    alpha, beta = c.alpha, c.beta
    if c.target is not None:
        vals = F.evaluate(disc, phase_field(c.target, disc.nodes, disc.box, eps), eps, scene.model.C)
        alpha = vals["A"] if alpha is None else alpha
        beta = vals["B"] if beta is None else beta
    return float(alpha), float(beta)


def load_warm_start(path: str, disc: Discretization) -> np.ndarray:
    """phi from a phi.npz of an earlier solve on the same mesh; InputError if unusable."""
    try:
        with np.load(path) as data:
            phi = np.asarray(data["phi"], float)
    except FileNotFoundError:
        raise InputError("initial.file", f"file not found: {path}") from None
    except Exception as exc:  # zip/pickle/key errors of a corrupt or foreign file
        raise InputError("initial.file", f"{path} is not a phi.npz written by vesicle-opt ({type(exc).__name__})") from None
    if phi.shape != (disc.n_nodes,):
        raise InputError("initial.file", f"{path} holds {phi.size} values, this mesh has {disc.n_nodes} nodes")
    if not np.all(np.isfinite(phi)):
        raise InputError("initial.file", f"{path} contains non-finite values")
    return phi


def initial_guess(scene: Scene, disc: Discretization) -> np.ndarray:
    if scene.initial.shape == "file":
        phi0 = load_warm_start(scene.initial.file, disc)
    else:
        phi0 = phase_field(scene.initial, disc.nodes, disc.box, scene.model.epsilon)
    if disc.consistent:
        return np.concatenate([phi0, disc.apply_laplacian(phi0)])
    return phi0


def gradient_scale(disc: Discretization, epsilon: float, alpha: float, beta: float) -> float:
    """G_ref of the module docstring: 2 (E_ref / V) sqrt(|Omega| / (eps |Gamma|)), energy per volume."""
    volume = F.enclosed_volume(alpha, disc.volume)  # > 0: check_feasible refuses alpha <= -|Omega|
    band = epsilon * F.surface_area(beta)  # measure of the interface band, ~ eps |Gamma|
    return 2 * F.sharp_energy_sphere(beta, disc.dim) / volume * np.sqrt(disc.volume / band)


def objective_scale(disc: Discretization, rigidity: float, epsilon: float, alpha: float, beta: float) -> float:
    """k of the module docstring: the objective rigidity E_h (or any energy in its units) is divided
    by rigidity * m_bar * G_ref (every NLP of the package: exact, penalty, the minimising movement)."""
    m_bar = disc.volume / disc.n_nodes
    return rigidity * m_bar * gradient_scale(disc, epsilon, alpha, beta)


def build_nlp(scene: Scene, disc: Discretization | None = None, check: bool = True) -> NLP:
    """Build the exact-constraint NLP (6)-(8) of a scene (``solver.method = 'exact'``); for the
    methods penalty, continuation and augmented, the lifted penalty NLP (11) (``penalty.py``)."""
    if scene.solver.method != "exact":
        from .penalty import build_penalty_nlp
        exact = build_nlp(scene.replace(solver=replace(scene.solver, method="exact")), disc, check)
        return replace(build_penalty_nlp(exact), scene=scene)
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
        lap = ca.mtimes(ca.DM(disc.laplacian.tocsc()), phi)
    E = F.energy(ops, phi, lap, eps, C)
    A = F.volume_functional(ops, phi)
    B = F.area_functional(ops, phi, eps)
    f_scale = objective_scale(disc, scene.model.rigidity, eps, alpha, beta)
    g_scale = np.array([disc.volume, beta])
    rows = [(A - alpha) / g_scale[0], (B - beta) / g_scale[1]]
    if disc.consistent:
        rows.append(eps**2 / m_bar * (ca.mtimes(ca.DM(disc.M.tocsc()), lap) + ca.mtimes(ops.K, phi)))
    g = ca.vertcat(*rows)
    ng = g.shape[0]
    inf = np.full(x.shape[0], np.inf)
    return NLP(scene=scene, disc=disc, alpha=alpha, beta=beta, x=x,
               f=scene.model.rigidity * E / f_scale, g=g, p=ca.MX.sym("p", 0),
               x0=initial_guess(scene, disc), lbx=-inf, ubx=inf, lbg=np.zeros(ng), ubg=np.zeros(ng),
               f_scale=f_scale, g_scale=g_scale)
