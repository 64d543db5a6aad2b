"""The Newton-Krylov backend (issue 6) against independent references: IPOPT on the same discrete
problem (2D and small 3D), a dense reduced solve for the projected CG, Theorem 3.2's O(1/M) expansion
for the penalty form, honest failure, and the backend dispatch through ``solve`` and the CLI."""

import json

import numpy as np
import pytest

from vesicle_opt.nk import solve as nk
from vesicle_opt import scene as S
from vesicle_opt.backends import choose_backend
from vesicle_opt.cli import main as cli_main
from vesicle_opt.errors import InputError, SolverError
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.nk.setup import prepare, resample
from vesicle_opt.result import Status
from vesicle_opt.nk.krylov import SubspacePreconditioner, projected_pcg
from vesicle_opt.nlp import build_nlp
from vesicle_opt.api import solve
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.scene.schema import Constraints

ENERGY_REL = 1e-8  # issue 6: the backends agree on the energy to 1e-8 relative
LAMBDA_REL = 1e-6  # ... and on the multipliers to 1e-6 (relative to their size)


def _scene(name, *sets):
    return S.load(name, list(sets))


def _ellipsoid_3d(**solver):
    """A small 3D periodic scene (10^3 FD) whose IPOPT solve takes ~2 s."""
    raw = {"domain": {"box": [[-2.5, 2.5]] * 3, "boundary": "periodic"},
           "mesh": {"kind": "fd", "n": 10}, "model": {"epsilon": 0.3},
           "constraints": {"target": {"shape": "ellipsoid", "semi_axes": [1.3, 1.0, 0.8]}},
           "initial": {"shape": "ellipsoid", "semi_axes": [1.15, 1.0, 0.9]},
           "solver": {"tol": 1e-10, **solver}}
    return S.from_dict(raw, "ellipsoid-3d")


def _agree(ri, rn):
    assert ri.converged and rn.converged, (ri.status, rn.status)
    assert abs(rn.energy / ri.energy - 1) <= ENERGY_REL
    scale = max(abs(ri.lambda_volume), abs(ri.lambda_area))
    assert abs(rn.lambda_volume - ri.lambda_volume) <= LAMBDA_REL * scale
    assert abs(rn.lambda_area - ri.lambda_area) <= LAMBDA_REL * scale


def _dense_problem(rng, n: int = 40, k: int = 3):
    """(H, C, b, diag H): an SPD H, k random constraint columns, a right-hand side."""
    Q = rng.standard_normal((n, n))
    H = Q @ Q.T + n * np.eye(n)
    return H, rng.standard_normal((n, k)), rng.standard_normal(n), np.diag(H).copy()


def test_projected_pcg_reaches_roundoff_in_the_subspace_for_every_seed():
    """With the residual update (``SubspacePreconditioner``) CG reaches eta = 1e-13 on every one of
    20 random problems and its iterate stays in {C^T x = 0} to round-off. Without it the recursive
    residual tended to C lambda, stalled near 1e-9 and the iterates left the subspace on 7 of
    these 20 seeds (|C^T x| up to 0.2): whether a test passed depended on its seed."""
    for seed in range(20):
        H, C, b, d = _dense_problem(np.random.default_rng(seed))
        n = b.size
        res = projected_pcg(lambda v: H @ v, b, SubspacePreconditioner(lambda r: r / d, C), 1e-13, 200)
        assert res.status == "converged" and res.iterations <= n, (seed, res.iterations)  # CG: <= n - k steps + round-off
        assert np.max(np.abs(C.T @ res.x)) <= 1e-12 * np.max(np.abs(C)) * np.max(np.abs(res.x)), seed


def test_projected_pcg_matches_dense_reduced_solve(rng):
    H, C, b, d = _dense_problem(rng)
    k = C.shape[1]
    prec = SubspacePreconditioner(lambda r: r / d, C)
    res = projected_pcg(lambda v: H @ v, b, prec, 1e-13, 200)
    Z = np.linalg.svd(C.T)[2][k:].T  # orthonormal basis of {C^T x = 0}
    ref = Z @ np.linalg.solve(Z.T @ H @ Z, Z.T @ b)
    assert res.status == "converged"
    assert np.max(np.abs(C.T @ res.x)) <= 1e-12 * np.max(np.abs(C))  # stays in the subspace (round-off)
    # measured <= 1.1e-13 over 21 seeds at eta = 1e-13 (6e-10 before the residual update, when the
    # recursive residual stalled at round-off before eta was reached): 100x margin
    assert np.max(np.abs(res.x - ref)) <= 1e-11 * np.max(np.abs(ref))


