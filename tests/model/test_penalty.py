"""The one E_M (model/penalty.penalised_energy, (11) in Section 5's convention) is what every place
evaluates: numbers and CasADi expressions, the lifted penalty NLP, the flows (FlowModel.E_M,
the history columns, the minimising movement (23)) and the Newton-Krylov objective."""

import casadi as ca
import numpy as np
import pytest

from vesicle_opt import scene as S
from vesicle_opt.flows.backward_euler import BackwardEulerScheme
from vesicle_opt.flows.base import observe
from vesicle_opt.flows.api import build_model, initial_field
from vesicle_opt.mesh.spectral import fourier_grid
from vesicle_opt.model import functionals as F
from vesicle_opt.model.lumped import LumpedOperators, PhaseField
from vesicle_opt.model.penalty import penalised_energy, penalty_terms, residuals
from vesicle_opt.nk.newton_cg import Counters, Objective
from vesicle_opt.nk.precond import FourierPreconditioner
from vesicle_opt.flows.discrete import FlowModel
from vesicle_opt.nlp import build_nlp

RIG, E, RES, M1, M2, MU = 2.5, 3.1, (1e-3, -2e-2), 1e4, 3e3, (0.7, -1.9)


def test_formula_scale_and_symbolic_form():
    ref = RIG * E + M1 / 2 * RES[0] ** 2 + M2 / 2 * RES[1] ** 2 - MU[0] * RES[0] - MU[1] * RES[1]
    # one formula written out: a few roundings apart (measured 0)
    assert penalised_energy(RIG, E, RES, M1, M2, MU) == pytest.approx(ref, rel=1e-15)
    assert penalised_energy(RIG, E, RES, M1, M2) == RIG * E + penalty_terms(RES, M1, M2)
    s = (40.0, 7.0)  # residuals in units s: the lifted NLP's u = (A - alpha, B - beta) / s
    scaled = penalty_terms((RES[0] / s[0], RES[1] / s[1]), M1, M2, MU, scale=s)
    assert scaled == pytest.approx(penalty_terms(RES, M1, M2, MU), rel=1e-14)  # (r/s) s: round-off
    # the same lines build a CasADi expression, whose value is the float one
    x = ca.SX.sym("x", 7)
    sym = ca.Function("E_M", [x], [penalised_energy(x[0], x[1], (x[2], x[3]), x[4], x[5], (x[6], MU[1]))])
    val = float(sym([RIG, E, RES[0], RES[1], M1, M2, MU[0]]))
    assert val == pytest.approx(penalised_energy(RIG, E, RES, M1, M2, MU), rel=1e-15)  # same ops


@pytest.mark.parametrize("mu", [None, (0.4, -1.3)])
def test_lifted_nlp_objective_is_penalised_energy(mu, rng):
    sc = S.load("ellipse-2d", ["mesh.n=16", "solver.method='penalty'", "model.rigidity=2.0", "model.c0=0.3"])
    nlp = build_nlp(sc)
    disc, eps, C = nlp.disc, sc.model.epsilon, sc.model.C
    phi = nlp.split(nlp.x0)[0] + 0.01 * rng.standard_normal(disc.n_nodes)
    p = nlp.parameters(1e3, 2e2, (0.0, 0.0) if mu is None else mu)
    f = float(ca.Function("f", [nlp.x, nlp.p], [nlp.f])(nlp.from_phi(phi), p))
    res = residuals(disc, phi, eps, nlp.alpha, nlp.beta)
    ref = penalised_energy(sc.model.rigidity, F.evaluate(disc, phi, eps, C)["E"], res, 1e3, 2e2, mu)
    # CasADi's sums against numpy's, through the lift u = res / g_scale: round-off (measured 3e-16)
    assert f * nlp.f_scale == pytest.approx(ref, rel=1e-12)


def _flow_model():
    sc = S.load("ellipse-2d", ["mesh.n=24", "solver.M=100", "model.rigidity=2.0", "model.c0=0.3",
                               'flow.scheme="backward-euler"'])
    md = build_model(sc)
    return sc, md, initial_field(sc, md)


def test_flow_model_history_and_minimising_movement_use_it():
    sc, md, phi_n = _flow_model()
    phi = 0.9 * phi_n + 0.05
    vals = F.evaluate(md.disc, phi, md.epsilon, md.C)
    res = (vals["A"] - md.alpha, vals["B"] - md.beta)
    E_M = md.E_M(phi)
    assert E_M == penalised_energy(md.rigidity, vals["E"], res, md.M, md.M)  # the same lines: exact
    obs = observe(md, phi)
    assert obs["penalized_energy"] == E_M and obs["energy"] == md.E(phi)
    assert (obs["volume_residual"], obs["area_residual"]) == res
    # (23)'s IPOPT objective at the lifted point (phi, A(phi), B(phi)), p = (phi^n, 1/(gamma k))
    be = BackwardEulerScheme(md, law_tol=1e-11)
    c = 1.0 / (md.gamma * 1e-3)
    f = be.solver.oracle()(x=np.concatenate([phi, [vals["A"], vals["B"]]]), p=np.concatenate([phi_n, [c]]))["f"]
    ref = E_M + c / 2 * md.norm2(phi - phi_n)
    assert float(f) * be.f_scale == pytest.approx(ref, rel=1e-12)  # CasADi's sums: round-off (measured 0)


