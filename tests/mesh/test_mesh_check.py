"""Mesh files checked before any work (``mesh.check``): each defect named under mesh.file with its
count, in one line; negatively oriented elements pass without a word (scikit-fem sorts each
element's vertices and assembles with |det J|: the P1 matrices are the same)."""

import meshio
import numpy as np
import pytest
import skfem

from vesicle_opt import load_scene, solve
from vesicle_opt.errors import InputError
from vesicle_opt.mesh import fem
from vesicle_opt.mesh.check import signed_measures

DISK = skfem.MeshTri.init_circle(3).scaled(3.0)


def _write(tmp_path, p, t, name="m.vtk"):
    path = tmp_path / name
    points = np.column_stack([p.T, np.zeros(p.shape[1])])
    meshio.write_points_cells(str(path), points, [("triangle", np.asarray(t).T)])
    return str(path)


def _p1(path):
    return fem.p1(((-3.0, 3.0), (-3.0, 3.0)), (8, 8), periodic=False, mesh_file=path)


def _orphan(p, t):
    return np.column_stack([p, [0.1, 0.2]]), t


def _zero_area(p, t):  # a triangle on one line: the two ends of an edge and its midpoint
    a, b = t[0, 0], t[1, 0]
    p2 = np.column_stack([p, 0.5 * (p[:, a] + p[:, b])])
    return p2, np.column_stack([t, [a, p.shape[1], b]])


def _duplicate(p, t):  # a vertex twice; one element uses the copy
    p2 = np.column_stack([p, p[:, t[0, 0]]])
    t2 = t.copy()
    t2[0, 0] = p.shape[1]
    return p2, t2


def _non_manifold(p, t):  # a third triangle on an inner edge, with a new apex
    a, b = t[0, 0], t[1, 0]
    p2 = np.column_stack([p, 0.5 * (p[:, a] + p[:, b]) + [0.05, 0.07]])
    return p2, np.column_stack([t, [a, b, p.shape[1]]])


def _two_pieces(p, t):
    return np.column_stack([p, p + [[10.0], [0.0]]]), np.column_stack([t, t + p.shape[1]])


@pytest.mark.parametrize("damage, words", [(_orphan, "1 vertices in no element"),
                                           (_zero_area, "1 elements of zero area"),
                                           (_duplicate, "1 duplicate nodes"),
                                           (_non_manifold, "1 non-manifold edges"),
                                           (_two_pieces, "2 disconnected pieces")])
def test_each_mesh_defect_is_named_with_its_count(tmp_path, damage, words):
    path = _write(tmp_path, *damage(DISK.p, DISK.t))
    with pytest.raises(InputError) as info:
        _p1(path)
    assert info.value.key == "mesh.file" and words in str(info.value) and "\n" not in str(info.value)


def test_an_orphan_vertex_is_refused_before_any_work_by_the_front_door(tmp_path):
    """Before: a matmul dimension-mismatch traceback from the solve."""
    path = _write(tmp_path, *_orphan(DISK.p, DISK.t))
    sc = load_scene("ellipse-2d", ["mesh.kind='fem-p1'", "domain.boundary='natural'", f"mesh.file='{path}'",
                                   "model.epsilon=0.25"])
    with pytest.raises(InputError, match="mesh.file.*1 vertices in no element"):
        solve(sc)


def test_reversed_elements_pass_silently_and_the_matrices_are_unchanged(tmp_path):
    t = DISK.t.copy()
    t[[0, 1], ::2] = t[[1, 0], ::2]  # every other triangle reversed
    assert (signed_measures(DISK.p, t) < 0).any() and (signed_measures(DISK.p, t) > 0).any()
    a, b = _p1(_write(tmp_path, DISK.p, DISK.t, "a.vtk")), _p1(_write(tmp_path, DISK.p, t, "b.vtk"))
    # the same sums of element matrices in the same order: equal to round-off (measured 0 or 1 ulp)
    for A, B in ((a.K, b.K), (a.M, b.M)):
        assert abs(A - B).max() <= 1e-14 * abs(A).max()
