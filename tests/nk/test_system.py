"""The Newton system in the orthonormal Fourier coordinates (``nk.system.FourierSystem``) against
the same system on nodal values (``NodalSystem``): T is orthogonal, so CG is the same iteration in
exact arithmetic; the two solutions agree to the CG tolerance with the same iteration count, for the
augmented Lagrangian with translations projected out (spectral), without them (FD) and for the
proximal objective of the flows (a shift, no projection); whole solves land on the same KKT point.
Also: CG writing z into its spent direction gives the same iterates bit for bit."""

import numpy as np
import pytest

from vesicle_opt import load_scene
from vesicle_opt.api import solve
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.nk.krylov import SubspacePreconditioner, projected_pcg
from vesicle_opt.nk.newton_cg import Counters, Objective
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.nk.solve import solve as nk_solve
from vesicle_opt.nk.proximal import ProximalObjective
from vesicle_opt.nk.setup import prepare
from vesicle_opt.nk.system import FourierSystem, NodalSystem

ETA = 1e-10  # CG to a relative dual residual of 1e-10: two solutions then differ by ~1e-10 |x| times kappa^(1/2)


def _pieces(kind, rng, n=16):
    """The torus's equilibrium of this grid, perturbed by a smooth field, with its multipliers and rho = 50: a point
    where the augmented Lagrangian's Hessian is positive off the translations."""
    sc = load_scene("torus-table1-3d", [f"mesh.kind='{kind}'", f"mesh.n={n}", "solver.second_order=false",
                                         "solver.backend='newton-krylov'"])
    ref = solve(sc)
    disc, pf, prec, translations = prepare(sc)
    alpha, beta = constraint_data(sc, disc)
    x = disc.nodes
    smooth = np.cos(x[:, 0] + rng.random()) * np.sin(x[:, 1]) * np.cos(x[:, 2])  # resolved: no aliasing
    phi = ref.phi + 1e-2 * smooth
    lam = np.array([ref.lambda_volume, ref.lambda_area])
    args = (pf, prec, translations, sc.model.rigidity, alpha, beta, lam, np.array([50.0, 50.0]))
    return args, phi


def _both(make, phi, rhs):
    out = []
    for coordinates in (True, False):
        obj = make(coordinates)
        pt = obj.point(phi)
        system = obj.newton_system(pt)
        out.append((system, system.solve(rhs(pt), ETA, 500)))
    return out


@pytest.mark.parametrize("kind", ["spectral", "fd"])
def test_the_fourier_system_solves_what_the_nodal_one_solves(kind, rng):
    args, phi = _pieces(kind, rng)
    (fs, a), (ns, b) = _both(lambda c: Objective(*args, Counters(), coordinates=c), phi, lambda pt: -pt.g)
    assert isinstance(fs, FourierSystem) and isinstance(ns, NodalSystem)
    # spectral: converged; FD (whose continuous translations are not null modes, so not projected)
    # meets a direction of nonpositive curvature on the perturbed point: the same one on both
    assert a.status == b.status == ("converged" if kind == "spectral" else "negative_curvature")
    assert abs(a.iterations - b.iterations) <= 1, (a.iterations, b.iterations)  # one iteration, two round-offs
    assert np.linalg.norm(a.x - b.x) <= 1e-7 * np.linalg.norm(b.x)  # ETA times the model's condition ~1e3
    if kind == "spectral":  # the translations are projected out of both
        T = args[2](phi)
        w = args[0].uniform_weight
        assert np.abs(T.T @ a.x).max() * w <= 1e-9 * np.linalg.norm(T, axis=0).max() * np.linalg.norm(a.x) * w


@pytest.mark.parametrize("kind", ["spectral", "fd"])
def test_the_proximal_step_system_too(kind, rng):
    args, phi = _pieces(kind, rng)
    anchor = phi + 0.05 * rng.standard_normal(phi.size)

    def make(c):
        return ProximalObjective(*args, Counters(), anchor=anchor, c=25.0, coordinates=c)
    (fs, a), (ns, b) = _both(make, phi, lambda pt: -pt.g)
    assert isinstance(fs, FourierSystem) and fs.shift > 0 and fs.precond.C is None
    assert a.status == b.status == "converged" and abs(a.iterations - b.iterations) <= 1
    assert np.linalg.norm(a.x - b.x) <= 1e-7 * np.linalg.norm(b.x)
    # its fallback direction, P^{-1} v without a projection, is the nodal model's
    v = rng.standard_normal(phi.size)
    # the same diagonal by two transform routes: round-off O(u log N) times the symbol's spread (~1e2)
    assert np.linalg.norm(fs.precondition(v) - ns.precondition(v)) <= 1e-12 * np.linalg.norm(ns.precondition(v))


@pytest.mark.parametrize("sets", [["mesh.kind='spectral'"], ["mesh.kind='fd'", "solver.method='penalty'"]])
def test_a_solve_is_the_same_on_either_system(sets):
    """Whole Newton-Krylov solves (exact constraints on the spectral grid; the penalty (11) on FD,
    where rho_A and rho_B are M) land on the same KKT point on either system."""
    sc = load_scene("torus-table1-3d", [*sets, "mesh.n=16", "solver.second_order=false", "solver.backend='newton-krylov'"])
    a = nk_solve(sc, options=NewtonKrylovOptions.from_scene(sc))
    b = nk_solve(sc, options=NewtonKrylovOptions.from_scene(sc, fourier_coordinates=False))
    assert a.converged and b.converged, (a.status, b.status)
    # tol 1e-8: two KKT points of one problem agree in E to ~tol^2 relative (measured <= 1e-12)
    assert abs(a.energy - b.energy) <= 1e-10 * abs(b.energy)
    assert abs(a.iterations - b.iterations) <= 2  # the same Newton path up to round-off


def test_cg_writing_into_its_spent_direction_is_the_same_iteration(rng):
    n, k = 60, 3
    Q = rng.standard_normal((n, n))
    H = Q @ Q.T + n * np.eye(n)
    C, b = rng.standard_normal((n, k)), rng.standard_normal(n)
    d = np.diag(H).copy()
    plain = projected_pcg(lambda v: H @ v, b, SubspacePreconditioner(lambda r: r / d, C), 1e-12, 200)
    calls = []

    def into(r, out=None):
        calls.append(out is not None)
        return np.divide(r, d, out=out)
    reused = projected_pcg(lambda v: H @ v, b, SubspacePreconditioner(into, C, writes_into=True), 1e-12, 200)
    assert np.array_equal(plain.x, reused.x) and plain.iterations == reused.iterations
    assert any(calls)  # the spent direction was written into


@pytest.mark.parametrize("coordinates", [True, False])
def test_a_spent_system_is_freed_at_once(coordinates, rng):
    """No reference cycle keeps a Newton system (a dozen fields) alive after its step: with the
    cyclic collector off, dropping the last reference frees it (a system that held its own bound
    method piled up: peak RSS 184 -> 346 MB at 64^3)."""
    import gc
    import weakref
    args, phi = _pieces("spectral", rng)
    obj = Objective(*args, Counters(), coordinates=coordinates)
    pt = obj.point(phi)
    gc.disable()
    try:
        system = obj.newton_system(pt)
        system.solve(-pt.g, 1e-3, 20)
        gone = weakref.ref(system)
        del system
        assert gone() is None
    finally:
        gc.enable()