@pytest.mark.parametrize("lam", [(0.0, 0.0), (0.4, -1.3)])
def test_newton_krylov_objective_is_penalised_energy_and_the_flows(lam, rng):
    disc = fourier_grid(((-2.0, 2.0), (-1.5, 1.5)), (16, 12), "spectral")
    eps, C, rig, M = 0.4, 0.2, 3.0, 1e3
    x = disc.nodes
    phi = np.tanh(1.2 - np.hypot(x[:, 0] / 1.4, x[:, 1])) + 0.05 * rng.standard_normal(disc.n_nodes)
    pf = PhaseField(LumpedOperators(disc), eps, C)
    st = pf.state(phi)
    alpha, beta = st.A + 0.3, st.B - 0.2
    obj = Objective(pf, FourierPreconditioner(disc.fourier, disc.weights[0], eps), lambda p: None,
                    rig, alpha, beta, lam, (M, M), Counters())
    f = obj.value(phi)[0]
    assert f == penalised_energy(rig, st.E, (st.A - alpha, st.B - beta), M, M, lam)  # exact: same call
    if lam == (0.0, 0.0):  # the matrix-free E_M against the flows' (numpy functionals) on one grid
        md = FlowModel(disc, eps, C, rig, alpha, beta, M, 1.0)
        assert f == pytest.approx(md.E_M(phi), rel=1e-12)  # two summation orders (measured 0)


def test_penalty_floor_against_the_nlps_own_round_off_and_injected_penalties(rng):
    """The penalty floor (``model.penalty.roundoff_floor``) models the NLP's evaluation error of A and
    B as sqrt(N) u sum|terms| and multiplies it by M (lambda = -M c). Checked on both ends:

    * the premise: CasADi's own rows (A - alpha, B - beta) at random fields differ from the
      compensated sums by at most the model (measured 0.002 ... 0.24 of it on 64^2 and 128^2);
    * the consequence, noise injected through M: at M = 1e5 ... 1e7, far above what tol permits, the
      solves' natural-norm residual is noise, below the floor (measured 0.016 ... 0.3 of it: the
      model is a bound, the noise's rms is ~0.1 of it) and growing with M."""
    import warnings

    from vesicle_opt.nlp.continuation import continuation
    u = np.finfo(float).eps
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nlp = build_nlp(S.load("ellipse-2d", ["mesh.n=48", "solver.method='continuation'"]))
    ex = nlp.exact  # the exact NLP: its rows are CasADi's (A - alpha)/|Omega|, (B - beta)/beta
    d, eps = ex.disc, ex.scene.model.epsilon
    g = ca.Function("g", [ex.x], [ex.g[:2]])
    for _ in range(3):
        phi = ex.x0 + 1e-3 * rng.standard_normal(d.n_nodes)
        rows = np.asarray(g(phi)).ravel() * np.array([d.volume, ex.beta])
        exact = residuals(d, phi, eps, ex.alpha, ex.beta)
        S_A = float(np.sum(np.abs(d.weights * phi)))
        S_B = float(F.area_functional(F.NumpyOps(d), phi, eps))
        model = np.sqrt(d.n_nodes) * u * np.array([S_A, S_B])
        assert np.all(np.abs(rows - exact) <= model), (rows - exact) / model  # measured <= 0.24
    stages = []
    continuation(nlp, Ms=[1e2, 1e5, 1e7], polish=False, stage_callback=lambda k, r: stages.append(r))
    stages = stages[1:]  # 1e2: a warm start, its residual is the solver's, above its floor
    ratios = [r.extra["kkt_dual"] / r.extra["kkt_dual_floor"] for r in stages]
    assert all(r.success for r in stages)
    assert all(1 / 100 <= q <= 1 for q in ratios), ratios  # measured 0.016 ... 0.30 (48^2, 64^2)
    assert stages[-1].extra["kkt_dual"] > 10 * stages[0].extra["kkt_dual"]  # noise ~ M (measured 136x)


