"""One parametric NLP and one IPOPT solver per mesh, reused by every exact solve on that mesh.

A branch walked through the front door (``solve(scene_v, x0=previous_result)``) on an
interface-refined meridian mesh (``mesh.band_start`` reuses the previous result's mesh while its
interface stays in the band) solves the same discrete problem (6)-(8) with other targets (alpha,
beta) or another C. Building its CasADi graph and IPOPT solver again at each point cost more than
the warm solve itself (measured at eps/R0 = 0.02, 12 k nodes: graph 0.11 s, ``nlpsol`` 0.14 s, the
second-order check's Hessian graph 0.09 s, against 0.2-0.3 s of IPOPT iterations). So, per mesh
(``weakref``: the entry dies with the mesh), this module keeps

* the parametric NLP (``nlp.exact.build_exact(parametric=True)``, p = (alpha, beta, C, f_scale): at
  each point the NLP the front door would build, ``nlp.exact.at_point``) and its IPOPT solver (MUMPS
  ordered by QAMD, ``ORDERING``);
* a pin: one linear row c . phi = 0 holding the axial translation: the centre of mass of the inside,
  int z (1 + phi) / int (1 + phi), at the box's mid-height z_m (``pin_row``: c = m (z - z_m), the same
  row at every point and whatever the start). Between natural walls the translation is only nearly
  null (+-1e-5 mu_ref on the mesh); unpinned, IPOPT spent 34-59 iterations sliding along it at
  eps/R0 = 0.02 (regularised, tiny decreases). On an up-down mirrored mesh (``refine.mirrored_tensor``,
  mirrored about z_m) an up-down symmetric vesicle centred there is exactly stationary along it, so
  the pin's multiplier vanishes; the certificate recomputes stationarity without the row (a held,
  non-stationary position fails it: the front door then re-meshes about the result,
  ``mesh.band_start.held``) and ``extra["translation_multiplier"]`` records it; the second-order
  check takes its tangent space with the row (``pin_of``): the slide the solve held is excluded as
  constrained, and the verdict's reason says "axial position pinned". (Before, c was the start's
  mass-weighted d_z phi and d its value at the start: a start off the mid-plane was held where the
  band's coarse cells push it, multiplier 6.1e-4 and kkt_not_met for the eps = 0.1 prolate 0.37 up;
  now certified, multiplier 2e-11, after one re-mesh.)
* IPOPT's Hessian of the Lagrangian assembled by sparse products (``nlp.lumped_hessian``, lumped
  meshes: 0.01 s a call at 62 k nodes against CasADi's 0.14 s, measured);
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

from vesicle_opt.mesh.axisymmetric import axial_translation  # noqa: F401  (the slide; re-exported)
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.nlp import lumped_hessian
from vesicle_opt.nlp.exact import at_point, build_exact, parameter_values
from vesicle_opt.nlp.ipopt import IpoptOptions, make_solver
from vesicle_opt.verify.certify import KKT_FACTOR
from vesicle_opt.verify.kkt import kkt_dual_with

WARM = (("ipopt.warm_start_init_point", "yes"),)  # IPOPT takes the given multipliers (no bounds, no
# inequalities: nothing else to warm)
ORDERING = (("ipopt.mumps_pivot_order", 6),)  # MUMPS's QAMD, which detects the KKT matrix's quasi-dense
# rows (dA, dB, the pin): its analysis 0.017 s CPU per IPOPT call against 0.10-0.11 s for the default's
# choice, the factorisations alike (refined meridian prolate, 20.3 k nodes, IPOPT's timing statistics)
_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()  # disc -> {(eps, rigidity): nlp, (.., options, warm): solver,
# ("derivatives", id(solver)): its Hessian and Jacobian functions and mirrored pattern}


def _pinned(nlp):
    """The parametric NLP with one more linear row c . phi - d = 0, (c, d) appended to its parameters
    (module docstring: the axial translation held at the start's position)."""
    import casadi as ca  # third-party, lazy: only the IPOPT path builds graphs (0.25 s at import)
    n = nlp.disc.n_nodes
    c, d = ca.MX.sym("translation", n), ca.MX.sym("translation_at", 1)
    return dataclasses.replace(nlp, g=ca.vertcat(nlp.g, ca.dot(c, nlp.x[:n]) - d), p=ca.vertcat(nlp.p, c, d),
                               lbg=np.zeros(nlp.lbg.size + 1), ubg=np.zeros(nlp.ubg.size + 1))


def pin_row(disc) -> np.ndarray:
    """c = m (z - z_m) / sum m |z - z_m| (z_m the box's mid-height, the refined mesh's mirror plane) and
    d = 0: the pin's parameter values. c . phi = 0 puts the centre of mass of the inside, int z (1 + phi)
    / int (1 + phi), at z_m (the weights integrate z exactly, so sum m (z - z_m) = 0); linear in phi and
    the same row at every point and position (module docstring)."""
    z = np.asarray(disc.nodes, float)[:, 1]
    lo, hi = (float(b) for b in disc.box[-1])
    c = disc.weights * (z - (lo + hi) / 2)
    c = c / max(float(np.abs(c).sum()), 1e-300)
    return np.concatenate([c, [0.0]])


def pin_of(p: np.ndarray, n: int) -> np.ndarray:
    """The pin's row c (phi block, ``pin_row``) held in the pinned NLP's parameters p: the row the
    second-order check adds to the tangent space (``verify.second_order.check(pin=...)``)."""
    return np.asarray(p, float).ravel()[-(n + 1):-1]


def parametric(scene, disc, options: IpoptOptions, warm: bool):
    """(parametric pinned NLP, IPOPT solver) of ``disc`` for the scene's eps and rigidity (the
    graph's constants): the graph built once per mesh, a solver once per IPOPT options."""
    entries = _CACHE.setdefault(disc, {})
    graph = (scene.model.epsilon, scene.model.rigidity)
    if graph not in entries:
        entries[graph] = _pinned(build_exact(scene, disc, check=False, parametric=True))
    nlp = entries[graph]
    key = (graph, options, warm, ORDERING)
    if key not in entries:
        extra = ORDERING + (WARM if warm else ())
        if lumped_hessian.applies(nlp):  # the assembled Hessian (``nlp.lumped_hessian``), one per graph
            hess = entries.setdefault(("hess_lag", graph), lumped_hessian.hess_lag(nlp))
            extra += (("hess_lag", hess),)
        opts = dataclasses.replace(options, extra=extra + tuple(options.extra))
        entries[key] = make_solver(nlp, opts)
    return nlp, entries[key]


def point(scene, disc, options: IpoptOptions, start):
    """(NLP of this point, solver, p, IPOPT start kwargs) for an exact solve of ``scene`` on ``disc``
    from ``start`` (a Result on ``disc``: warm, its multipliers; a field: cold)."""
    warm = getattr(start, "lambda_volume", None) is not None and getattr(start, "disc", None) is disc \
        and np.isfinite(start.lambda_volume) and np.isfinite(start.lambda_area)
    nlp_p, solver = parametric(scene, disc, options, warm)
    alpha, beta = constraint_data(scene, disc)
    nlp = at_point(nlp_p, scene, alpha, beta)
    if warm:
        x0 = np.asarray(start.x, float) if start.x is not None and start.x.size == nlp.x0.size else nlp.from_phi(start.phi)
    elif getattr(start, "phi", start) is not None:
        x0 = nlp.from_phi(np.asarray(getattr(start, "phi", start), float).ravel())
    else:
        x0 = nlp.x0
    p = np.concatenate([parameter_values(scene, disc, alpha, beta), pin_row(disc)])
    kw = {"x0": x0}
    if warm:  # the physical multipliers in this point's scaled rows (NLP.multipliers inverted); the pin's at 0
        kw["lam_g0"] = np.concatenate([-np.array([start.lambda_volume, start.lambda_area]) * nlp.g_scale / nlp.f_scale,
                                       np.zeros(nlp.lbg.size - 2)])
    return nlp, solver, p, kw


def unpinned(result, nlp=None, tol: float | None = None):
    """The result in the unpinned NLP's layout (as the front door's), the pin's multiplier (IPOPT's
    scaled units) in ``extra["translation_multiplier"]``: the certificate recomputed stationarity
    without the row, so a pin that held a non-stationary position shows as kkt_dual. With the point's
    ``nlp`` (its f_scale) and IPOPT's ``tol``: ``kkt_dual_pinned``, the same residual with the row's
    force f_scale lambda_pin c (r = -f_scale lambda_pin c at IPOPT's point), and ``pin_held``: the
    row's force is what fails the test (kkt_dual_pinned within KKT_FACTOR tol, kkt_dual above it;
    ``mesh.band_start.held``: only then does a re-mesh about the result help)."""
    if result.lam_g is None or result.lam_g.size < 3:
        return result
    lam = float(result.lam_g[-1])
    extra = {**result.extra, "translation_multiplier": lam}
    if nlp is not None and tol is not None and np.isfinite(extra.get("kkt_dual", np.nan)):
        disc, m = nlp.disc, nlp.scene.model
        force = nlp.f_scale * lam * pin_row(disc)[:-1]
        pinned = kkt_dual_with(disc, result.phi, m.epsilon, m.C, m.rigidity, result.lambda_volume,
                               result.lambda_area, force, extra["kkt_dual_scale"])
        extra.update(kkt_dual_pinned=pinned,
                     pin_held=bool(pinned <= KKT_FACTOR * tol < extra["kkt_dual"]))
    return dataclasses.replace(result, lam_g=result.lam_g[:-1], extra=extra)


def _mirrored(pattern):
    """(the full symmetric pattern of a triangle, the triangle's nonzero index of each of its
    entries): H from IPOPT's values without a sparse conversion and a transpose-add per point."""
    shape = (pattern.size1(), pattern.size2())
    tri = sp.csc_matrix((np.arange(1, pattern.nnz() + 1, dtype=float), pattern.row(), pattern.colind()), shape=shape)
    full = (tri + sp.triu(tri, 1).T + sp.tril(tri, -1).T).tocsc()  # indices + 1 (no two entries overlap)
    full.sort_indices()
    return full, full.data.astype(np.int64) - 1


def derivatives(nlp, solver, p):
    """(hessian_of(x, lam_g), jacobian_of(x)) for ``verify.second_order.check`` from the solver's
    own functions at the parameters p: the physical Hessian of the Lagrangian (f_scale times IPOPT's, its
    upper triangle mirrored; the pin is linear; any parametric exact NLP's solver, pinned or not) and the Jacobian of the two constraints (the check
    adds the pin's row itself, ``pin_of``: its tangent space is the solve's, the slide excluded as
    constrained)."""
    entries = _CACHE.get(nlp.disc, {})
    key = ("derivatives", id(solver))
    built = entries.get(key, (None,))
    if built[0] is not solver:
        hess = solver.get_function("nlp_hess_l")
        built = (solver, hess, solver.get_function("nlp_jac_g"), *_mirrored(hess.sparsity_out(0)))
        if any(v is solver for v in entries.values()):  # a solver of ``parametric``: kept with it (0.015-0.03 s a point)
            entries[key] = built
    _, hess, jac, full, where = built
    n_g = hess.size1_in(3)

    def hessian_of(x, lam_g):
        lam = np.zeros(n_g)  # the two constraints' multipliers; the linear rows' (the pin) do not enter
        lam[:2] = np.asarray(lam_g, float).ravel()[:2]
        vals = np.asarray(hess(x, p, 1.0, lam).nonzeros(), float)  # IPOPT's upper triangle, CasADi's order
        return sp.csc_matrix((vals[where] * nlp.f_scale, full.indices, full.indptr), shape=full.shape)

    def jacobian_of(x):
        return sp.csr_matrix(jac(x, p)[1].sparse())[:2]
    return hessian_of, jacobian_of
