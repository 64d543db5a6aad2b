"""The frozen result of an equilibrium solve, its status vocabulary, and its JSON summary.

``Status`` is the one vocabulary of outcomes across IPOPT, Newton-Krylov and the gradient flows
(optimistix style); the solver's own status string (IPOPT's ``return_status``, the Newton-Krylov
loop's ``status``) is kept beside it in ``Result.status``. Results are built in one place only,
``vesicle_opt.verify.certify.build_result``, which recomputes every residual it reports.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass, field

import numpy as np


class Status(str, enum.Enum):
    """Outcome of a solve or a flow (the ``outcome`` key of summary.json)."""

    # equilibrium solves (certified by ``verify.certify.certify``)
    CONVERGED = "converged"  # solver success and every recomputed residual within tol
    MAX_ITERATIONS = "max_iterations"  # the solver ran out of iterations
    SOLVER_FAILED = "solver_failed"  # the solver reported another failure
    NON_FINITE = "non_finite"  # the iterate has NaN or inf entries
    ROUNDOFF_FLOOR = "roundoff_floor"  # stationarity cannot be known to tol in double precision
    INFEASIBLE = "infeasible"  # the constraints A = alpha, B = beta do not hold to tol
    KKT_NOT_MET = "kkt_not_met"  # the recomputed KKT residual exceeds its bound
    NOT_CERTIFIED = "not_certified"  # another consistency check failed (it says which)
    WRONG_SHAPE = "wrong_shape"  # a KKT point, but not the vesicle asked (verify.shape: bulk, merged images)
    # gradient flows (``vesicle_opt.flows``)
    T_END = "t_end"  # reached the final time
    STEADY = "steady"  # ||phi_t|| fell below flow.steady_tol times its first value
    MAX_STEPS = "max_steps"  # reached flow.steps accepted steps
    STOPPED = "stopped"  # a tracker asked to stop
    FAILED = "failed"  # a step was rejected down to flow.dt_min

    def __str__(self) -> str:  # the value, so f-strings and JSON read "converged"
        return self.value


@dataclass(frozen=True, eq=False)
class Result:
    """phi (and w) with energies, residuals and multipliers in the convention
    rigidity * grad E_h = lambda_volume grad A + lambda_area grad B  (at a KKT point).

    ``success`` is the solver's own verdict; ``converged`` (and ``outcome``) additionally require
    the independently recomputed KKT and constraint residuals to meet the tolerance and the
    round-off floor to lie below it. Never trust phi unless converged.
    """

    phi: np.ndarray
    w: np.ndarray | None
    energy: float  # rigidity * E_h(phi), never with penalty terms
    volume_residual: float  # A - alpha
    area_residual: float  # B - beta
    lambda_volume: float
    lambda_area: float
    kkt_residual: float  # relative L2 norm of the Lagrangian gradient (see verify.kkt)
    status: str  # the solver's own status string
    success: bool
    converged: bool
    outcome: Status
    iterations: int
    wall_time_s: float
    derivative_time_s: float  # gradient, Jacobian and Hessian evaluations
    other_time_s: float  # everything else: linear algebra, function values
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
    disc: object = field(default=None, repr=False)  # the discretisation phi lives on (for writers, plots)
    scene: object = field(default=None, repr=False)  # the Scene solved (``vo.solve``, ``vo.load_result``)

    @property
    def reason(self) -> str | None:
        """Why the result is not converged (None when it is)."""
        return self.extra.get("reason")

    # --- the physical and verification quantities of ``extra``, as attributes (read-only views) ---
    def _num(self, key: str) -> float | None:
        v = self.extra.get(key)
        return None if v is None else float(v)

    @property
    def volume(self) -> float | None:
        """The enclosed volume (area in 2D) implied by A(phi): V = (|Omega| + A) / 2 (Section 3.1, (4))."""
        return self._num("volume")

    @property
    def area(self) -> float | None:
        """The membrane area (perimeter in 2D) implied by B(phi): S = 3 sqrt(2) B / 4 (Section 3.1, (5))."""
        return self._num("area")

    @property
    def reduced_volume(self) -> float | None:
        """V / ((4 pi / 3) R0^3) with R0 = sqrt(S / 4 pi) in 3D, 4 pi V / S^2 (reduced area) in 2D:
        1 for the sphere / circle (``geometry.reduced_volume``)."""
        return self._num("reduced_volume")

    @property
    def reduced_energy(self) -> float | None:
        """E / (rigidity E_sphere): E_sphere = 16 sqrt(2) pi / 3 (3D) or 2 sqrt(2) pi / (3 R) for the
        circle of the same perimeter (2D), the eps -> 0 limit of (3) (``geometry.sphere_energy``)."""
        return self._num("reduced_energy")

    @property
    def second_order(self) -> str | None:
        """``"minimum"``, ``"saddle"`` or ``"not checked"`` (the tangent-Hessian check of ``vo.solve``)."""
        return self.extra.get("second_order")

    @property
    def second_order_min_eigenvalue(self) -> float | None:
        """The least eigenvalue of the reduced Hessian (mu_ref units, symmetry modes excluded);
        negative at a saddle, None when not checked."""
        return self._num("second_order_min_eigenvalue")

    @property
    def topology(self) -> str | None:
        """The inside's topology of the phi > 0 set (in words, ``verify.topology``: e.g. ``"disk-like"``)."""
        return self.extra.get("topology")

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
            "status": self.status, "outcome": self.outcome.value, "success": bool(self.success),
            "converged": bool(self.converged),
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


def stage_record(r: Result) -> dict:
    """One stage of a continuation or augmented Lagrangian, as ``history['stages']`` keeps it."""
    return {"M": r.M, "energy": r.energy, "penalized_energy": r.penalized_energy,
            "volume_residual": r.volume_residual, "area_residual": r.area_residual,
            "lambda_volume": r.lambda_volume, "lambda_area": r.lambda_area,
            "kkt_residual": r.kkt_residual, "iterations": r.iterations, "wall_time_s": r.wall_time_s,
            "status": r.status, "converged": r.converged}


def polish_keys(r: Result) -> dict:
    """The ``polish_*`` summary keys of a continuation's augmented polish stage."""
    return {"polish": "augmented", "polish_converged": bool(r.converged), "polish_outcome": str(r.outcome),
            "polish_energy": r.energy, "polish_lambda_volume": r.lambda_volume, "polish_lambda_area": r.lambda_area,
            "polish_volume_residual": r.volume_residual, "polish_area_residual": r.area_residual,
            "polish_kkt_dual": r.extra.get("kkt_dual"), "polish_iterations": r.iterations,
            "polish_wall_time_s": r.wall_time_s}


def combine_stages(last: Result, stages: list[Result], method: str, t_wall: float,
                   extra: dict | None = None, iterations: int | None = None,
                   derivative_time_s: float | None = None) -> Result:
    """The last stage's result with the whole run's counts, times and stage history; its certificate
    is the last stage's (nothing here changes ``converged``). The run's iterations and derivative
    time are the stages' sums unless given (a run with work outside its stages: coarse levels)."""
    history = dict(last.history)
    history["stages"] = [stage_record(r) for r in stages]
    info = dict(last.extra)
    info.update({"stages": len(stages)}, **(extra or {}))
    deriv = sum(r.derivative_time_s for r in stages) if derivative_time_s is None else derivative_time_s
    its = sum(r.iterations for r in stages) if iterations is None else iterations
    return dataclasses.replace(
        last, method=method, iterations=int(its), wall_time_s=t_wall,
        derivative_time_s=deriv, other_time_s=t_wall - deriv, history=history, extra=info)
