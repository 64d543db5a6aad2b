"""The front door ``vesicle_opt.solve``: the exact NLP (6)-(8) through IPOPT (KKT, constraints,
multipliers, symmetry, failure), warm starts on both backends, and what it refuses."""

import json
from dataclasses import replace

import numpy as np
import pytest

from vesicle_opt import cli
import vesicle_opt as S
from vesicle_opt.api import solve as front_door
from vesicle_opt.errors import InputError, NotSupported, SolverError
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.nlp.ipopt import IpoptOptions
from vesicle_opt.result import Status
from vesicle_opt.verify.certify import KKT_FACTOR
from vesicle_opt.nlp import build_nlp
from vesicle_opt import load_scene


TOL = 1e-8  # the scenes' solver.tol


@pytest.fixture(scope="module")
def ellipse64():
    nlp = build_nlp(load_scene("ellipse-2d", ["mesh.n=64"]))
    return nlp, S.solve(nlp)


@pytest.mark.parametrize("overrides", [
    ("mesh.n=64",),
    ("mesh.n=32", "mesh.kind='fem-p1'", "mesh.mass='consistent'"),
    ("mesh.n=32", "mesh.kind='fem-p1'", "mesh.quadrature='gauss'"),
    ("mesh.n=32", "mesh.kind='fem-p1'", "domain.boundary='natural'"),
    ("mesh.n=64", "model.c0=0.3"),
], ids=["fd", "fem-consistent", "fem-gauss", "fem-natural", "fd-c0"])
def test_exact_solution_is_kkt_point(overrides):
    """Problem x discretisation matrix: constraints and recomputed KKT residual to the tolerance."""
    res = S.solve(load_scene("ellipse-2d", overrides))
    assert res.converged, res.status
    nlp = build_nlp(load_scene("ellipse-2d", overrides))
    assert abs(res.volume_residual) <= TOL * nlp.disc.volume  # g_A = (A - alpha)/|Omega| <= tol
    assert abs(res.area_residual) <= TOL * nlp.beta  # g_B = (B - beta)/beta <= tol
    # relative L2 stationarity; KKT_FACTOR = 100 is the documented slack over IPOPT's max-norm test
    assert res.kkt_residual <= KKT_FACTOR * TOL
    assert np.all(np.abs(res.phi) < 1.1)  # a phase field, not a blow-up (|phi| <= 1 + O(eps^2))


def test_multipliers_are_energy_sensitivities(ellipse64):
    """Sensitivity theorem: dE*/d alpha = lambda_A, dE*/d beta = lambda_B at a regular minimiser."""
    nlp, res = ellipse64
    sc = nlp.scene
    for which, lam in (("alpha", res.lambda_volume), ("beta", res.lambda_area)):
        delta = 1e-4 * abs(getattr(nlp, which))
        energies = []
        for sign in (1, -1):
            data = {"alpha": nlp.alpha, "beta": nlp.beta}
            data[which] += sign * delta
            cons = replace(sc.constraints, target=None, **data)
            energies.append(S.solve(sc.replace(constraints=cons), x0=res.x).energy)
        slope = (energies[0] - energies[1]) / (2 * delta)
        # central difference O(delta^2) ~1e-8 relative, plus solve tolerances 1e-8 / delta ~1e-6
        assert slope == pytest.approx(lam, rel=1e-5), which


def test_energy_converges_at_second_order_in_h():
    """FD energies on ellipse-2d at n, 2n, 4n: Richardson's observed order (theory: 2)."""
    energies = [S.solve(load_scene("ellipse-2d", [f"mesh.n={n}"])).energy for n in (48, 96, 192)]
    order = np.log2((energies[1] - energies[0]) / (energies[2] - energies[1]))
    assert 1.8 < order < 2.3, f"observed order {order:.3f}, energies {energies}"