def test_projected_pcg_stops_on_negative_curvature():
    H = np.diag([1.0, -1.0, 2.0])
    res = projected_pcg(lambda v: H @ v, np.array([1.0, 1.0, 0.0]), SubspacePreconditioner(lambda r: r, None),
                        1e-12, 10)
    assert res.status == "negative_curvature"


def test_nk_matches_ipopt_ellipse_2d():
    sc = _scene("ellipse-2d", "mesh.n=64", "solver.tol=1e-10")
    ri = solve(build_nlp(sc))
    rn = nk.solve(sc)
    _agree(ri, rn)
    assert rn.extra["kkt_dual"] <= 1e-10  # the stopping test it reports was met


def test_nk_matches_ipopt_small_3d():
    sc = _ellipsoid_3d()
    # the core's feasibility bound (a 1D IPOPT solve) fails to converge on this box; the target
    # shape's own (alpha, beta) are feasible by construction, so the check is skipped
    ri = solve(build_nlp(sc, check=False))
    rn = nk.solve(sc, check=False)
    _agree(ri, rn)


@pytest.mark.slow
def test_nk_matches_ipopt_torus_16_fd():
    sc = _scene("torus-table1-3d", "mesh.n=16", "solver.tol=1e-10")
    _agree(solve(build_nlp(sc)), nk.solve(sc))


def test_penalty_obeys_theorem_3_2_expansion():
    """E(phi_M) = E* - |lam|^2/M + O(1/M^2) and E_M(phi_M) = E* - |lam|^2/(2M) + O(1/M^2).

    First order: the penalty minimiser has rig dE = -M c . dc, so lam = -M c and
    rig E(phi_M) ~ E* + lam . (c(phi_M)) = E* - |lam|^2/M; E_M adds M|c|^2/2 = |lam|^2/(2M).
    """
    # tol 5e-9: the penalty's round-off floor on 64^2 is 1.9e-9 at M = 2e3 (measured), so 1e-10
    # could not be certified; the last Newton step still lands far below tol (kkt 4e-10 measured)
    base = ("mesh.n=64", "solver.tol=5e-9")
    ex = nk.solve(_scene("ellipse-2d", *base))
    lam2 = ex.lambda_volume**2 + ex.lambda_area**2
    rem, rem_pen = {}, {}
    for M in (1e3, 2e3):
        p = nk.solve(_scene("ellipse-2d", *base, "solver.method='penalty'", f"solver.M={M}"))
        assert p.converged and p.method == "penalty" and p.M == M
        rem[M] = p.energy - (ex.energy - lam2 / M)
        rem_pen[M] = p.penalized_energy - (ex.energy - lam2 / (2 * M))
        # the first-order term explains all but 1% of the shift (measured 0.06%)
        assert abs(rem[M]) <= 1e-2 * lam2 / M and abs(rem_pen[M]) <= 1e-2 * lam2 / M
        # penalty multipliers -M c converge to the exact ones at O(1/M) (measured 6e-5 at M = 1e3)
        assert abs(p.lambda_area - ex.lambda_area) <= 10 * np.sqrt(lam2) / M
    # the remainders are second order: halving 1/M quarters them (measured 4.00; [3, 5] allows
    # the O(1/M^3) terms and the 1e-10 solver tolerance)
    assert 3.0 <= rem[1e3] / rem[2e3] <= 5.0
    assert 3.0 <= rem_pen[1e3] / rem_pen[2e3] <= 5.0


def test_failure_is_reported_not_returned_as_solution():
    sc = _scene("ellipse-2d", "mesh.n=32", "solver.max_iter=2")
    r = nk.solve(sc)
    assert not r.converged and not r.success and r.status == "max_iter"
    assert r.outcome == Status.MAX_ITERATIONS
    with pytest.raises(SolverError):
        solve(sc, backend="newton-krylov", throw=True)


