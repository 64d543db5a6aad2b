"""Problem data of a scene on a discretisation, shared by every solver path.

* ``constraint_data``: (alpha, beta) of (7), (8): given, or A_h, B_h of a target shape's tanh profile;
* ``initial_guess``: the start (a shape, or a phi.npz of an earlier solve: ``model.warm_start``, which
  resamples a file of another periodic grid of the same box);
* ``gradient_scale`` / ``objective_scale``: the scaling contract of the stopping test (documented in
  ``vesicle_opt.nlp.exact``): G_ref = 2 (E_ref / V) sqrt(|Omega| / (eps |Gamma|)) and
  k = rigidity m_bar G_ref, m_bar = |Omega| / N.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.mesh.base import Discretization
from vesicle_opt.model import functionals as F
from vesicle_opt.scene.schema import Scene
from vesicle_opt.model.warm_start import load_warm_start
from vesicle_opt.scene.shapes import phase_field

__all__ = ["constraint_data", "initial_guess", "load_warm_start", "gradient_scale", "objective_scale"]


def constraint_data(scene: Scene, disc: Discretization) -> tuple[float, float]:
    """(alpha, beta): given directly, or A_h and B_h of the target shape's tanh profile on this mesh."""
    c = scene.constraints
    eps = scene.model.epsilon
    alpha, beta = c.alpha, c.beta
    if c.target is not None:
        vals = F.evaluate(disc, phase_field(c.target, *disc.scene_points(), eps), eps, scene.model.C)
        alpha = vals["A"] if alpha is None else alpha
        beta = vals["B"] if beta is None else beta
    return float(alpha), float(beta)


def initial_guess(scene: Scene, disc: Discretization) -> np.ndarray:
    if scene.initial.shape == "file":
        phi0 = load_warm_start(scene.initial.file, disc)
    else:
        phi0 = phase_field(scene.initial, *disc.scene_points(), scene.model.epsilon)
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
