"""The branch corrector on an interface-refined meridian mesh (``branch.refined_corrector``): the
band follows the point. A walk whose interface moves beyond the band about the scene's ``initial``
is refused by the band check on ``IpoptCorrector``'s one mesh (the bug it fixes), and certified on
the point's own band here, on a mesh other than the start's, its energy that of the same problem
solved cold by the front door on a band about the solution (independent start and mesh)."""

import dataclasses

import pytest

import vesicle_opt as vo
from vesicle_opt.branch.corrector import IpoptCorrector
from vesicle_opt.branch.params import parameter
from vesicle_opt.branch.refined_corrector import RUNGS, RefinedCorrector, ladder
from vesicle_opt.mesh import refine
from vesicle_opt.scene.ranges import BAND_MIN

# the bundled prolate at eps = 0.1 on square cells of 0.2 halved twice (h = eps/2) in a band of 4 eps
# (the narrowest allowed: the interface leaves it after moving ~1 eps)
OVER = {"model.epsilon": 0.1, "domain.box": [[0.0, 2.4], [-3.4, 3.4]], "mesh.n": [12, 34],
        "mesh.refine": "interface", "mesh.levels": 2, "mesh.band": 4.0, "solver.second_order": False,
        "constraints.reduced_volume": 0.85, "initial.semi_axes": [0.8, 0.8, 1.35]}


def _at(scene, v):
    return parameter(scene, "reduced_volume").scene_at(scene, v)


@pytest.mark.slow  # five refined solves and a start up the ladder: 11 s at load 13 (3.5 CPU-s)
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
