"""Problem data of a scene on a discretisation, shared by every solver path.

* ``constraint_data``: (alpha, beta) of (7), (8): given, or A_h, B_h of a target shape's tanh profile;
* ``initial_guess`` / ``load_warm_start``: the start (a shape, or a phi.npz of an earlier solve);
* ``gradient_scale`` / ``objective_scale``: the scaling contract of the stopping test (documented in
  ``vesicle_opt.nlp.exact``): G_ref = 2 (E_ref / V) sqrt(|Omega| / (eps |Gamma|)) and
  k = rigidity m_bar G_ref, m_bar = |Omega| / N.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.errors import InputError
from vesicle_opt.mesh.base import Discretization
from vesicle_opt.model import functionals as F
from vesicle_opt.scene.schema import Scene
from vesicle_opt.scene.shapes import phase_field


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
