"""The gradient flow of a scene in memory: ``vesicle_opt.flow(scene, trackers=...)`` (py-pde style).

    import vesicle_opt as vo
    from vesicle_opt.flows.trackers import HistoryTracker, StopTracker
    sc = vo.load_scene("ellipse-2d", ["mesh.n=32", "flow.t_end=0.1"])
    res = vo.flow(sc, trackers=[HistoryTracker(), StopTracker(lambda row: row["energy"] < 8.0)])
    print(res.status, res.steps, res.t, res.energy, len(res.history))

No directory is needed: output, progress, checkpoints and stop criteria are trackers
(``flows.trackers``); ``flows.run.write_flow`` is this plus the directory trackers (the CLI verb).
``FlowResult.history`` holds the rows of the first ``HistoryTracker(keep=True)`` among the trackers
(empty without one: a long run keeps no rows unless asked to). Also here: the scene's flow pieces
(``build_model``, ``initial_field``, ``make_scheme``, ``stepper_options``) for callers that drive
``flows.stepper.run`` themselves with their own options (the flow studies).
"""

from __future__ import annotations

import copy
import hashlib
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

if TYPE_CHECKING:  # annotations only
    from vesicle_opt.scene import Scene

import numpy as np

from vesicle_opt import resources
from vesicle_opt.errors import InputError, SolverError
from vesicle_opt.mesh import Discretization, discretize
from vesicle_opt.mesh.base import require_lumped
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.model.warm_start import load_warm_start, start_field
from vesicle_opt.result import Status
from vesicle_opt.scene.argument import require_scene
from vesicle_opt.scene.shapes import phase_field
from vesicle_opt.flows.backward_euler import BackwardEulerScheme
from vesicle_opt.flows.backward_euler_nk import STEP_TOL, BackwardEulerNKScheme
from vesicle_opt.flows.discrete import FEATURE, WHY, FlowModel
from vesicle_opt.flows.lagrange import LagrangeScheme
from vesicle_opt.flows.penalty import PenaltyScheme
from vesicle_opt.flows.projection import project
from vesicle_opt.flows.stepper import FlowState, StepperOptions, run
from vesicle_opt.flows.trackers import CheckpointTracker, HistoryTracker, Tracker, as_tracker

SCHEMES = {"penalty": PenaltyScheme, "lagrange": LagrangeScheme, "backward-euler": BackwardEulerScheme}


def check_supported(scene) -> None:
    """Refuse what the flows do not support or what cannot fit in memory (``resources``), before any
    work (one-line InputError)."""
    if scene.mesh.kind not in ("fd", "fem-p1", "spectral"):
        raise InputError("mesh.kind", f"the gradient flows support 'fd', 'fem-p1' and 'spectral', "
                                      f"got {scene.mesh.kind!r}")
    if scene.flow.scheme == "backward-euler" and matrix_free_steps(scene) and scene.mesh.kind == "fem-p1":
        raise InputError("solver.backend", "'backward-euler' (23) by Newton-Krylov runs on 'fd' and 'spectral' "
                                           "grids; on 'fem-p1' use solver.backend = 'ipopt'")
    require_lumped(FEATURE, scene.mesh.mass, scene.mesh.quadrature, WHY)
    resources.check(scene, "flow")


def build_model(scene, disc: Discretization | None = None) -> FlowModel:
    disc = disc or discretize(scene)
    alpha, beta = constraint_data(scene, disc)
    return FlowModel(disc, scene.model.epsilon, scene.model.C, scene.model.rigidity, alpha, beta,
                     scene.solver.M_value, scene.flow.gamma)


def initial_field(scene, md: FlowModel) -> np.ndarray:
    """The scene's initial shape, projected onto A = alpha, B = beta (``projection``) unless
    ``flow.initial = "shape"`` (penalty and backward Euler only; (17) must start on the set)."""
    if scene.initial.shape == "file":  # an earlier solve's phi.npz (resampled from another periodic grid)
        phi0 = load_warm_start(scene.initial.file, md.disc)
    else:
        phi0 = phase_field(scene.initial, *md.disc.scene_points(), scene.model.epsilon)
    if scene.flow.initial == "projected" or scene.flow.scheme == "lagrange":
        phi0 = project(md, phi0, md.alpha, md.beta, volume_first=scene.initial.shape != "file")
    return phi0


def matrix_free_steps(scene) -> bool:
    """Whether (23) steps go to the Newton-Krylov minimiser (``flows.backward_euler_nk``) rather
    than IPOPT: always on spectral grids (no assembled Laplacian), and where ``solver.backend`` is
    'newton-krylov' (FD grids). 'auto' keeps IPOPT on FD/P1 (the flows' historical path)."""
    return scene.mesh.kind == "spectral" or scene.solver.backend == "newton-krylov"


def make_scheme(scene, md: FlowModel):
    if scene.flow.scheme == "backward-euler" and matrix_free_steps(scene):
        return BackwardEulerNKScheme(md, law_tol=scene.flow.law_tol, tol=min(STEP_TOL, scene.solver.tol))
    return SCHEMES[scene.flow.scheme](md, law_tol=scene.flow.law_tol)


def stepper_options(scene, scheme=None) -> StepperOptions:
    """The scene's ``flow.*`` stepping keys; a scheme may name its own adaptive-k thresholds
    (``scheme.controller``: what counts as an easy / hard solve in its iteration count)."""
    fl = scene.flow
    opts = StepperOptions(dt=fl.dt, t_end=fl.t_end, max_steps=fl.steps, adaptive=fl.stepping == "adaptive",
                          dt_min=fl.dt_min, dt_max=fl.dt_max, steady_tol=fl.steady_tol)
    return replace(opts, **getattr(scheme, "controller", {}))