def test_richardson_is_exact_on_its_polynomials_and_next_stage_stops_at_the_floor():
    from vesicle_opt.model.penalty import next_stage, penalty_retry, richardson
    Ms = [1e2, 1e3, 2.7e3]
    for order in (1, 2):  # v(M) = 3 + a/M + ... of degree `order` in 1/M: extrapolated exactly (round-off)
        vals = [3.0 + 0.7 / M + (0.0 if order == 1 else -5.0 / M**2) for M in Ms]
        assert richardson(Ms, vals, order) == pytest.approx(3.0, rel=1e-13)
    # the floor is linear in M: at 1e3 a floor of 1e-9 allows 5e3 (tol/2 = 5e-9), so 1e4 is replaced by it
    assert next_stage([10.0, 1e2, 1e3, 1e4], 2, 1e-9, 1e-8) == pytest.approx(5e3)
    assert next_stage([10.0, 1e2, 1e3, 1e4], 1, 1e-10, 1e-8) == 1e3  # next one below the cap: as scheduled
    assert next_stage([10.0, 1e2, 1e3, 1e4], 2, 4e-9, 1e-8) is None  # cap 1.25e3 < 1.5 M: stop here
    # the default M (1e4) is lowered to where its floor is tol / 2; a chosen M is solved as given
    # solver.M = 'auto' (its number 1e4): floor 2e-8 at 1e4 -> the M of floor tol/2, 1e4 x 5e-9 / 2e-8
    assert penalty_retry(1e4, 2e-8, 1e-8, True) == pytest.approx(2.5e3) and penalty_retry(1e4, 2e-9, 1e-8, True) is None
    assert penalty_retry(1e4, 2e-8, 1e-8, False) is None  # a number, even 1e4, is solved as given
    assert penalty_retry(1e8, 2e-4, 1e-8, False) is None


def test_extrapolation_error_is_the_change_from_one_term_less_with_two_stages_too():
    """Two stages (a floor-capped schedule) fit the corrected energies C = v* + c2/M^2 (powers (0, 2));
    the error estimate is then the change from the last stage's own C, not nan, and bounds the true
    error (the 1/M^3 term left over) here; with three stages (powers (0, 2, 3)) the law is fitted
    exactly and the estimate is the change from the two-term fit. The plain Richardson of the
    uncorrected E = C + lambda . g (here lambda . g = -0.7/M: a law 3 - 0.7/M - 5/M^2 + 40/M^3 of degree
    3) is exact from four stages only, so with three its leftover 40/M^3 term shows."""
    from vesicle_opt.model.penalty import extrapolation

    def rec(M):  # lambda = -M g with g = (0, -sqrt(0.7)/M): E = C + lambda . g = C - 0.7/M
        g = np.sqrt(0.7) / M
        C = 3.0 - 5.0 / M**2 + 40.0 / M**3
        return {"M": M, "energy": C - 0.7 / M, "volume_residual": 0.0, "area_residual": -g, "lambda_volume": 0.0,
                "lambda_area": M * g, "converged": True}

    two = extrapolation([rec(M) for M in (1e2, 2.7e2)])
    assert two["extrapolation_order"] == 1
    assert two["energy_corrected"] == pytest.approx(rec(2.7e2)["energy"] + 0.7 / 2.7e2, rel=1e-14)
    assert two["energy_extrapolation_error"] == pytest.approx(abs(two["energy_extrapolated"] - two["energy_corrected"]),
                                                              rel=1e-12)
    assert abs(two["energy_extrapolated"] - 3.0) <= two["energy_extrapolation_error"]
    three = extrapolation([rec(M) for M in (1e2, 1e3, 2.7e3)])
    assert three["extrapolation_order"] == 2 and three["energy_extrapolated"] == pytest.approx(3.0, rel=1e-13)
    assert 0 < three["energy_extrapolation_error"] < two["energy_extrapolation_error"]
    # plain degree 2 through M = 1e2 ... 2.7e3 leaves 40 x1 x2 x3 = 1.5e-10 (the Lagrange remainder)
    assert abs(three["energy_extrapolated_plain"] - 3.0) == pytest.approx(40 / (1e2 * 1e3 * 2.7e3), rel=1e-3)


def test_dual_secant_reaches_the_root_of_a_linear_dual_in_few_steps():
    """c(mu) = J (mu - mu*) with a non-diagonal J (the AL's dual, linearised): the first step is the
    first-order mu - M c; Broyden then converges superlinearly, far faster than the first-order
    iteration (whose rate here is |1 - M J| ~ 0.5)."""
    from vesicle_opt.model.penalty import DualSecant
    J = np.array([[2e-3, 5e-4], [3e-4, 1e-3]])
    star = np.array([0.4, -0.9])
    M = 500.0
    sec, mu, first, mu1 = DualSecant(), np.zeros(2), None, np.zeros(2)
    for k in range(8):
        mu = sec.step(mu, J @ (mu - star), M)
        mu1 = mu1 - M * (J @ (mu1 - star))
        if k == 0:
            first = mu.copy()
    np.testing.assert_allclose(first, -M * (J @ (-star)))  # the first step is the classical update
    assert np.linalg.norm(mu - star) <= 1e-12  # Broyden on 2 x 2 linear: exact after ~2n steps
    assert np.linalg.norm(mu1 - star) > 1e-3  # first-order after 8 steps: still far
