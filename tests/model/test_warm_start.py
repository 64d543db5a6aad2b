"""Warm starts (model.warm_start): Fourier resampling between periodic grids, the refusals, and a
start from an earlier solve's file on both backends and in every flow scheme."""

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt.errors import InputError
from vesicle_opt.mesh import discretize
from vesicle_opt.model.warm_start import carry, fourier_resample, grid_of, load_warm_start
from vesicle_opt.flows.trackers import HistoryTracker

BASE = ["mesh.n=32", "model.epsilon=0.4"]  # eps/h = 1.6 on the 8 x 8 box


def _trig(nodes):
    """A trigonometric polynomial of degree 3 on the [-4, 4]^2 box: band-limited on 12^2 and finer."""
    x, y = nodes[:, 0] * np.pi / 4, nodes[:, 1] * np.pi / 4
    return np.sin(x) * np.cos(2 * y) + 0.3 * np.cos(3 * x + y) + 0.1


def test_fourier_resample_is_exact_on_a_band_limited_field():
    src = discretize(vo.load_scene("ellipse-2d", ["mesh.n=[12, 16]"]))
    dst = discretize(vo.load_scene("ellipse-2d", ["mesh.n=[40, 20]"]))
    assert grid_of(src.nodes, src.box) == (12, 16)
    got = fourier_resample(_trig(src.nodes), (12, 16), (40, 20))
    np.testing.assert_allclose(got, _trig(dst.nodes), rtol=0, atol=1e-13)  # interpolation is exact: round-off


def test_files_of_another_periodic_grid_are_resampled(tmp_path):
    src = discretize(vo.load_scene("ellipse-2d", ["mesh.n=24", "mesh.kind='spectral'"]))
    np.savez(tmp_path / "phi.npz", phi=_trig(src.nodes), nodes=src.nodes)
    for kind in ("fd", "fem-p1", "spectral"):  # periodic P1 numbers its dofs as the C-order grid
        dst = discretize(vo.load_scene("ellipse-2d", ["mesh.n=36", f"mesh.kind='{kind}'"]))
        phi = load_warm_start(tmp_path / "phi.npz", dst)
        np.testing.assert_allclose(phi, _trig(dst.nodes), rtol=0, atol=1e-13)  # exact: round-off


@pytest.mark.parametrize("sets", [["domain.box=[[-3.0, 3.0], [-4.0, 4.0]]"],
                                  ["mesh.kind='fem-p1'", "domain.boundary='natural'"]],
                         ids=["another box", "natural boundary"])
def test_another_mesh_is_refused_naming_both_shapes(tmp_path, sets):
    src = discretize(vo.load_scene("ellipse-2d", ["mesh.n=24"]))
    np.savez(tmp_path / "phi.npz", phi=_trig(src.nodes), nodes=src.nodes)
    dst = discretize(vo.load_scene("ellipse-2d", ["mesh.n=16", *sets]))
    with pytest.raises(InputError) as exc:
        load_warm_start(tmp_path / "phi.npz", dst)
    msg = str(exc.value)
    assert msg.startswith("initial.file") and "24x24 grid" in msg and "\n" not in msg
    assert ("16x16 grid" in msg) or (f"{dst.n_nodes} nodes" in msg)


def test_a_field_without_nodes_must_have_this_mesh_size():
    dst = discretize(vo.load_scene("ellipse-2d", ["mesh.n=16"]))
    with pytest.raises(InputError, match="x0"):
        carry(np.zeros(10), None, dst, "x0", "the start")


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    """An equilibrium on FD 32^2 written as the CLI writes it, and the cold solve on 24^2."""
    out = tmp_path_factory.mktemp("ref")
    res = vo.solve(vo.load_scene("ellipse-2d", BASE))
    np.savez(out / "phi.npz", phi=res.phi, nodes=res.disc.nodes)
    cold24 = vo.solve(vo.load_scene("ellipse-2d", ["mesh.n=24", "model.epsilon=0.4"]))
    assert res.converged and cold24.converged
    return out / "phi.npz", res, cold24


@pytest.mark.parametrize("backend, kind", [("ipopt", "fd"), ("newton-krylov", "fd"), ("newton-krylov", "spectral")])
def test_solve_from_a_file_on_both_backends(solved, backend, kind):
    path, ref, cold24 = solved
    file_start = f'initial={{shape="file", file="{path}"}}'
    same = vo.solve(vo.load_scene("ellipse-2d", [*BASE, file_start, f"solver.backend='{backend}'",
                                                 f"mesh.kind='{kind}'"]))
    assert same.converged, same.reason
    if kind == "fd":  # the same discrete problem: the same KKT point, to the solve's tolerance
        assert abs(same.energy - ref.energy) <= 1e-7 * ref.energy  # tol 1e-8, kkt <= 100 tol
    coarse = vo.solve(vo.load_scene("ellipse-2d", ["mesh.n=24", "model.epsilon=0.4", file_start,
                                                   f"solver.backend='{backend}'"]))
    assert coarse.converged, coarse.reason
    assert abs(coarse.energy - cold24.energy) <= 1e-7 * cold24.energy  # the cold solve's minimiser
    api = vo.solve(vo.load_scene("ellipse-2d", ["mesh.n=24", "model.epsilon=0.4"]), backend=backend, x0=path)
    assert api.converged and abs(api.energy - cold24.energy) <= 1e-7 * cold24.energy  # one argument name: x0


@pytest.mark.parametrize("scheme, kind", [("penalty", "fd"), ("lagrange", "fd"), ("backward-euler", "fd"),
                                          ("penalty", "spectral"), ("lagrange", "spectral")])
def test_every_flow_scheme_starts_from_a_file(solved, scheme, kind):
    path, ref, _ = solved
    sets = [*BASE, f"flow.scheme='{scheme}'", f"mesh.kind='{kind}'", "flow.steps=2", "flow.dt=1e-4"]
    sc = vo.load_scene("ellipse-2d", [*sets, f'initial={{shape="file", file="{path}"}}'])
    run = vo.flow(sc, trackers=[HistoryTracker(keep=True)])
    by_x0 = vo.flow(vo.load_scene("ellipse-2d", sets), x0=path, trackers=[HistoryTracker(keep=True)])
    assert not run.failed and run.steps == 2 and by_x0.steps == 2
    energies = [row["energy"] for row in run.history]
    if kind == "fd":  # started at the solve's equilibrium: E stays there (penalty M = 1e4: O(1/M) off)
        assert max(abs(e - ref.energy) for e in energies) <= 1e-4 * ref.energy
    if scheme == "lagrange" and kind == "fd":  # (17) keeps A, B; from a KKT point phi_t ~ 0: E constant to round-off
        assert max(energies) - min(energies) <= 1e-10 * ref.energy
