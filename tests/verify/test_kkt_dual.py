"""The natural-norm KKT residual (verify.kkt.kkt_dual): its denominator, the sum of the norms of the
elementary terms of r, and its round-off floor against injected noise."""

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt.model import functionals as F
from vesicle_opt.model.metric import natural_metric
from vesicle_opt.verify.certify import build_result
from vesicle_opt.verify.kkt import dual_scale, kkt_dual, kkt_dual_report

NK = "solver.backend='newton-krylov'"
CIRCLE = ["domain.box=[[-4.0, 4.0], [-4.0, 4.0]]", "mesh.kind='spectral'", "mesh.n=256", "model.epsilon=0.2",
          'constraints.target={shape="circle", radius=1.5}', 'initial={shape="circle", radius=1.5}', NK,
          "solver.second_order=false"]


@pytest.mark.parametrize("sets", [("mesh.kind='spectral'", "mesh.n=64"), ("mesh.kind='fem-p1'", "mesh.n=32")],
                         ids=["spectral", "p1"])
def test_the_natural_floor_is_the_round_off_of_phi_through_the_bulk_hessian(sets, rng):
    """White noise delta = s u |phi| xi (s = 1e6: far above the evaluation's own round-off) changes
    the relative natural-norm residual by s x floor: the model (the bulk Hessian P0, H_B ~ S) is the
    linearised leading term; measured ratio 1.3 ... 1.6 (the interface's g' differs from the bulk's).
    Both are relative to kkt_dual's denominator, the five term norms (``verify.kkt.dual_scale``)."""
    sc = vo.load_scene("ellipse-2d", [*sets, NK, "solver.second_order=false"])
    r = vo.solve(sc)
    d, eps, C, rig = r.disc, sc.model.epsilon, sc.model.C, sc.model.rigidity
    lam = (r.lambda_volume, r.lambda_area)
    g0 = F.gradients(d, r.phi, eps, C)
    dual, floor = kkt_dual(d, r.phi, eps, C, rig, *lam, grads=g0)
    assert r.converged and dual == pytest.approx(r.extra["kkt_dual"], rel=1e-12)  # the certificate's number
    assert floor == pytest.approx(r.extra["kkt_dual_floor"], rel=1e-12)
    met, s = natural_metric(d, eps), 1e6
    scale = dual_scale(d, r.phi, eps, C, rig, *lam)
    assert scale == pytest.approx(r.extra["kkt_dual_scale"], rel=1e-12)
    ratios = []
    for _ in range(3):
        phi = r.phi * (1 + s * np.finfo(float).eps * rng.standard_normal(d.n_nodes))
        g = F.gradients(d, phi, eps, C)
        change = met.dual_norm(sum(c * (a - b) for c, a, b in zip((rig, -lam[0], -lam[1]), g, g0)))
        ratios.append(change / scale / (s * floor))
    assert all(0.5 <= q <= 3.0 for q in ratios), ratios  # measured 1.3 ... 1.6


def test_the_scale_counts_the_terms_of_each_gradient_apart(rng):
    """dual_scale = rig (|dE_lap| + |dE_reac|) + |lam_A| |dA| + |lam_B| (|dB_grad| + |dB_well|) in the
    natural norm: the parts sum to the gradients (round-off), and at an equilibrium the two parts of
    dE cancel, so the net denominator (kkt_dual_net's) is far smaller. Measured on the 256^2 circle
    R = 1.5 at its own targets: |dE_lap| 0.389, |dE_reac| 0.392, |dE| 0.0100 (39x); a random field has
    no such cancellation (measured 1.2)."""
    sc = vo.load_scene("ellipse-2d", CIRCLE)
    r = vo.solve(sc)
    d, eps, C, rig = r.disc, sc.model.epsilon, sc.model.C, sc.model.rigidity
    n = natural_metric(d, eps).dual_norm
    lam = (r.lambda_volume, r.lambda_area)
    for phi in (r.phi, r.phi + 0.1 * rng.standard_normal(d.n_nodes)):
        bend, reac = F.energy_gradient_parts(d, phi, eps, C)
        grad, well = F.area_gradient_parts(d, phi, eps)
        dE, dA, dB = F.gradients(d, phi, eps, C)
        assert np.array_equal(bend + reac, dE) and np.array_equal(grad + well, dB)  # the same sums
        want = rig * (n(bend) + n(reac)) + abs(lam[0]) * n(dA) + abs(lam[1]) * (n(grad) + n(well))
        assert dual_scale(d, phi, eps, C, rig, *lam) == pytest.approx(want, rel=1e-14)  # round-off of 5 sums
        cancel = (n(bend) + n(reac)) / n(dE)
        # the equilibrium's parts cancel (measured 78 = 0.781 / 0.0100); the noisy field's do not (1.2)
        assert cancel > 20 if phi is r.phi else cancel < 5, cancel
    rep = kkt_dual_report(d, r.phi, eps, C, rig, *lam)
    assert rep["kkt_dual_net"] > 20 * rep["kkt_dual"]  # the same |r| against the net terms (measured 38x)


def test_the_circle_is_certified_at_1e10_and_noise_above_its_floor_is_refused(rng):
    """The 256^2 spectral circle R = 1.5 at its own targets, tol 1e-10: refused before (net-term floor
    2.8e-10), certified now (floor 7.3e-12, kkt_dual 8.4e-12, measured). The rule still fails where it
    must: the same field with white noise s u |phi| xi, s = 1e5 (s x floor = 7e-7, above 100 tol = 1e-8),
    is refused as kkt_not_met, its kkt_dual s x floor to the model's 0.5 ... 3 (measured 1.0)."""
    sc = vo.load_scene("ellipse-2d", [*CIRCLE, "solver.tol=1e-10"])
    r = vo.solve(sc)
    assert r.converged, r.reason
    floor = r.extra["kkt_dual_floor"]
    assert floor < 1e-10 / 5  # measured 7.3e-12 (the net-term floor, 2.8e-10, refused tol 1e-10)
    s = 1e5
    phi = r.phi * (1 + s * np.finfo(float).eps * rng.standard_normal(r.disc.n_nodes))
    noisy = build_result(scene=sc, disc=r.disc, alpha=r.extra["alpha"], beta=r.extra["beta"], phi=phi,
                         tol=1e-10, solver_status="converged", solver_success=True, method="exact",
                         lam=(r.lambda_volume, r.lambda_area))
    assert not noisy.converged and str(noisy.outcome) == "kkt_not_met", noisy.extra.get("reason")
    assert 0.5 <= noisy.extra["kkt_dual"] / (s * floor) <= 3.0  # the floor model (measured 1.00 ... 1.01)


def test_the_spectral_128_branch_is_certified_at_1e10_at_every_point():
    """Issue 25's branch target, cut to its first points: ellipse-2d on spectral 128^2 in the reduced
    volume at tol 1e-10 (the L2 rule refused its first point, 'tol >= 5e-10'); every point is
    certified (the full run to 0.8: 26 of 26, kkt_dual 1.2e-12 ... 1.7e-11, floors 1.1e-12, measured)."""
    sc = vo.load_scene("ellipse-2d", ["mesh.kind='spectral'", "solver.tol=1e-10"])
    br = vo.branch(sc, "reduced_volume", to=0.867, step=-0.003, max_points=4, switch=False, snapshots=False)
    assert len(br.rows) >= 3 and all(r["converged"] and str(r["outcome"]) == "converged" for r in br.rows), \
        [(r["point"], r["outcome"], r.get("reason")) for r in br.rows]