def test_circle_stays_a_circle():
    """The circle-2d minimiser: isotropic second moments of (phi + 1) about its centroid."""
    sc = load_scene("circle-2d")
    with pytest.warns(UserWarning, match="beta_min"):  # circle data sit near the feasibility bound
        res = S.solve(sc)
    assert res.converged
    nlp = build_nlp(sc, check=False)
    u = (res.phi + 1) / 2 * nlp.disc.weights
    x = nlp.disc.nodes - (u[:, None] * nlp.disc.nodes).sum(0) / u.sum()
    inertia = np.einsum("i,ij,ik->jk", u, x, x)
    eig = np.linalg.eigvalsh(inertia)
    # the start's anisotropy was 10%; measured 3e-7 after the solve (mesh anisotropy is O(h^4) here)
    assert (eig[1] - eig[0]) / eig.sum() < 1e-5


def test_failure_is_reported_not_returned(tmp_path):
    sc = load_scene("ellipse-2d", ["mesh.n=32", "solver.max_iter=3"])
    res = S.solve(sc)
    assert not res.converged and not res.success and res.status == "Maximum_Iterations_Exceeded"
    with pytest.raises(SolverError, match="Maximum_Iterations_Exceeded"):
        S.solve(sc, throw=True)
    rc = cli.main(["solve", "ellipse-2d", "--out", str(tmp_path), "--set", "mesh.n=32",
                   "--set", "solver.max_iter=3"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert rc == 1 and summary["converged"] is False and summary["status"] == "Maximum_Iterations_Exceeded"


def test_cli_bad_input_is_one_line_exit_2(tmp_path, capsys):
    rc = cli.main(["solve", "ellipse-2d", "--out", str(tmp_path), "--set", "model.epsilon=-1"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.count("\n") == 0 and "model.epsilon" in err and "> 0" in err
    assert not (tmp_path / "summary.json").exists()


def test_nlp_pieces_work_with_a_plain_nlpsol(ellipse64):
    """build_nlp's dict, bounds and x0 go to any casadi.nlpsol and give the same solution."""
    import casadi as ca
    nlp, res = ellipse64
    solver = ca.nlpsol("user", "ipopt", nlp.as_dict(), {"ipopt.tol": TOL, "ipopt.print_level": 0,
                                                        "print_time": False, "ipopt.sb": "yes"})
    sol = solver(x0=nlp.x0, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg)
    assert solver.stats()["success"]
    energy = float(sol["f"]) * nlp.f_scale
    assert energy == pytest.approx(res.energy, rel=1e-8)  # same minimiser to IPOPT's tolerance
    lam = nlp.multipliers(np.asarray(sol["lam_g"]))
    assert lam[0] == pytest.approx(res.lambda_volume, rel=1e-5)  # multipliers: tol / |lambda| sensitivity


def test_same_scene_twice_gives_bitwise_identical_summary(tmp_path):
    """Determinism: every number of summary.json except the timings is reproduced exactly."""
    summaries = []
    for run in ("a", "b"):
        assert cli.main(["solve", "ellipse-2d", "--out", str(tmp_path / run), "--set", "mesh.n=32"]) == 0
        summaries.append(json.loads((tmp_path / run / "summary.json").read_text()))
    timing = {"wall_time_s", "derivative_time_s", "other_time_s", "second_order_time_s"}
    assert {k: v for k, v in summaries[0].items() if k not in timing} == \
        {k: v for k, v in summaries[1].items() if k not in timing}


def test_the_package_exports_the_front_door_function():
    assert S.solve is front_door and callable(S.solve)  # not a module of that name


def test_spectral_scene_has_no_nlp_and_refuses_ipopt():
    sc = load_scene("torus-table1-3d", ["mesh.kind='spectral'", "mesh.n=16"])
    with pytest.raises(NotSupported, match="mesh.kind") as info:
        build_nlp(sc)
    assert "\n" not in str(info.value) and "newton-krylov" in str(info.value)
    with pytest.raises(NotSupported, match="solver.backend"):
        S.solve(sc, backend="ipopt")


def test_an_nlp_runs_on_ipopt_only_and_for_its_own_method(ellipse64):
    nlp, _ = ellipse64
    with pytest.raises(NotSupported, match="solver.backend"):
        S.solve(nlp, backend="newton-krylov")
    with pytest.raises(NotSupported, match="solver.method"):
        S.solve(nlp, method="penalty")
    with pytest.raises(NotSupported, match="options"):
        S.solve(nlp, options=NewtonKrylovOptions(tol=TOL))


@pytest.mark.parametrize("backend, kind", [("ipopt", "fd"), ("newton-krylov", "spectral")])
def test_an_augmented_result_is_second_order_checked_like_the_exact_one(backend, kind):
    """method augmented promises A = alpha, B = beta to tol, so its point gets the check the exact
    method's gets, on the exact Lagrangian (lambda = mu - M c): the same verdict and eigenvalue. FD on
    64^2 (issue 25: augmented now warms up through M0 r^k, and on 48^2, where the symmetric FD point is a
    saddle (eps/h = 1.2), that path leaves it for the lower minimum, as continuation does), spectral 48^2."""
    sc = load_scene("ellipse-2d", [f"mesh.n={64 if kind == 'fd' else 48}", f"mesh.kind='{kind}'"])
    exact, aug = (S.solve(sc, backend=backend, method=m, throw=True) for m in ("exact", "augmented"))
    assert aug.extra["second_order"] == exact.extra["second_order"] != "not checked"
    mu_e, mu_a = exact.extra["second_order_min_eigenvalue"], aug.extra["second_order_min_eigenvalue"]
    # the two points differ by their constraint residuals (<= tol = 1e-8): measured 7.7e-7 (IPOPT) and
    # 8.8e-7 (NK, whose LOBPCG levels settle to 1e-6) relative
    assert abs(mu_a - mu_e) <= 1e-5 * abs(mu_e), (mu_a, mu_e)


@pytest.mark.parametrize("backend", ["ipopt", "newton-krylov"])
def test_one_warm_start_argument_on_both_backends(backend):
    """x0 = an earlier Result (or its phi) on either backend: the same minimiser in few iterations."""
    sc = load_scene("ellipse-2d", ["mesh.n=48", "solver.second_order=false"])
    cold = S.solve(sc, backend=backend, throw=True)
    for x0 in (cold, cold.phi):
        warm = S.solve(sc, backend=backend, x0=x0, throw=True)
        # the same KKT point: energies agree to the certified tolerance (tol 1e-8 relative; measured 0 and 1.8e-12)
        assert abs(warm.energy - cold.energy) <= TOL * cold.energy
        # started at the solution: at most a few iterations (measured 0 IPOPT, 1 NK, against 23 and 24 cold)
        assert warm.iterations <= max(3, cold.iterations // 4), (warm.iterations, cold.iterations)
    with pytest.raises(InputError, match="x0"):
        S.solve(sc, backend=backend, x0=np.zeros(7))


def test_options_replace_the_scene_settings_per_backend():
    sc = load_scene("ellipse-2d", ["mesh.n=32", "solver.second_order=false"])
    r = S.solve(sc, options=IpoptOptions(tol=TOL, max_iter=2))
    assert not r.converged and r.outcome == Status.MAX_ITERATIONS and r.iterations == 2
    r = S.solve(sc, backend="newton-krylov", options=NewtonKrylovOptions(tol=TOL, max_iter=2))
    assert not r.converged and r.outcome == Status.MAX_ITERATIONS
    with pytest.raises(NotSupported, match="options"):
        S.solve(sc, backend="newton-krylov", options=IpoptOptions(tol=TOL))
    with pytest.raises(SolverError) as info:
        S.solve(sc, options=IpoptOptions(tol=TOL, max_iter=2), throw=True)
    assert info.value.result is not None and info.value.result.outcome == Status.MAX_ITERATIONS


def test_a_method_override_is_checked_before_any_work():
    sc = load_scene("ellipse-2d", ["mesh.n=32"])
    for backend in (None, "auto", "newton-krylov"):
        with pytest.raises(NotSupported, match="solver.method"):
            S.solve(sc, backend=backend, method="penlaty")


def test_nk_resamples_a_result_of_another_grid_and_refuses_a_bare_field_of_another_size():
    """Issue 12: a Result carries its grid, so another periodic grid of the same box is Fourier-
    resampled (model.warm_start); a bare array of another size has no grid to resample from."""
    small = S.solve(load_scene("ellipse-2d", ["mesh.n=32", "solver.second_order=false"]), backend="newton-krylov")
    # finer (h = 8/48 <= eps = 0.2) and coarser (h = 0.33): on 24^2 this FD start reaches an
    # asymmetric KKT point, where the projection of the spectral translations (not symmetries of the
    # FD stencil) froze the gradient's translation part: a round-off stall at dual ~2e-6 (before
    # ``nk.setup.prepare`` dropped the projection on FD grids; now kkt 6e-12 in 61 Newton steps)
    for n in (48, 24):
        sc = load_scene("ellipse-2d", [f"mesh.n={n}", "solver.second_order=false"])
        assert S.solve(sc, backend="newton-krylov", x0=small).converged, n
    with pytest.raises(InputError, match="x0"):
        S.solve(sc, backend="newton-krylov", x0=small.phi)


@pytest.mark.parametrize("backend", ["ipopt", "newton-krylov"])
def test_both_backends_start_from_an_earlier_solves_file(backend, tmp_path):
    """initial.shape = 'file' (a phi.npz of an earlier solve on the same mesh) on either backend."""
    sets = ["mesh.n=32", "solver.second_order=false"]
    first = S.solve(load_scene("ellipse-2d", sets), throw=True)
    cold = S.solve(load_scene("ellipse-2d", sets), backend=backend, throw=True)
    np.savez(tmp_path / "phi.npz", phi=first.phi)
    again = S.solve(load_scene("ellipse-2d", [*sets, f"initial={{shape='file', file='{tmp_path / 'phi.npz'}'}}"]),
                    backend=backend, throw=True)
    assert abs(again.energy - first.energy) <= TOL * first.energy  # the same KKT point, to the certified tol
    # started at it: a few steps, far fewer than from the shape (measured IPOPT 0 against 74-81, NK
    # 1-4 against 23, depending on the BLAS kernel)
    assert again.iterations <= cold.iterations // 4, (again.iterations, cold.iterations)


def test_nk_continuation_stages_carry_their_own_counts():
    """history['stages'] holds each stage's Newton steps and times; the run's are their sums here
    (32^2, eps 0.4: no coarse level, so every Newton step belongs to a stage)."""
    sc = load_scene("ellipse-2d", ["mesh.n=32", "model.epsilon=0.4", "solver.method='continuation'",
                                   "solver.M0=10.0", "solver.M_max=1e3", "solver.second_order=false"])
    r = S.solve(sc, backend="newton-krylov", throw=True)  # M0 = 10 (the default is 100): three stages
    stages = r.history["stages"]
    assert [s["M"] for s in stages] == [10.0, 100.0, 1000.0]
    # the run's also counts the augmented polish after the stages (issue 25; nlp.continuation.polish_stage)
    assert sum(s["iterations"] for s in stages) + r.extra["polish_iterations"] == r.iterations \
        == r.extra["newton_iterations"]
    assert all(s["iterations"] < r.iterations for s in stages)  # not the run's totals
    assert sum(s["wall_time_s"] for s in stages) <= r.wall_time_s


def test_a_solve_meets_its_physical_targets_and_reports_them():
    """reduced_volume and area in, the same out of the certified field (summary keys of geometry)."""
    sc = S.scene.from_dict({
        "domain": {"box": [[-4, 4], [-4, 4]]}, "mesh": {"kind": "fd", "n": 64}, "model": {"epsilon": 0.25},
        "constraints": {"reduced_volume": 0.8, "area": 10.0},
        "initial": {"shape": "ellipse", "semi_axes": [2.0, 1.1]}, "solver": {"second_order": False}})
    r = S.solve(sc)
    s = r.summary(sc.name)
    assert r.converged
    assert s["reduced_volume"] == pytest.approx(0.8, rel=1e-6)  # constraints met to tol 1e-8 relative
    assert s["area"] == pytest.approx(10.0, rel=1e-6)
    # an ellipse-like closed curve has more bending energy than the circle of its perimeter
    assert s["reduced_energy"] > 1 and s["energy"] == pytest.approx(
        s["reduced_energy"] * S.geometry.sphere_energy(s["area"], 2), rel=1e-12)
