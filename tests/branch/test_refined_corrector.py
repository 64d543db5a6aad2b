"""The branch corrector on an interface-refined meridian mesh (``branch.refined_corrector``): the
band follows the point. A walk whose interface moves beyond the band about the scene's ``initial``
is refused by the band check on ``IpoptCorrector``'s one mesh (the bug it fixes), and certified on
the point's own band here, on a mesh other than the start's, its energy that of the same problem
solved cold by the front door on a band about the solution (independent start and mesh). A line's
points on their own meshes are written with their triangles and resumed on the same meshes."""

import dataclasses

import numpy as np
import pytest
import skfem

import vesicle_opt as vo
from vesicle_opt.branch.corrector import IpoptCorrector
from vesicle_opt.branch.params import parameter
from vesicle_opt.branch.transition import Found, Sample
from vesicle_opt.branch.transition_store import LineStore
from vesicle_opt.errors import StateFileError
from vesicle_opt.io import fields
from vesicle_opt.mesh import axisymmetric as ax
from vesicle_opt.branch.refined_corrector import RUNGS, RefinedCorrector, ladder, seeded
from vesicle_opt.mesh import refine
from vesicle_opt.scene.ranges import BAND_MIN

# the bundled prolate at eps = 0.1 on square cells of 0.2 halved twice (h = eps/2) in a band of 4 eps
# (the narrowest allowed: the interface leaves it after moving ~1 eps)
OVER = {"model.epsilon": 0.1, "domain.box": [[0.0, 2.4], [-3.4, 3.4]], "mesh.n": [12, 34],
        "mesh.refine": "interface", "mesh.levels": 2, "mesh.band": 4.0, "solver.second_order": False,
        "constraints.reduced_volume": 0.85, "initial.semi_axes": [0.8, 0.8, 1.35]}


def _at(scene, v):
    return parameter(scene, "reduced_volume").scene_at(scene, v)


@pytest.mark.slow  # five refined solves and a start up the ladder: 6 s at load 5, 24 s at load 13
def test_the_band_follows_the_walk_and_the_fixed_band_refuses_it():
    scene = vo.load_scene("prolate-axisymmetric", OVER)
    corr = RefinedCorrector(scene)
    start = corr.start(scene)
    assert start.converged and start.extra["band_margin"] >= BAND_MIN
    # v 0.85 -> 0.75: the poles move out by ~0.2 (2 eps): beyond the band of 4 eps less BAND_MIN
    fixed = IpoptCorrector(scene)  # one mesh: the band about the scene's initial shape; a full solve (cold)
    old = fixed.solve(_at(scene, 0.75), refine.transfer(start.disc.mesh, start.phi, fixed.disc.nodes), None)
    assert not old.converged and "left the refined band" in old.reason
    walk, meshes = [start], {id(start.disc)}
    for v in (0.75, 0.65):  # measured: re-meshed at both (margins 5.8, 5.8 after)
        r = walk[-1]
        walk.append(corr.solve(_at(scene, v), r.phi, (r.lambda_volume, r.lambda_area), r.disc))
        assert walk[-1].converged and walk[-1].extra["band_margin"] >= BAND_MIN
        meshes.add(id(walk[-1].disc))
    assert len(meshes) >= 2 and id(corr.disc) not in meshes  # the band followed the points, not initial
    # the same discrete problem as the front door's cold solve (its own band about its solution): the
    # coarse cells' share at >= 3 eps is <= 3.6e-4 relative in E_h (verify.band)
    far = _at(scene, 0.65)
    cold = vo.solve(far.replace(initial=dataclasses.replace(far.initial, semi_axes=(0.7, 0.7, 1.6))))
    assert cold.converged
    assert walk[-1].energy == pytest.approx(cold.energy, rel=3.6e-4)


def test_the_ladder_keeps_eps_over_h_and_ends_at_the_scene():
    scene = vo.load_scene("prolate-axisymmetric", {**OVER, "mesh.levels": 3, "model.epsilon": 0.05})
    rungs = ladder(scene)
    assert len(rungs) == min(3, RUNGS) and rungs[-1] == scene
    for r in rungs:  # eps / h_fine the scene's (h_fine = 0.2 / 2^levels)
        assert r.model.epsilon / (0.2 / 2**r.mesh.levels) == pytest.approx(0.05 / (0.2 / 8), rel=1e-12)


def _sphere_band(radius):
    return ax.band_p1(((0.0, 2.0), (-2.0, 2.0)), (10, 20), lambda p: np.abs(np.hypot(p[:, 0], p[:, 1]) - radius),
                      4.0, 1, 0.1)


def _mesh_of(nodes, triangles):  # as VesicleCrossing.mesh_of for that box and levels
    mesh = skfem.MeshTri(np.ascontiguousarray(np.asarray(nodes, float).T), np.ascontiguousarray(triangles))
    return ax.assemble(mesh, ((0.0, 2.0), (-2.0, 2.0)), h_fine=0.1, band=4.0)


def test_points_on_their_own_meshes_are_stored_and_resumed_on_them(tmp_path):
    first, own = _sphere_band(1.0), {"a": _sphere_band(0.8), "b": _sphere_band(1.2)}
    assert own["a"].n_nodes != own["b"].n_nodes != first.n_nodes
    pts = {x: Sample(0.7, 0.0, np.tanh(d.nodes[:, 0] - 0.5), 1.0, True, (1.0, 2.0), 0.1 if x == "a" else 0.2,
                     0.0, {}, d) for x, d in own.items()}
    store = LineStore(tmp_path, {"k": 1}, first, "c0", "reduced_volume", _mesh_of)
    store.append(0, "start", Found(0.0, 0.7, pts, 0.7, 3, 6, 1.0))
    again = LineStore(tmp_path, {"k": 1}, first, "c0", "reduced_volume", _mesh_of)  # a resume
    found = again.found(0, again.rows()[0])
    for x, d in own.items():
        back = found.points[x]
        assert back.disc.n_nodes == d.n_nodes and np.array_equal(back.phi, pts[x].phi)
        assert abs(back.disc.K - d.K).max() == 0 and np.array_equal(back.disc.weights, d.weights)  # same assembly
    bad = fields.arrays("branch-point", pts["a"].phi, own["a"], triangles=own["a"].mesh.t + own["a"].n_nodes)
    np.savez(tmp_path / "bad.npz", **bad)
    with pytest.raises(StateFileError, match="triangles"):
        fields.read(tmp_path / "bad.npz")


def test_a_seed_from_a_meridian_has_its_band_and_its_interface_on_the_curve():
    scene = vo.load_scene("prolate-axisymmetric", OVER)
    t = np.linspace(0, np.pi, 2001)
    disc, phi = seeded(scene, 0.9 * np.sin(t), 1.2 * np.cos(t))  # a spheroid's meridian, semi-axes 0.9, 1.2
    pts = refine.zero_crossings(disc.mesh, phi)
    # the P1 zero crossings on the spheroid to the interpolation error of a fine cell (h_fine = 0.05)
    assert np.abs(np.hypot(pts[:, 0] / 0.9, pts[:, 1] / 1.2) - 1).max() < 0.05 / 0.9
    # the band is about the curve: its margin the band's 4 eps, or more (the marking's slack)
    assert refine.band_margin(disc.mesh, phi, disc.h_fine, 0.1) >= 4.0
