"""The resource guard (vesicle_opt.resources): the estimate's arithmetic, the refusal before any
work with one line naming mesh.n and the estimate, and solver.max_memory_gb."""

import time

import pytest

import vesicle_opt as vo
from vesicle_opt import cli, resources
from vesicle_opt.errors import InputError


def test_the_estimate_is_nodes_times_bytes_per_node_plus_the_feasibility_grid():
    small, big = (vo.load_scene("ellipse-2d", [f"mesh.n={n}"]) for n in (64, 128))
    grid = resources.feasibility_points(small) * resources.BYTES_PER_RADIAL_POINT  # the same box and eps
    b_small, _ = resources.estimate_bytes(small, "ipopt")
    b_big, _ = resources.estimate_bytes(big, "ipopt")
    assert b_small - grid == 64**2 * resources.BYTES_PER_NODE[("ipopt", 2)]  # integer arithmetic: exact
    assert (b_big - grid) == 4 * (b_small - grid)  # linear in the nodes in 2D
    s3 = [vo.load_scene("sphere-3d", [f"mesh.n={n}", "mesh.kind='fd'"]) for n in (20, 40)]
    per = [resources.bytes_per_node(s, "ipopt") for s in s3]
    assert per[1] == pytest.approx(2 * per[0], rel=1e-12)  # 3D IPOPT: fill grows like N^(4/3)
    assert resources.bytes_per_node(s3[0], "newton-krylov") < per[0] / 10  # matrix-free is far lighter


@pytest.mark.parametrize("sets", [["mesh.n=100000"], ["mesh.n=9223372036854775807"], ["mesh.n=5000"]])
def test_too_large_is_refused_at_once(sets):
    t0 = time.perf_counter()
    with pytest.raises(InputError) as exc:
        vo.solve(vo.load_scene("ellipse-2d", sets))
    msg = str(exc.value)
    assert msg.startswith("mesh.n:") and "GB" in msg and "solver.max_memory_gb" in msg and "\n" not in msg
    assert time.perf_counter() - t0 < 5  # before any array is made (the unguarded 20000^2 died after 14 s)


def test_max_memory_gb_sets_the_limit():
    sc = vo.load_scene("ellipse-2d", ["mesh.n=16", "solver.max_memory_gb=1e-3"])  # 1 MB: below any run
    with pytest.raises(InputError, match="solver.max_memory_gb"):
        resources.check(sc, "ipopt")
    big = vo.load_scene("ellipse-2d", ["mesh.n=100000", "solver.max_memory_gb=1e6"])
    assert resources.check(big, "newton-krylov") > 1e12  # raised: accepted (the check only estimates)
    with pytest.raises(InputError, match="solver.max_memory_gb"):
        vo.load_scene("ellipse-2d", ["solver.max_memory_gb=0"])


def test_flows_and_the_cli_are_guarded_too(tmp_path, capsys):
    with pytest.raises(InputError, match="mesh.n"):
        vo.flow(vo.load_scene("ellipse-2d", ["mesh.n=50000"]))
    for verb in (["solve", "ellipse-2d"], ["flow", "ellipse-2d"]):
        rc = cli.main([*verb, "--set", "mesh.n=50000", "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and err[0].startswith("vesicle-opt: error: mesh.n")
        assert not (tmp_path / "o").exists()  # refused before the output directory is made


def test_the_jax_array_adds_its_device_buffers():
    """solver.array = "jax": the numpy footprint plus the Newton-CG program's device buffers, a
    figure at least nk_jax's own (XLA's memory analysis, one device)."""
    pytest.importorskip("jax")
    from vesicle_opt.nk_jax.ops import memory_bytes_per_node
    sc = vo.load_scene("torus-table1-3d", ["mesh.kind='spectral'", "mesh.n=32", "solver.backend='newton-krylov'"])
    sj = vo.load_scene("torus-table1-3d", ["mesh.kind='spectral'", "mesh.n=32", "solver.backend='newton-krylov'",
                                           "solver.array='jax'"])
    extra = resources.bytes_per_node(sj, "newton-krylov") - resources.bytes_per_node(sc, "newton-krylov")
    assert extra == resources.JAX_DEVICE_BYTES_PER_NODE[3] >= memory_bytes_per_node(3, 1)


@pytest.mark.parametrize("sets", [[], ["model.epsilon=0.04", "mesh.band=8.0", "mesh.levels=4",
                                       "domain.box=[[0.0, 1.92], [-0.96, 0.96]]", "mesh.n=[6, 6]"]])
def test_an_interface_refined_mesh_is_estimated_from_its_band(sets):
    """mesh.n counts a refined meridian mesh's coarse cells only (648 of the bundled oblate's 10.5 k
    nodes): the estimate counts its band about the start shape, against the mesh built
    (``refine.band_mesh``): the bundled oblate (levels 2) and a 4-level band as the phase diagram's."""
    from vesicle_opt import mesh
    from vesicle_opt.mesh import refine

    sc = vo.load_scene("oblate-axisymmetric", sets)
    est, how = resources.estimate_bytes(sc, "ipopt")
    nodes = resources._nodes(sc)
    built = refine.band_mesh(sc.domain.box, sc.mesh.n, mesh.initial_distance(sc), sc.mesh.band * sc.model.epsilon,
                             sc.mesh.levels).p.shape[1]
    # a pointwise area of whole-triangle marking (plus green closures): measured 0.93-0.98 of the nodes
    assert 0.85 * built < nodes < 1.15 * built, (nodes, built)
    assert f"{nodes:.4g} nodes" in how and nodes > 10 * sc.mesh.n[0] * sc.mesh.n[1]
    coarse = est - (nodes - sc.mesh.n[0] * sc.mesh.n[1]) * resources.bytes_per_node(sc, "ipopt")
    limit = vo.load_scene("oblate-axisymmetric", sets + [f"solver.max_memory_gb={2 * coarse / resources.GB}"])
    with pytest.raises(InputError, match="mesh.n"):  # twice what mesh.n alone would need: refused
        resources.check(limit, "ipopt")