def test_backend_dispatch_and_validation():
    spectral = _scene("torus-table1-3d", "mesh.kind='spectral'", "mesh.n=16", "solver.backend='ipopt'")
    with pytest.raises(InputError, match="solver.backend"):  # forcing IPOPT on a spectral mesh
        choose_backend(spectral)
    # the default backend is "auto" (README: it was "ipopt" before), which runs spectral meshes
    assert choose_backend(_scene("torus-table1-3d", "mesh.kind='spectral'", "mesh.n=16")) == "newton-krylov"
    auto = _scene("torus-table1-3d", "mesh.kind='spectral'", "mesh.n=16", "solver.backend='auto'")
    assert choose_backend(auto) == "newton-krylov"
    assert choose_backend(_scene("ellipse-2d", "solver.backend='auto'")) == "ipopt"
    assert choose_backend(_scene("torus-table1-3d", "mesh.n=32", "solver.backend='auto'")) == "newton-krylov"
    with pytest.raises(InputError, match="solver.backend"):
        choose_backend(_scene("sphere-3d", "mesh.mass='consistent'", "solver.backend='newton-krylov'"))
    r = solve(auto)  # Scene -> dispatched; the same Result type with the backend recorded
    assert r.converged and r.extra["backend"] == "newton-krylov" and r.extra["mesh_kind"] == "spectral"


