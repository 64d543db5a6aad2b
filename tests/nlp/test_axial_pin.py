"""The axial pin of refined meridian meshes (``nlp.reuse.pin_row``): the centre of mass at the box's
mid-height, one linear row whatever the start. A start off the mid-plane certifies (the front door
re-meshes about a result whose pin held a force, ``mesh.band_start.held``), and on one mesh a start
shifted along the axis solves the same discrete problem as the centred one: the same energy to the
solver's tolerance."""

import dataclasses

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt.mesh import refine
from vesicle_opt.nlp import reuse

BOX = {"model.epsilon": 0.1, "domain.box": [[0.0, 2.4], [-3.4, 3.4]]}  # walls >= 12 eps from the shape
REFINED = {**BOX, "mesh.n": [12, 34], "mesh.refine": "interface", "mesh.levels": 2, "solver.second_order": False}
SHIFT = 0.37  # 3.7 eps: the case the pin at the start's position failed (kkt_not_met, multiplier 6.1e-4)


def _centre(res):
    w = res.disc.weights * (1 + res.phi)
    return float(w @ res.disc.nodes[:, 1] / w.sum())


def test_pin_row_is_the_centre_of_mass_at_mid_height():
    res = vo.solve(vo.load_scene("prolate-axisymmetric", REFINED))
    c = reuse.pin_row(res.disc)
    z = res.disc.nodes[:, 1]
    # sum m (z - z_m) = 0: the weights integrate z exactly, so c . phi = 0 <=> centre of mass at z_m
    assert abs(c[:-1].sum()) < 1e-13 and c[-1] == 0.0  # round-off of a sum of O(1) terms
    assert abs(c[:-1] @ res.phi) < 1e-10  # the solve's pin row, met to IPOPT's constraint tolerance
    assert abs(_centre(res)) < 1e-10 * np.abs(z).max()


def test_a_shifted_start_certifies_and_solves_the_centred_problem():
    centred = vo.solve(vo.load_scene("prolate-axisymmetric", REFINED))
    up = vo.solve(vo.load_scene("prolate-axisymmetric", {**REFINED, "initial.center": [0.0, 0.0, SHIFT]}))
    assert centred.converged and up.converged
    # both held at mid-height with no force: multipliers ~1e-11 (IPOPT's scaled units, O(1) for the
    # other rows) against 7.9e-3 before the re-mesh about the result
    assert abs(up.extra["translation_multiplier"]) < 1e-8 and abs(_centre(up)) < 1e-9
    # two bands (about the ellipsoid start, about the result): the coarse cells' share of E_h differs
    # (measured 2.2e-5 relative at the band's 3-8 eps margins; verify.band: 2e-5 at 4 eps)
    assert up.energy == pytest.approx(centred.energy, rel=1e-4)
    # on ONE mesh (the up start's), the centred field shifted 0.37 up as a warm start: the pin's row
    # and target do not depend on the start, so this is the same discrete problem, and IPOPT returns
    # to the same point: the same energy to the solver's tolerance (tol 1e-8 on a stationary energy:
    # measured difference ~1e-13 relative)
    d = up.disc
    q = d.nodes - [0.0, SHIFT]
    q[:, 1] = np.clip(q[:, 1], d.box[1][0], d.box[1][1])  # below the box: the bulk value at the wall
    shifted = refine.transfer(d.mesh, up.phi, q)
    start = dataclasses.replace(up, phi=shifted, x=shifted)
    again = vo.solve(up.scene, x0=start)
    assert again.converged and again.disc is d
    assert abs(_centre(up) - _centre(again)) < 1e-9
    assert again.energy == pytest.approx(up.energy, rel=1e-10)


def test_the_front_door_remeshes_only_where_the_pin_fails_the_kkt_test(monkeypatch):
    """``band_start.held``: a pinned kkt_not_met is re-meshed only where the pin's force is what fails
    the KKT test (``pin_held``). The start 0.37 up, on its own band: the residual without the row is
    the row's force alone (r = -f_scale lambda_pin c at IPOPT's point: the same norm), and with it the
    point is stationary; the same point with the pin's multiplier made negligible fails with the row
    too: no re-mesh (the front door solved such a point REMESH_ROUNDS more times before)."""
    from vesicle_opt import api
    from vesicle_opt.mesh import band_start, discretize
    from vesicle_opt.model.metric import natural_metric
    from vesicle_opt.nlp.solve import solve_exact
    from vesicle_opt.verify.certify import KKT_FACTOR

    sc = vo.load_scene("prolate-axisymmetric", {**REFINED, "initial.center": [0.0, 0.0, SHIFT]})
    opts = vo.IpoptOptions.from_scene(sc)
    nlp, solver, p, start = reuse.point(sc, discretize(sc), opts, None)
    raw = solve_exact(nlp, solver=solver, options=opts, p=p, **start)
    res = reuse.unpinned(raw, nlp, opts.tol)
    ex = res.extra
    assert res.outcome == vo.Status.KKT_NOT_MET and ex["pin_held"] and band_start.held(res)
    force = nlp.f_scale * ex["translation_multiplier"] * reuse.pin_row(res.disc)[:-1]
    share = natural_metric(res.disc, sc.model.epsilon).dual_norm(force) / ex["kkt_dual_scale"]
    # the row's force is the residual: measured 7.879e-6 both, 2e-8 apart (IPOPT's tol on a 1e-5 residual)
    assert share == pytest.approx(ex["kkt_dual"], rel=1e-4)
    assert ex["kkt_dual_pinned"] < 1e-3 * KKT_FACTOR * opts.tol  # stationary with the row (measured 6.2e-11)
    lam = raw.lam_g.copy()
    lam[-1] *= 1e-9  # the same point, the pin's multiplier negligible: a failure that is not the pin's
    other = reuse.unpinned(dataclasses.replace(raw, lam_g=lam), nlp, opts.tol)
    assert other.outcome == vo.Status.KKT_NOT_MET and not other.extra["pin_held"] and not band_start.held(other)
    assert other.extra["kkt_dual_pinned"] == pytest.approx(ex["kkt_dual"], rel=1e-6)  # the row adds ~nothing

    for given, solves in ((res, 1 + band_start.REMESH_ROUNDS), (other, 1)):
        given, calls = dataclasses.replace(given, scene=sc), []  # as the front door's results (its log names it)
        monkeypatch.setattr(api, "_solve", lambda *a, remesh=False, given=given: calls.append(remesh) or given)
        assert vo.solve(sc) is given and len(calls) == solves, calls
