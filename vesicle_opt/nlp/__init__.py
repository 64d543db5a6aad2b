"""The IPOPT path: the discrete problem as a CasADi NLP with exact constraints, or lifted penalty.

* ``exact``: the NLP (6)-(8) and its scaling contract; ``lifted``: the penalty NLP (11) with M (and
  the multiplier shifts mu) as CasADi parameters;
* ``ipopt``: frozen options, one solver built once, one call, its statistics;
* ``solve``: one certified IPOPT call (exact, or one penalty stage); ``continuation``: the methods
  continuation and augmented on one solver, warm-started stage after stage;
* ``scp``: a Gauss-Newton SCP baseline with cvxpy (studies only);
* ``reuse``: one parametric NLP and IPOPT solver per interface-refined mesh, reused by every exact
  solve on it (the front door's warm path), with the axial translation pinned.

``build_nlp(scene)`` is the raw CasADi door (``.as_dict()`` goes to any ``ca.nlpsol``);
``solve_nlp(nlp)`` runs the method the NLP was built for. The front door is ``vesicle_opt.solve``.
"""

from __future__ import annotations

import dataclasses

from vesicle_opt.errors import NotSupported
from vesicle_opt.scene.argument import require_scene
from vesicle_opt.nlp.continuation import solve_penalised
from vesicle_opt.nlp.exact import NLP, build_exact
from vesicle_opt.nlp.ipopt import IpoptOptions
from vesicle_opt.nlp.lifted import PenaltyNLP, build_penalty_nlp
from vesicle_opt.nlp.solve import solve_exact
from vesicle_opt.result import Result

__all__ = ["NLP", "PenaltyNLP", "IpoptOptions", "build_nlp", "solve_nlp"]


def build_nlp(scene: "Scene", disc: "Discretization | None" = None, check: bool = True) -> NLP:
    """The NLP of a scene's ``solver.method``: the exact NLP (6)-(8) for ``exact``, the lifted
    penalty NLP (11) for penalty, continuation and augmented. A ``spectral`` mesh has a dense
    Laplacian and no NLP: refused with :class:`NotSupported` (use the newton-krylov backend)."""
    require_scene(scene)
    if scene.mesh.kind == "spectral":
        raise NotSupported("mesh.kind", "'spectral' has a dense Laplacian and no CasADi NLP; "
                           "build_nlp supports 'fem-p1' and 'fd' (solve spectral scenes with "
                           "solver.backend = 'newton-krylov')")
    exact_scene = scene.replace(solver=dataclasses.replace(scene.solver, method="exact"))
    exact = build_exact(exact_scene, disc, check)
    if scene.solver.method == "exact":
        return exact
    return dataclasses.replace(build_penalty_nlp(exact), scene=scene)


def solve_nlp(nlp: NLP, *, x0=None, lam_x0=None, lam_g0=None, solver=None,
              options: IpoptOptions | None = None) -> Result:
    """IPOPT on an NLP of ``build_nlp``: the exact solve, or the penalised method of its scene."""
    if isinstance(nlp, PenaltyNLP):
        return solve_penalised(nlp, x0=x0, lam_x0=lam_x0, lam_g0=lam_g0, solver=solver, options=options)
    return solve_exact(nlp, x0=x0, lam_x0=lam_x0, lam_g0=lam_g0, solver=solver, options=options)
