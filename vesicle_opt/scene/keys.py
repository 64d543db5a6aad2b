"""The scene key table: ``SCHEMA``, dotted key -> (kind, default, allowed), kind one of float,
float/auto (a number or the string 'auto'), int, str, bool, shape, box, ints; the allowed text is
what an InputError names. ``POSITIVE``: the
keys that must be > 0; ``known``: whether a dotted key is a scene key (``schema`` validates with it).
"""

from __future__ import annotations

from typing import Any

from vesicle_opt.scene.ranges import (BAND_MAX, BAND_MIN, CHOICES, EPS_PER_BOX_MAX, EPS_PER_H_MIN, LEVELS_MAX,
                                       M_AUTO, M_DEFAULT, M_LIMIT, TOL_RANGE)
from vesicle_opt.scene.shape_spec import SHAPE_KEYS

REQUIRED = object()  # the default of a key a scene must give
SCHEMA: dict[str, tuple[str, Any, Any]] = {
    "domain.box": ("box", REQUIRED, "list of [lo, hi] pairs with lo < hi, 2 or 3 of them"),
    "domain.boundary": ("str", "periodic", CHOICES["domain.boundary"]),
    "mesh.kind": ("str", "fem-p1", CHOICES["mesh.kind"]),
    "mesh.n": ("ints", REQUIRED, "integer >= 4, or one per dimension"),
    "mesh.mass": ("str", "lumped", CHOICES["mesh.mass"]),
    "mesh.quadrature": ("str", "nodal", CHOICES["mesh.quadrature"]),
    "mesh.file": ("str", None, "path to a mesh file meshio can read"),
    "mesh.refine": ("str", "none", CHOICES["mesh.refine"]),
    "mesh.levels": ("int", 2, f"1 <= levels <= {LEVELS_MAX} (mesh.refine = 'interface': the band's cells are the box's / 2^levels)"),
    "mesh.band": ("float", 8.0, f"{BAND_MIN + 1:g} <= band <= {BAND_MAX:g} (units of model.epsilon: the refined band's half-width)"),
    "model.epsilon": ("float", REQUIRED, f"h/{1 / EPS_PER_H_MIN:g} <= epsilon <= {EPS_PER_BOX_MAX:g} x the shortest box side"),
    "model.c0": ("float", 0.0, "any real"),
    "model.rigidity": ("float", 1.0, "> 0"),
    "constraints.alpha": ("float", None, "-|Omega| < alpha < |Omega|"),
    "constraints.beta": ("float", None, "> 0"),
    "constraints.target": ("shape", None, "a shape table"),
    "constraints.reduced_volume": ("float", None, "0 < reduced_volume <= 1, with constraints.area"),
    "constraints.area": ("float", None, "> 0 (area in 3D, perimeter in 2D), with constraints.reduced_volume"),
    "initial": ("shape", REQUIRED, "a shape table"),
    "solver.method": ("str", "exact", CHOICES["solver.method"]),
    "solver.M": ("float/auto", M_AUTO, f"{M_AUTO!r} (the penalty method's choice, from {M_DEFAULT:g} down to "
                 f"the certifiable M) or 0 < M <= {M_LIMIT:g} (solved as given)"),
    "solver.tol": ("float", 1e-8, f"{TOL_RANGE[0]:g} <= tol <= {TOL_RANGE[1]:g}"),
    "solver.max_iter": ("int", 500, ">= 1"),
    "solver.backend": ("str", "auto", CHOICES["solver.backend"]),
    "solver.second_order": ("bool", True, "true or false"),
    "solver.shape_check": ("bool", True, "true or false (false: a wrong shape, verify.shape, is reported, not refused)"),
    "solver.second_order_max_iter": ("int", 300, ">= 1 (LOBPCG iterations per level of the matrix-free check)"),
    "solver.M0": ("float", 100.0, f"0 < M0 <= M_max <= {M_LIMIT:g}"),
    "solver.M_factor": ("float", 10.0, "> 1"),
    "solver.M_max": ("float", 1e6, f"M0 <= M_max <= {M_LIMIT:g}"),
    "solver.max_outer": ("int", 20, ">= 1"),
    "solver.array": ("str", "numpy", CHOICES["solver.array"]),
    "solver.fft": ("str", "auto", CHOICES["solver.fft"]),
    "solver.max_memory_gb": ("float", None, "> 0 (GB; default: the memory available now)"),
    # gradient flows (vesicle_opt.flows)
    "flow.scheme": ("str", "penalty", CHOICES["flow.scheme"]),
    "flow.gamma": ("float", 1.0, "> 0"),
    "flow.dt": ("float", 1e-3, "> 0"),
    "flow.t_end": ("float", 1.0, "> 0"),
    "flow.steps": ("int", 100000, ">= 1"),
    "flow.stepping": ("str", "constant", CHOICES["flow.stepping"]),
    "flow.dt_min": ("float", 1e-12, "> 0"),
    "flow.dt_max": ("float", 1.0, "> 0"),
    "flow.steady_tol": ("float", 1e-6, ">= 0 (0: never stop early)"),
    "flow.law_tol": ("float", 1e-9, "> 0"),
    "flow.frames": ("int", 10, ">= 1"),
    "flow.checkpoint_every": ("int", 50, ">= 1"),
    "flow.initial": ("str", "projected", CHOICES["flow.initial"]),
}
POSITIVE = {"model.epsilon", "mesh.band", "model.rigidity", "constraints.beta", "constraints.area",
            "solver.M", "solver.tol", "solver.max_memory_gb",
            "solver.M0", "solver.M_max",
            "flow.gamma", "flow.dt", "flow.t_end", "flow.dt_min", "flow.dt_max", "flow.law_tol"}


def known(key: str) -> bool:
    """A scene key: one of ``SCHEMA``, or a shape key below ``initial`` / ``constraints.target``."""
    if key in SCHEMA:
        return True
    for base in ("initial", "constraints.target"):
        if key.startswith(base + ".") and key[len(base) + 1:] in SHAPE_KEYS:
            return True
    return False