@dataclass(frozen=True, eq=False)
class FlowResult:
    """The end of a flow run. ``status`` is a ``Status`` (T_END, STEADY, MAX_STEPS, STOPPED, FAILED);
    on FAILED, ``phi`` is the last accepted field. ``observed`` holds the scheme's columns of the final
    field (energy = kappa E_h, penalized_energy = E_M, volume_residual, area_residual);
    ``flow(scene, resume_from=result.state)`` continues the run."""

    phi: np.ndarray
    t: float
    steps: int
    status: Status
    message: str
    rejections: int
    wall_time_s: float
    model: FlowModel
    scheme: str
    law: str
    observed: dict
    history: tuple
    state: FlowState
    resumed_from_step: int = 0

    @property
    def energy(self) -> float:
        """rigidity * E_h of the final field (``observed["energy"]``)."""
        return float(self.observed["energy"])

    @property
    def failed(self) -> bool:
        """True when the run ended FAILED (a step rejected down to flow.dt_min)."""
        return self.status is Status.FAILED


def _field(md: FlowModel, phi, key: str) -> np.ndarray:
    phi = np.asarray(phi, dtype=float)
    if phi.shape != (md.disc.n_nodes,):
        raise InputError(key, f"expected a field of shape ({md.disc.n_nodes},), got {phi.shape}")
    if not np.all(np.isfinite(phi)):
        raise InputError(key, "the field has non-finite entries")
    return phi


def fingerprint(scene) -> str:
    """Identifies the problem a checkpoint belongs to (not t_end, steps, frames: those may change)."""
    # the placeholders (dt = t_end = 0) lie outside the ranges a Flow is built with (scene.ranges):
    # set on a copy, so the key (and every checkpoint's fingerprint) is what it was
    neutral = copy.copy(scene.flow)
    for name, value in dict(t_end=0.0, steps=1, frames=1, dt=0.0, stepping="constant", checkpoint_every=1).items():
        object.__setattr__(neutral, name, value)
    key = replace(scene, name="", flow=neutral)
    return hashlib.sha256(repr(key).encode()).hexdigest()[:16]


def flow(scene: Scene, *, trackers: Sequence[Tracker | Callable] = (), x0: np.ndarray | str | Path | object = None,
         phi0: np.ndarray | None = None, resume_from: FlowState | str | Path | None = None,
         throw: bool = False, model: FlowModel | None = None, scheme: object = None) -> FlowResult:
    """Run ``scene.flow`` in memory and return a frozen ``FlowResult``.

    trackers: ``flows.trackers`` objects, or callables ``fn(state, row)`` (a True return stops the run).
    x0: the start, the argument name of ``solve`` too: a field, a path to a phi.npz or an earlier
    Result / FlowResult (another periodic grid of the same box is Fourier-resampled,
    ``model.warm_start``); used as given. phi0: the deprecated old name of x0 (a DeprecationWarning).
    Default (neither): ``initial_field(scene, model)``; (17) needs it on
    A = alpha, B = beta: ``flows.projection.project``). resume_from: a ``FlowState`` (e.g.
    ``result.state``) or a checkpoint file a ``CheckpointTracker`` wrote; the run continues from it
    bit-for-bit. throw: raise ``SolverError`` (carrying the result) when the run failed.
    model: a ``build_model(scene)`` to reuse (e.g. the one a tracker evaluates energies with).
    scheme: a ``make_scheme(scene, model)`` to reuse (e.g. one whose multiplier shift a caller sets)."""
    require_scene(scene)
    check_supported(scene)
    md = model if model is not None else build_model(scene)
    scheme = scheme if scheme is not None else make_scheme(scene, md)
    trackers = tuple(as_tracker(tr) for tr in trackers)
    tag = fingerprint(scene)
    for tr in trackers:  # checkpoints say which problem they belong to
        if isinstance(tr, CheckpointTracker) and tr.fingerprint is None:
            tr.fingerprint = tag
    start = None
    if phi0 is not None:  # the old name of x0 (one warm-start argument, as solve's): an alias
        if x0 is not None:
            raise InputError("x0", "give x0 only (phi0 is its deprecated old name), not both")
        warnings.warn("flow(phi0=...) is deprecated; pass the start as x0= (solve's name)",
                      DeprecationWarning, stacklevel=2)
        x0 = phi0
    if x0 is not None:
        phi0 = start_field(x0, md.disc, "x0")
    if resume_from is not None:
        if phi0 is not None:
            raise InputError("x0", "give x0 or resume_from, not both")
        start = (resume_from if isinstance(resume_from, FlowState)
                 else CheckpointTracker.load(resume_from, tag, md.disc.n_nodes))
        if start is None:
            raise InputError("resume_from", f"no checkpoint at {resume_from}")
        phi_start = _field(md, start.phi, "resume_from")
    else:
        phi_start = initial_field(scene, md) if phi0 is None else _field(md, phi0, "x0")
    out = run(scheme, phi_start, stepper_options(scene, scheme), trackers, start=start)
    history = next((tuple(tr.rows) for tr in trackers if isinstance(tr, HistoryTracker) and tr.keep), ())
    result = FlowResult(out.phi, out.t, out.step, out.status, out.message, out.rejections, out.wall_time_s,
                        md, scene.flow.scheme, scheme.law, scheme.observe(out.phi), history, out.state,
                        start.step if start is not None else 0)
    if throw and result.failed:
        raise SolverError(f"flow failed: {out.message}", result)
    return result
