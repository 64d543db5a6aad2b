"""The frozen result of an equilibrium solve, and its JSON summary (the CLI's output contract)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class Result:
    """phi (and w) with energies, residuals and multipliers in the convention
    rigidity * grad E_h = lambda_volume grad A + lambda_area grad B  (at a KKT point).

    ``success`` is the solver's own verdict; ``converged`` additionally requires the independently
    recomputed KKT and constraint residuals to meet the tolerance. Never trust phi unless converged.
    """

    phi: np.ndarray
    w: np.ndarray | None
    energy: float  # rigidity * E_h(phi), never with penalty terms
    volume_residual: float  # A - alpha
    area_residual: float  # B - beta
    lambda_volume: float
    lambda_area: float
    kkt_residual: float  # relative L2 norm of the Lagrangian gradient (see kkt.py)
    status: str
    success: bool
    converged: bool
    iterations: int
    wall_time_s: float
    derivative_time_s: float  # gradient, Jacobian and Hessian evaluations
    other_time_s: float  # everything else: linear algebra inside IPOPT, function values
    n_nodes: int
    hessian_nnz_per_row: float
    method: str = "exact"
    M: float | None = None
    penalized_energy: float | None = None
    history: dict = field(default_factory=dict)
    x: np.ndarray | None = None  # the full NLP vector, with lam_x and lam_g for warm starts
    lam_x: np.ndarray | None = None
    lam_g: np.ndarray | None = None
    extra: dict = field(default_factory=dict)

    def summary(self, scene_name: str) -> dict:
        """The summary.json dict; numbers that are not finite are written as null."""
        def num(v):
            if v is None:
                return None
            v = float(v)
            return v if math.isfinite(v) else None
        out = {
            "scene": scene_name, "method": self.method,
            "energy": num(self.energy), "volume_residual": num(self.volume_residual),
            "area_residual": num(self.area_residual), "lambda_volume": num(self.lambda_volume),
            "lambda_area": num(self.lambda_area), "kkt_residual": num(self.kkt_residual),
            "status": self.status, "success": bool(self.success), "converged": bool(self.converged),
            "iterations": int(self.iterations), "wall_time_s": num(self.wall_time_s),
            "derivative_time_s": num(self.derivative_time_s), "other_time_s": num(self.other_time_s),
            "n_nodes": int(self.n_nodes), "hessian_nnz_per_row": num(self.hessian_nnz_per_row),
        }
        if self.M is not None:
            out["M"] = num(self.M)
            out["penalized_energy"] = num(self.penalized_energy)
        def item(v):
            if isinstance(v, bool) or v is None or isinstance(v, (str, list)):
                return v
            if isinstance(v, (int, np.integer)):
                return int(v)
            return num(v)
        out.update({k: item(v) for k, v in self.extra.items()})
        return out
