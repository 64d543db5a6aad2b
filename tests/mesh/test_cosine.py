"""Mirror grids (mesh.cosine): the cosine Laplacian against closed forms, against the doubled periodic
spectral grid (a discrete identity), and against FD refinement; resampling; unfolding; topology."""

import math

import numpy as np
import pytest

from vesicle_opt.mesh import cosine, fd, spectral
from vesicle_opt.model import functionals as F
from vesicle_opt.model.lumped import LumpedOperators, PhaseField
from vesicle_opt.nk.precond import FourierPreconditioner
from vesicle_opt.verify import topology

L3, N3 = (2.0, 1.5, 1.2), (20, 16, 12)


def _pair(L, n):
    """The mirror grid of [0, L] and the periodic spectral grid of the doubled box whose nodes are
    its nodes' mirror images ([-L + h/2, L + h/2] with 2n nodes per side)."""
    h = np.array(L) / np.array(n)
    return (cosine.grid([[0.0, x] for x in L], n),
            spectral.grid([[-x + hh / 2, x + hh / 2] for x, hh in zip(L, h)], [2 * k for k in n]))


def _even_field(x):
    """A smooth field even in every coordinate (an ellipsoid's diffuse profile, eps = 0.3)."""
    return np.tanh((1 - (x[:, 0] / 1.3) ** 2 - (x[:, 1] / 0.8) ** 2 - (x[:, 2] / 0.7) ** 2) / 0.3)


def test_cosine_modes_are_eigenfunctions_with_the_closed_form_symbol():
    g = cosine.grid([[0.5, 2.5], [-1.0, 0.5]], (12, 10))
    x = g.nodes
    for k in ((0, 0), (3, 0), (2, 7), (11, 9)):
        v = np.cos(math.pi * k[0] * (x[:, 0] - 0.5) / 2.0) * np.cos(math.pi * k[1] * (x[:, 1] + 1.0) / 1.5)
        lam = -((math.pi * k[0] / 2.0) ** 2 + (math.pi * k[1] / 1.5) ** 2)
        # round-off: eps_mach times the largest |symbol| (~ 400 here) times a few transforms
        assert np.max(np.abs(g.apply_laplacian(v) - lam * v)) <= 1e-12 * max(1.0, abs(lam))


def test_cosine_grid_is_the_doubled_periodic_grid_on_even_fields():
    cg, pg = _pair(L3, N3)
    phic, phip = _even_field(cg.nodes), _even_field(pg.nodes)
    # the unfolded octant nodes are the doubled grid's nodes (|x| per axis), to round-off of lo + (j+1/2) h
    assert np.max(np.abs(cosine.unfold(cg.nodes[:, 0], N3).ravel() - np.abs(pg.nodes[:, 0]))) < 1e-14
    assert np.max(np.abs(cosine.unfold(phic, N3).ravel() - phip)) < 1e-14
    lap_c = cosine.unfold(cg.apply_laplacian(phic), N3).ravel()
    lap_p = pg.apply_laplacian(phip)
    # FFT round-off: ~1e-15 relative to max |Delta phi| (measured 1.5e-14 with the 3 transforms each)
    assert np.max(np.abs(lap_c - lap_p)) <= 1e-13 * np.max(np.abs(lap_p))
    assert cg.volume == pytest.approx(pg.volume, rel=1e-15)
    a, b = F.evaluate(cg, phic, 0.1, 0.3), F.evaluate(pg, phip, 0.1, 0.3)
    for key in ("E", "A", "B"):  # the full field's functionals, summed over 8x the nodes: round-off
        assert a[key] == pytest.approx(b[key], rel=1e-12), key


