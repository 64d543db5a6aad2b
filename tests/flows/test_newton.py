"""Gradient flows on Fourier grids: Jacobian products and GMRES in place of sparse matrices and LU.

Checked against independent references: the sparse Jacobian matrices, and the same scheme on the
same FD discretisation solved with SuperLU (the FFT-applied FD Laplacian equals the sparse stencil
to round-off, ``test_spectral``); and the discrete energy laws, which hold to round-off only when
the nonlinear step is solved exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from vesicle_opt import cli
from vesicle_opt import scene as S
from vesicle_opt.flows.discrete import FlowModel
from vesicle_opt.flows.api import build_model, initial_field, make_scheme
from vesicle_opt.flows.stepper import StepperOptions, run
from vesicle_opt.flows.trackers import CallbackTracker
from vesicle_opt.mesh.spectral import fourier_grid

LAW_TOL = 1e-11  # as tests/flows/test_schemes.py: laws measured at 1e-15..3e-13 relative on these grids


def _scene(*sets, n=24):
    return S.load("ellipse-2d", [f"mesh.n={n}", "solver.M=100", "flow.steady_tol=0", *sets])


def _fft_twin(md: FlowModel) -> FlowModel:
    """The same FD discretisation with Delta_h applied by FFT (matrix-free)."""
    d = md.disc
    fd = fourier_grid(d.box, d.grid_shape, "fd")
    return FlowModel(fd, md.epsilon, md.C, md.rigidity, md.alpha, md.beta, md.M, md.gamma)


def test_jacobian_products_equal_the_matrices(rng):
    md0 = build_model(_scene())
    md = FlowModel(md0.disc, md0.epsilon, 0.4, 2.0, md0.alpha, md0.beta, md0.M, 1.0)  # C != 0: every term
    phi = initial_field(_scene(), md)
    eta = phi + 0.1 * rng.standard_normal(phi.size)
    v = rng.standard_normal(phi.size)
    a, b = 0.3, -0.7
    J = sp.identity(phi.size) + a * md.dg2(phi, eta) + b * md.df2(phi, eta)
    ref = J @ v
    # the same sums in another order: round-off (measured 4e-16 relative)
    assert np.max(np.abs(md.jacobian_apply(phi, eta, a, b)(v) - ref)) <= 1e-13 * np.max(np.abs(ref))
    fft = _fft_twin(md)
    assert fft.matrix_free and not md.matrix_free
    # FFT stencil vs sparse stencil: round-off of the transforms (measured ~1e-14 relative)
    assert np.max(np.abs(fft.jacobian_apply(phi, eta, a, b)(v) - ref)) <= 1e-11 * np.max(np.abs(ref))


@pytest.mark.parametrize("scheme", ["penalty", "lagrange"])
def test_gmres_step_equals_direct_step(scheme):
    """One step of (18)/(17) on FD: Newton-GMRES with FFT products vs Newton-SuperLU with matrices."""
    sc = _scene(f'flow.scheme="{scheme}"')
    md = build_model(sc)
    phi0 = initial_field(sc, md)
    direct = make_scheme(sc, md).step(phi0, 1e-3, phi0)
    krylov = make_scheme(sc, _fft_twin(md)).step(phi0, 1e-3, phi0)
    assert direct.converged and krylov.converged, (direct.message, krylov.message)
    assert krylov.linear_iterations > 0 and direct.linear_iterations == 0
    # both solve the same equations to Newton's xtol = 1e-12 (max norm); the fields agree to it
    assert np.max(np.abs(krylov.phi - direct.phi)) <= 1e-10
    assert abs(krylov.law_residual) <= LAW_TOL and abs(direct.law_residual) <= LAW_TOL


@pytest.mark.parametrize("scheme", ["penalty", "lagrange"])
def test_spectral_flow_laws_round_off(scheme):
    """On the pseudo-spectral grid the laws (22) / Lemma 4.2 hold to round-off on every step, and (17)
    preserves A and B; the energy decreases strictly."""
    sc = _scene(f'flow.scheme="{scheme}"', "mesh.kind='spectral'")
    md = build_model(sc)
    assert md.matrix_free
    phi = initial_field(sc, md)
    A0, B0 = md.A(phi), md.B(phi)
    rows = []
    out = run(make_scheme(sc, md), phi, StepperOptions(dt=1e-3, t_end=5e-3, max_steps=100),
              [CallbackTracker(lambda state, row: rows.append((row, state.phi)))])
    assert out.status == "t_end" and len(rows) == 5
    for row, p in rows:
        assert abs(row["energy_law_residual"]) <= LAW_TOL, row
        assert row["krylov_iterations"] > 0
        if scheme == "lagrange":  # A ~ 50, B ~ 10: 1e-12 relative is round-off
            assert abs(md.A(p) - A0) <= 1e-12 * abs(A0)
            assert abs(md.B(p) - B0) <= 1e-12 * B0
    key = "energy" if scheme == "lagrange" else "penalized_energy"
    energies = [r[key] for r, _ in rows]
    assert all(b < a for a, b in zip(energies, energies[1:]))


def test_spectral_oversized_step_is_rejected_not_nan():
    """k = 0.1 makes the Newton/GMRES solve fail on this grid (measured); the stepper halves k."""
    sc = _scene("flow.scheme='penalty'", "mesh.kind='spectral'")
    md = build_model(sc)
    phi = initial_field(sc, md)
    sch = make_scheme(sc, md)
    assert not sch.step(phi, 0.1, phi).converged
    out = run(sch, phi, StepperOptions(dt=0.1, t_end=0.1, max_steps=50))
    assert out.rejections >= 1 and out.status == "t_end" and np.all(np.isfinite(out.phi))


def test_backward_euler_by_newton_krylov_refused_on_p1(tmp_path, capsys):
    """(23) by Newton-Krylov runs on FD and spectral grids; asked for on P1 it is bad input (exit 2)."""
    rc = cli.main(["flow", "ellipse-2d", "--scheme", "backward-euler", "--out", str(tmp_path), "--quiet",
                   "--set", "mesh.kind='fem-p1'", "--set", "solver.backend='newton-krylov'"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "solver.backend" in err and len(err.splitlines()) == 1


def test_backward_euler_runs_on_spectral(tmp_path):
    """(23) is no longer refused on spectral grids: its steps go to the Newton-Krylov minimiser."""
    rc = cli.main(["flow", "ellipse-2d", "--scheme", "backward-euler", "--out", str(tmp_path), "--quiet",
                   "--steps", "3", "--dt", "1e-3", "--set", "mesh.kind='spectral'", "--set", "mesh.n=24"])
    assert rc == 0
