"""An unstructured mesh read from a file (meshio): natural boundaries, a converged KKT point; the
P1 assembly's quadrature orders and chunks."""

import numpy as np
import pytest
import skfem
from skfem.models.poisson import laplace, mass

from vesicle_opt.mesh import fem

import vesicle_opt as S
from vesicle_opt.verify.certify import KKT_FACTOR
from vesicle_opt.errors import InputError
from vesicle_opt import load_scene



def test_solve_on_unstructured_mesh_file(tmp_path):
    mesh = skfem.MeshTri.init_circle(5).scaled(3.0)  # unstructured disk of radius 3
    path = tmp_path / "disk.vtk"
    mesh.save(str(path))
    sc = load_scene("ellipse-2d", ["mesh.kind='fem-p1'", "domain.boundary='natural'", f"mesh.file='{path}'", "mesh.n=8", "model.epsilon=0.25", "initial.semi_axes=[1.5, 1.0]", "constraints.target.semi_axes=[1.6, 0.9]"])
    res = S.solve(sc)
    assert res.converged, res.status
    assert res.n_nodes == mesh.p.shape[1]
    assert np.isfinite(res.energy) and res.kkt_residual <= KKT_FACTOR * 1e-8  # documented test


def test_corrupt_mesh_file_is_bad_input(tmp_path):
    path = tmp_path / "broken.vtk"
    path.write_text("not a mesh")
    try:
        S.solve(load_scene("ellipse-2d", ["mesh.kind='fem-p1'", "domain.boundary='natural'", f"mesh.file='{path}'"]))
    except InputError as exc:
        assert exc.key == "mesh.file" and "\n" not in str(exc)
    else:
        raise AssertionError("a corrupt mesh file was accepted")


def test_missing_mesh_file_is_bad_input(tmp_path):
    import pytest
    with pytest.raises(InputError) as info:
        S.solve(load_scene("ellipse-2d", ["mesh.kind='fem-p1'", "domain.boundary='natural'", f"mesh.file='{tmp_path / 'absent.msh'}'"]))
    assert info.value.key == "mesh.file"


@pytest.mark.parametrize("dim", [2, 3])
def test_lowest_exact_quadrature_gives_the_same_matrices(dim, monkeypatch):
    """P1 gradients are constant per element: the one-point rule gives the stiffness matrix of the
    order-2 rule exactly (max difference 0.0); the chunked assembly (here 7 elements per chunk)
    sums the same element matrices in another grouping: equal to round-off."""
    box, n = [(0.0, 1.0)] * dim, (5,) * dim
    mesh = fem._box_mesh(box, n)
    elem = skfem.ElementTriP1() if dim == 2 else skfem.ElementTetP1()
    whole = skfem.Basis(mesh, elem, intorder=2)
    K2, M2 = skfem.asm(laplace, whole).tocsr(), skfem.asm(mass, whole).tocsr()
    K1 = skfem.asm(laplace, skfem.Basis(mesh, elem, intorder=fem.STIFFNESS_ORDER)).tocsr()
    assert abs(K1 - K2).max() == 0.0
    monkeypatch.setattr(fem, "CHUNK", 7)
    Kc = fem._assemble(mesh, elem, laplace, fem.STIFFNESS_ORDER)
    Mc = fem._assemble(mesh, elem, mass, fem.MASS_ORDER)
    # sums of <= 24 element entries in another order: a few ulps of the largest entry
    assert abs(Kc - K2).max() <= 1e-14 * abs(K2).max() and abs(Mc - M2).max() <= 1e-14 * abs(M2).max()
    d = fem.p1(box, n, periodic=False)
    assert abs(d.K - Kc).max() <= 1e-14 * abs(K2).max() and abs(d.M - Mc).max() <= 1e-14 * abs(M2).max()