def test_dual_norm_and_preconditioner_match_the_doubled_grid():
    cg, pg = _pair(L3, N3)
    eps = 0.15
    pfc = PhaseField(LumpedOperators(cg), eps, 0.0)
    pfp = PhaseField(LumpedOperators(pg), eps, 0.0)
    gc = pfc.gradients(pfc.state(_even_field(cg.nodes)))
    gp = pfp.gradients(pfp.state(_even_field(pg.nodes)))
    pc = FourierPreconditioner(cg.fourier, cg.weights[0], eps)
    pp = FourierPreconditioner(pg.fourier, pg.weights[0], eps)
    for vc, vp in zip(gc, gp):  # dE, dA, dB: the stopping norm is the same number on both grids
        assert pc.dual_norm(vc) == pytest.approx(pp.dual_norm(vp), rel=1e-11)  # round-off of sums of N terms
    r = pc.inverse(1.0, 0.3, 2.0)(gc[0])
    rp = pp.inverse(1.0, 0.3, 2.0)(gp[0])
    # P^{-1} with the rho_A m m^T term: the octant's, unfolded, is the doubled grid's times 8
    # (a gradient on the octant is 8x the doubled grid's: its weights are 8 h^3)
    assert np.max(np.abs(cosine.unfold(r, N3).ravel() - rp)) <= 1e-11 * np.max(np.abs(rp))


def _smooth_even(x, L):
    """exp(sum cos(pi x_i / L_i)): even about 0 and L_i, not band-limited; its Laplacian in closed form."""
    c = [np.cos(math.pi * x[:, i] / L[i]) for i in range(x.shape[1])]
    s = [np.sin(math.pi * x[:, i] / L[i]) for i in range(x.shape[1])]
    f = np.exp(sum(c))
    lap = f * sum((math.pi / L[i]) ** 2 * (s[i] ** 2 - c[i]) for i in range(x.shape[1]))
    return f, lap


def test_cosine_laplacian_converges_spectrally_while_fd_refines_at_order_two():
    L = (2.0, 1.0)
    cos_err, fd_err, hs = [], [], []
    for n in (16, 32, 64, 128):
        g = cosine.grid([[0.0, x] for x in L], (n, n // 2))
        f, lap = _smooth_even(g.nodes, L)
        cos_err.append(np.max(np.abs(g.apply_laplacian(f) - lap)))
        # FD on the doubled periodic box, nodes at the same points (the mirror class's FD analogue)
        h = np.array(L) / np.array((n, n // 2))
        d = fd.grid([[-x + hh / 2, x + hh / 2] for x, hh in zip(L, h)], (2 * n, n))
        fp, lp = _smooth_even(d.nodes, L)
        fd_err.append(np.max(np.abs(d.apply_laplacian(fp) - lp)))
        hs.append(h[0])
    order = np.polyfit(np.log(hs[1:]), np.log(fd_err[1:]), 1)[0]  # the three finest (asymptotic range)
    assert abs(order - 2) < 0.1, f"FD observed order {order:.3f}, errors {fd_err}"  # the stencil's O(h^2)
    # spectral: each doubling gains orders of magnitude until round-off (~1e-12 of |lap| ~ 30)
    assert cos_err[1] < 1e-6 and cos_err[2] < 1e-10 and cos_err[3] < 1e-10, cos_err
    assert all(c < f for c, f in zip(cos_err[1:], fd_err[1:])), (cos_err, fd_err)


def test_resample_is_exact_for_band_limited_cosine_series():
    L, n = (2.0, 1.0), (8, 6)
    def series(x):  # modes below 8 x 6: represented on both grids
        return (1.0 + np.cos(math.pi * 3 * x[:, 0] / L[0]) * np.cos(math.pi * 5 * x[:, 1] / L[1])
                + 0.5 * np.cos(math.pi * 7 * x[:, 0] / L[0]))
    coarse = cosine.grid([[0.0, x] for x in L], n)
    fine = cosine.grid([[0.0, x] for x in L], (16, 10))
    up = spectral.resample(series(coarse.nodes), n, (16, 10), kind=cosine.KIND)
    assert np.max(np.abs(up - series(fine.nodes))) < 1e-13  # round-off of two DCTs of length <= 16
    down = cosine.resample(series(fine.nodes), (16, 10), n)
    assert np.max(np.abs(down - series(coarse.nodes))) < 1e-13


def test_topology_counts_on_the_unfolded_box():
    g = cosine.grid([[0.0, 2.0]] * 3, (16, 16, 16))
    r = np.linalg.norm(g.nodes, axis=1)
    corner = topology.analyse(g, 1.0 - r)  # a ball centred at the corner: one full vesicle
    assert corner.components == 1 and corner.describe(3) == "sphere-like (genus 0)"
    mid = topology.analyse(g, 0.5 - np.linalg.norm(g.nodes - 1.0, axis=1))  # inside the box: 8 images
    assert mid.components == 8
