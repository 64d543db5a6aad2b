"""One parametric NLP and one IPOPT solver per mesh, reused by every exact solve on that mesh.

A branch walked through the front door (``solve(scene_v, x0=previous_result)``) on an
interface-refined meridian mesh (``mesh.band_start`` reuses the previous result's mesh while its
interface stays in the band) solves the same discrete problem (6)-(8) with other targets (alpha,
beta) or another C. Building its CasADi graph and IPOPT solver again at each point cost more than
the warm solve itself (measured at eps/R0 = 0.02, 12 k nodes: graph 0.11 s, ``nlpsol`` 0.14 s, the
second-order check's Hessian graph 0.09 s, against 0.2-0.3 s of IPOPT iterations). So, per mesh
(``weakref``: the entry dies with the mesh), this module keeps

* the parametric NLP (``nlp.exact.build_exact(parametric=True)``, p = (alpha, beta, C, f_scale): at
  each point the NLP the front door would build, ``nlp.exact.at_point``) and its IPOPT solver;
* IPOPT's own derivative functions ``nlp_hess_l`` and ``nlp_jac_g`` of that solver, which the
  assembled second-order check (``verify.second_order.check``) evaluates instead of building its own
  Hessian graph (the same matrix: 0.0 apart, measured).

The warm start takes the previous point's physical multipliers (``lambda_volume``,
``lambda_area``) converted to this point's scaled rows, with ``ipopt.warm_start_init_point``.
"""

from __future__ import annotations

import dataclasses
import weakref

import numpy as np
import scipy.sparse as sp

from vesicle_opt.model.problem import constraint_data
from vesicle_opt.nlp.exact import at_point, build_exact, parameter_values
from vesicle_opt.nlp.ipopt import IpoptOptions, make_solver

WARM = (("ipopt.warm_start_init_point", "yes"),)  # IPOPT takes the given multipliers (no bounds, no
# inequalities: nothing else to warm)
_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()  # disc -> {key: (nlp, solver)}


def _key(scene, options: IpoptOptions, warm: bool):
    """What the graph and the solver depend on besides the mesh: eps, the rigidity (constants of
    the graph) and the IPOPT options."""
    return (scene.model.epsilon, scene.model.rigidity, options, warm)


def parametric(scene, disc, options: IpoptOptions, warm: bool):
    """(parametric NLP, IPOPT solver) of ``disc`` for the scene's eps and rigidity, built once."""
    entries = _CACHE.setdefault(disc, {})
    key = _key(scene, options, warm)
    if key not in entries:
        nlp = build_exact(scene, disc, check=False, parametric=True)
        opts = dataclasses.replace(options, extra=WARM + tuple(options.extra)) if warm else options
        entries[key] = (nlp, make_solver(nlp, opts))
    return entries[key]


def point(scene, disc, options: IpoptOptions, start):
    """(NLP of this point, solver, p, IPOPT start kwargs) for an exact solve of ``scene`` on ``disc``
    from ``start`` (a Result on ``disc``, or None / a field: cold)."""
    warm = getattr(start, "lambda_volume", None) is not None and getattr(start, "disc", None) is disc \
        and np.isfinite(start.lambda_volume) and np.isfinite(start.lambda_area)
    nlp_p, solver = parametric(scene, disc, options, warm)
    alpha, beta = constraint_data(scene, disc)
    nlp = at_point(nlp_p, scene, alpha, beta)
    p = parameter_values(scene, disc, alpha, beta)
    if not warm:
        return nlp, solver, p, {}
    lam_g0 = -np.array([start.lambda_volume, start.lambda_area]) * nlp.g_scale / nlp.f_scale  # NLP.multipliers^-1
    x0 = np.asarray(start.x, float) if start.x is not None and start.x.size == nlp.x0.size else nlp.from_phi(start.phi)
    return nlp, solver, p, {"x0": x0, "lam_g0": lam_g0}


def derivatives(nlp, solver, p):
    """(hessian_of(x, lam_g), jacobian_of(x)) for ``verify.second_order.check`` from the solver's
    own functions: the physical Hessian of the Lagrangian (f_scale times IPOPT's, its upper triangle
    mirrored) and the constraint Jacobian, at the parameters p."""
    hess, jac = solver.get_function("nlp_hess_l"), solver.get_function("nlp_jac_g")

    def hessian_of(x, lam_g):
        H = sp.csr_matrix(hess(x, p, 1.0, lam_g).sparse())
        return (H + sp.triu(H, 1).T).tocsr() * nlp.f_scale  # IPOPT's is the upper triangle

    def jacobian_of(x):
        return sp.csr_matrix(jac(x, p)[1].sparse())
    return hessian_of, jacobian_of
