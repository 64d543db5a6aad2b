"""nk_jax's operators against the numpy path (``model.lumped``, ``nk.precond``, ``nk.krylov``) on
the same grid: the same numbers to round-off (a second implementation of the same formulas)."""

import numpy as np
import pytest

jax = pytest.importorskip("jax")

from vesicle_opt import scene as S  # noqa: E402
from vesicle_opt.model.problem import constraint_data, initial_guess  # noqa: E402
from vesicle_opt.nk.krylov import projected_pcg  # noqa: E402
from vesicle_opt.nk.newton_cg import Counters, Objective  # noqa: E402
from vesicle_opt.nk.setup import prepare  # noqa: E402
from vesicle_opt.nk_jax.layout import GridLayout  # noqa: E402
from vesicle_opt.nk_jax.newton import DeviceObjective  # noqa: E402
from vesicle_opt.nk_jax.ops import GridOps, largest_grid_per_gib, memory_bytes_per_node  # noqa: E402

ROUNDOFF = 1e-13  # relative max-norm: FFT round-off ~ u log N (measured <= 1.4e-15 on these grids)


def _setup(kind, n):
    sc = S.load("torus-table1-3d", [f"mesh.kind='{kind}'", f"mesh.n={n}"])
    disc, pf, prec, translations = prepare(sc)
    layout = GridLayout(disc.grid_shape)
    return sc, disc, pf, prec, translations, layout, GridOps(disc.fourier, sc.model.epsilon, sc.model.C, layout)


def _rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("kind", ["spectral", "fd"])
def test_operators_equal_numpy(kind, rng):
    """E, A, B, dE, dB, the Hessian product with its rank-one terms, P^{-1}, the dual norm and the
    translation modes on an anisotropic grid with odd and even sides, at a random field."""
    sc, disc, pf, prec, translations, layout, ops = _setup(kind, [12, 10, 9])
    phi = np.tanh(rng.standard_normal(disc.n_nodes))
    v = rng.standard_normal(disc.n_nodes)
    st = pf.state(phi)
    P, V = layout.put(phi), layout.put(v)
    lap, r, s, E, A, B = ops.state(P)
    assert _rel(layout.get(lap), st.lap) < ROUNDOFF
    for got, want in ((E, st.E), (A, st.A), (B, st.B)):
        assert abs(float(got) - want) < ROUNDOFF * abs(want)
    dE, dA, dB = pf.gradients(st)
    jdE, jdB = ops.gradients(P, lap, r, s)
    assert _rel(layout.get(jdE), dE) < ROUNDOFF and _rel(layout.get(jdB), dB) < ROUNDOFF
    rig, cB, rA, rB = 10.0, -3.0, 5.0, 7.0
    want = pf.hvp(st, pf.hessian_parts(st), v, rig, cB) + rA * (dA @ v) * dA + rB * (dB @ v) * dB
    got = ops.hvp(s, *ops.hessian_parts(P, r), jdB, V, rig, cB, rA, rB)
    assert _rel(layout.get(got), want) < ROUNDOFF
    assert _rel(layout.get(ops.apply_inverse(V, rig, cB, 2.0)), prec.inverse(rig, cB, 2.0)(v)) < ROUNDOFF
    assert abs(float(ops.dual_norm(V)) - prec.dual_norm(v)) < ROUNDOFF * prec.dual_norm(v)
    T = translations(phi)
    assert (T is None) == (disc.kind == "fd")  # FD grids: no translation modes (nk.setup.prepare)
    for i, t in enumerate(ops.derivatives(P) if T is not None else ()):
        assert _rel(layout.get(t), T[:, i]) < ROUNDOFF


def test_projected_cg_iterates_equal_numpy():
    """The compiled CG loop follows nk.krylov.projected_pcg iterate for iterate (fixed iteration
    counts, eta = 0 so neither stops early) at the torus start with multipliers and penalties."""
    sc, disc, pf, prec, translations, layout, ops = _setup("spectral", 16)
    alpha, beta = constraint_data(sc, disc)
    phi = initial_guess(sc, disc)
    lam, rho = np.array([-3.0, 29.0]), np.array([97.0, 150.0])
    obj = Objective(pf, prec, translations, 10.0, alpha, beta, lam, rho, Counters())
    jobj = DeviceObjective(ops, 10.0, alpha, beta, lam, rho, Counters())
    pt, jpt = obj.point(phi), jobj.point(layout.put(phi))
    assert abs(jpt.f - pt.f) < ROUNDOFF * abs(pt.f) and abs(jpt.rel - pt.rel) < ROUNDOFF * pt.rel
    for iters in (1, 3, 6):
        cg = projected_pcg(obj.hvp(pt), -pt.g, obj.preconditioner(pt), 0.0, iters)
        jcg = jobj.pcg(jpt, -jpt.g, 0.0, iters)[0]
        assert (jcg.iterations, jcg.status) == (cg.iterations, cg.status)
        # CG amplifies round-off with each iteration (Krylov); measured 2e-15 after 6 here
        assert _rel(layout.get(jcg.x), cg.x) < 1e-11
        assert abs(jcg.rel_residual - cg.rel_residual) < 1e-11 * cg.rel_residual


def test_memory_estimate_matches_the_compiled_cg_program():
    """XLA's memory analysis of the compiled CG loop (arguments, output, temporaries) plus the six
    fields the Newton loop holds outside it is the estimate, to 3% (its temporaries were measured
    at 64^3 and 32^3; here 20^3, so the per-node figure must not depend on the grid)."""
    sc, disc, pf, prec, translations, layout, ops = _setup("spectral", 20)
    alpha, beta = constraint_data(sc, disc)
    jobj = DeviceObjective(ops, 10.0, alpha, beta, np.zeros(2), np.array([1.0, 1.0]), Counters())
    jpt = jobj.point(layout.put(initial_guess(sc, disc)))
    coef, sub = jobj.model(jpt)
    mem = jobj.krylov._pcg.lower(-jpt.g, jobj.hess(jpt), coef, sub, 0.01, 10).compile().memory_analysis()
    if mem is None:
        pytest.skip("this jax build reports no memory analysis")
    N = disc.n_nodes
    program = mem.argument_size_in_bytes + mem.output_size_in_bytes + mem.temp_size_in_bytes - mem.alias_size_in_bytes
    per_node = program / N + 8.0 * 6
    assert abs(per_node - memory_bytes_per_node(3)) <= 0.03 * memory_bytes_per_node(3), per_node
    assert largest_grid_per_gib(1.0) == int((2**30 / memory_bytes_per_node(3)) ** (1 / 3))