def test_cli_solve_spectral(tmp_path):
    code = cli_main(["solve", "torus-table1-3d", "--out", str(tmp_path), "--set", "mesh.kind='spectral'",
                     "--set", "mesh.n=16", "--set", "solver.backend='newton-krylov'"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert code == 0 and summary["converged"] and summary["backend"] == "newton-krylov"
    assert (tmp_path / "phi.png").exists() and (tmp_path / "phi.npz").exists()
    assert cli_main(["solve", "torus-table1-3d", "--out", str(tmp_path), "--set", "mesh.kind='spectral'",
                     "--set", "domain.boundary='natural'"]) == 2


def test_nk_matches_ipopt_fem_2d():
    """P1 lumped mesh with natural boundaries: sparse operators and the LU-preconditioned model."""
    # tol 1e-9: at 1e-10 both backends end at a symmetric KKT point where a soft mode (the mesh
    # diagonals break the ellipse's symmetry) has slightly negative curvature and round-off rules
    sc = _scene("ellipse-2d", "mesh.kind='fem-p1'", "domain.boundary='natural'", "mesh.n=48",
                "solver.tol=1e-9")
    _agree(solve(build_nlp(sc)), nk.solve(sc))


def test_nested_start_reaches_the_same_solution():
    # tol 1e-9: the L2 round-off floor of the 128^2 FFT grid is 4.5e-10 (measured), so 1e-10 is not certifiable
    sc = _scene("ellipse-2d", "mesh.n=128", "solver.tol=1e-9")
    nested = nk.solve(sc, options=NewtonKrylovOptions.from_scene(sc, nested=True))
    cold = nk.solve(sc, options=NewtonKrylovOptions.from_scene(sc, nested=False))
    assert nested.extra["levels"] == "64x64 128x128" and cold.extra["levels"] == "128x128"
    _agree(nested, cold)


def test_resample_is_the_trigonometric_interpolant():
    """On [0, 2 pi)^2 grids (resample works in grid index space: the box does not enter)."""
    coarse, fine = (8, 12), (16, 24)
    x = [np.arange(n) * 2 * np.pi / n for n in coarse]
    X = [np.arange(n) * 2 * np.pi / n for n in fine]
    f = lambda a, b: np.sin(a)[:, None] * np.cos(2 * b)[None, :] + np.cos(3 * a)[:, None]  # noqa: E731
    out = resample(f(*x).ravel(), coarse, fine)
    assert np.max(np.abs(out - f(*X).ravel())) <= 1e-13  # band-limited: exact up to round-off


def test_continuation_ends_at_the_penalty_solution():
    """NK continuation runs the IPOPT path's schedule M0, M0 r, ..., M_max and ends at the penalty
    minimiser at M_max; both backends agree stage by stage."""
    # tol 1e-8 at M <= 1e3: the round-off floor on 64^2 is 9.3e-10 at M = 1e3 (measured), certifiable
    base = ("mesh.n=64", "solver.tol=1e-8", "solver.M=1e3", "solver.M0=10", "solver.M_max=1e3")
    pen = nk.solve(_scene("ellipse-2d", *base, "solver.method='penalty'"))
    cont = nk.solve(_scene("ellipse-2d", *base, "solver.method='continuation'"))
    assert pen.converged and cont.converged and cont.method == "continuation" and cont.M == 1e3
    assert [st["M"] for st in cont.history["stages"]] == [10.0, 100.0, 1000.0]
    assert abs(cont.energy / pen.energy - 1) <= ENERGY_REL  # the same minimiser of E_{M,h}
    ip = solve(_scene("ellipse-2d", *base, "solver.method='continuation'"), backend="ipopt")
    assert ip.converged and [st["M"] for st in ip.history["stages"]] == [10.0, 100.0, 1000.0]
    for a, b in zip(ip.history["stages"], cont.history["stages"]):
        assert abs(a["energy"] / b["energy"] - 1) <= ENERGY_REL


def test_entry_point_reports_on_fem_meshes_too():
    """solve() dispatching a P1 scene to newton-krylov: topology and the matrix-free second-order
    check reported. On this coarse mesh (h > eps) the KKT point reached is a saddle (measured least
    eigenvalue -5.5e-3); descent confirms it: pushed along the negative mode and re-solved, the
    energy drops."""
    import warnings

    from vesicle_opt.verify.lobpcg import reduced_hessian_eigenvalues
    sc = _scene("ellipse-2d", "mesh.kind='fem-p1'", "domain.boundary='natural'", "mesh.n=32",
                "solver.backend='newton-krylov'")
    res = solve(sc)
    assert res.converged and res.extra["topology"] == "one component"
    assert res.extra["second_order"] == "saddle" and res.extra["second_order_min_eigenvalue"] < 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # lobpcg warns when the unwanted eigenvalues lag behind
        vals, _, vecs = reduced_hessian_eigenvalues(sc, res, prepare(sc), k=3, vectors=True)
    v = vecs[:, 0] / np.max(np.abs(vecs[:, 0]))
    pushed = solve(sc, x0=res.phi + 0.05 * v)  # 0.05: well beyond round-off, inside [-1, 1]
    assert pushed.converged
    # a saddle has lower points nearby: the push must find one (1e-4 relative: far above tol 1e-8)
    assert pushed.energy < res.energy * (1 - 1e-4)


def test_dual_model_at_is_the_push_through_identity(rng):
    """W(rho) = G^T (H + G diag(rho) G^T)^{-1} G, moved from rho to rho_new by ``dual_model_at``,
    against the dense W(rho_new) (H SPD, condition ~1e2: agreement at round-off, measured 1e-15)."""
    n = 30
    A = rng.standard_normal((n, n))
    H = A @ A.T + n * np.eye(n)
    G = rng.standard_normal((n, 2))

    def W(rho):
        return G.T @ np.linalg.solve(H + G @ np.diag(rho) @ G.T, G)
    rho, rho_new = np.array([300.0, 1400.0]), np.array([30.0, 5.0])
    moved = nk.dual_model_at(W(rho), rho, rho_new)
    assert np.allclose(moved, W(rho_new), rtol=1e-10, atol=0)  # round-off of two 2x2 inverses


def test_warm_start_lands_on_the_cold_solution():
    """``warm`` (start multipliers and a nearby solution's dual model) changes the path, not the
    point: an ellipse solved cold, then a neighbouring target solved cold and warm from it."""
    sc = S.load("ellipse-2d", ["mesh.kind='spectral'", "mesh.n=64", "solver.second_order=false"])
    first = nk.solve(sc)
    assert first.converged and first.history["dual_model"] is not None
    alpha, beta = constraint_data(sc, first.disc)
    sc2 = sc.replace(constraints=Constraints(alpha, 1.01 * beta))
    cold = nk.solve(sc2, x0=first.phi)
    warm = nk.solve(sc2, x0=first.phi, warm=((first.lambda_volume, first.lambda_area), first.history["dual_model"]))
    assert cold.converged and warm.converged
    # both KKT points to tol 1e-8: energies to O(tol)
    assert abs(warm.energy - cold.energy) <= 1e-8 * abs(cold.energy)
