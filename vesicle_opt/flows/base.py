"""What every time scheme returns for one step, and the columns it observes (physics lives here,
not in the stepper)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vesicle_opt.model.penalty import penalised_energy
from vesicle_opt.flows.discrete import FlowModel


@dataclass(frozen=True)
class StepOutcome:
    """One attempted step phi^n -> phi^{n+1} with step k.

    ``law_residual`` is the scheme's own energy law, relative to |E(phi^n)|:
    (17), (18): (E(phi^{n+1}) - E(phi^n) + ||phi^{n+1} - phi^n||^2 / (gamma k)) / |E(phi^n)|, = 0 exactly;
    (23): the left side of (24), (E_M^{n+1} - E_M^n + ||.||^2 / (2 gamma k)) / |E_M^n|, must be <= 0.
    """

    phi: np.ndarray
    converged: bool
    iterations: int
    message: str
    law_residual: float = float("nan")
    law_ok: bool = False
    rate: float = float("nan")  # ||phi^{n+1} - phi^n|| / k, the discrete ||phi_t||
    linear_iterations: int = 0  # GMRES iterations of the step (matrix-free grids; 0 for direct solves)
    extra: dict = field(default_factory=dict)


def observe(model: FlowModel, phi: np.ndarray) -> dict:
    """History columns of a field: energy (kappa E_h), penalized_energy (E_M, as ``FlowModel.E_M``),
    A - alpha, B - beta."""
    E_h, res = model.E_h(phi), model.residuals(phi)
    return {"energy": model.rigidity * E_h,
            "penalized_energy": penalised_energy(model.rigidity, E_h, res, model.M, model.M),
            "volume_residual": res[0], "area_residual": res[1]}


class Scheme:
    """What the stepper asks of a scheme besides ``step``: the energy its law decreases
    (E_M for the penalty schemes (18), (23); E for (17), set ``penalised = False``) and the
    observed history columns."""

    penalised = True
    model: FlowModel

    def energy(self, phi):
        return self.model.E_M(phi) if self.penalised else self.model.E(phi)

    def observe(self, phi):
        return observe(self.model, phi)


def equality_law(model: FlowModel, energy, phi_n, phi, k) -> tuple[float, float]:
    """(relative residual of E(phi) - E(phi_n) + ||phi - phi_n||^2/(gamma k), ||phi - phi_n||/k)."""
    d = phi - phi_n
    dd = model.norm2(d)
    E0 = energy(phi_n)
    return (energy(phi) - E0 + dd / (model.gamma * k)) / abs(E0), float(np.sqrt(dd)) / k
