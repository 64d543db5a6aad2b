"""An unstructured mesh read from a file (meshio): natural boundaries, a converged KKT point."""

import numpy as np
import skfem

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
