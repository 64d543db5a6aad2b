"""Mirror grids (spectral + natural: one octant) are written and drawn as the whole vesicle: the
VTK image of the reflected field on the doubled box, the phi = 0 surface of the whole vesicle
(closed, its area and volume the sphere's), the PNG cuts and the branch insets through its centre."""

import math

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt.io import fields, output, surface, vtk
from vesicle_opt.mesh import discretize

R, EPS = 1.0, 0.15


def _octant(dim: int = 3, n: int = 20):
    box = [[0.0, 2.0]] * dim
    sc = vo.scene.from_dict({"domain": {"box": box, "boundary": "natural"},
                             "mesh": {"kind": "spectral", "n": n}, "model": {"epsilon": EPS},
                             "constraints": {"alpha": 0.0, "beta": 1.0},
                             "initial": {"shape": "circle" if dim == 2 else "sphere", "radius": R,
                                         "center": [0.0] * dim}})
    disc = discretize(sc)
    r = np.linalg.norm(disc.nodes, axis=1)
    return disc, np.tanh((R - r) / (math.sqrt(2) * EPS))  # the sphere at the corner: one octant of it


def test_surface_is_the_whole_closed_sphere():
    disc, phi = _octant()
    s = surface.zero_surface(disc, phi)
    assert s.closed  # the octant alone is an open patch (area rel diff -0.75 before)
    # marching cubes at h = 0.1 on a sphere of radius 1: area and volume within 1% (O(h^2) facets)
    assert s.area == pytest.approx(4 * math.pi * R**2, rel=1e-2)
    assert s.volume == pytest.approx(4 / 3 * math.pi * R**3, rel=1e-2)
    lo = s.vertices.min(axis=0)
    assert np.all(lo < -0.9 * R)  # it extends to the mirror side


def test_vti_holds_the_reflected_field_on_the_doubled_box(tmp_path):
    disc, phi = _octant()
    vtk.write_vti(tmp_path / "phi.vti", disc, {"phi": phi})
    data, origin, spacing = vtk.read_vti(tmp_path / "phi.vti")
    F = data["phi"]
    assert F.shape == (41, 41, 41)  # 2 n + 1: the doubled box, completed periodically
    np.testing.assert_allclose(origin, -2.0 + 0.05, rtol=0, atol=1e-15)  # 2 lo - hi + h/2
    # the written points are the cell centres of the doubled box: phi there is the sphere's tanh
    axes = [origin[d] + spacing[d] * np.arange(41) for d in range(3)]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    exact = np.tanh((R - np.linalg.norm(X, axis=-1)) / (math.sqrt(2) * EPS))
    np.testing.assert_allclose(F[:-1, :-1, :-1], exact[:-1, :-1, :-1], rtol=0, atol=1e-14)  # round-off


def test_png_cuts_pass_through_the_vesicle_centre():
    disc, phi = _octant()
    spec = output.figure_spec(disc, phi)
    for cut, label in zip(spec["cuts"], spec["labels"]):
        assert cut.shape == (40, 40) and cut.max() > 0.9 and cut.min() < -0.9  # inside and outside seen
        assert abs(float(label.split("=")[1])) < 0.1  # the cut plane at the centre (h/2 off)
    img = output.figure_spec(*_octant(dim=2))
    assert img["field"].shape == (40, 40) and img["lo"][0] == pytest.approx(-1.95)


def test_npz_records_the_mirror_cells(tmp_path):
    disc, phi = _octant()
    fields.write(tmp_path / "p.npz", "branch-point", phi, disc, p=0.7)
    snap = fields.read(tmp_path / "p.npz")
    assert snap["mirror_cells"] == 8
    from vesicle_opt.branch.diagram import _cut
    section, box = _cut(snap)
    assert section.shape == (40, 40) and section.max() > 0.9  # the inset cuts the vesicle
    np.testing.assert_allclose(box, [[-2.0, 2.0], [-2.0, 2.0]])


@pytest.mark.parametrize("dim, xlabel, ylabel", [(2, "reduced area", "E / E_circle"), (3, "reduced volume", "E / E_sphere")])
def test_diagram_labels_follow_the_dimension(tmp_path, monkeypatch, dim, xlabel, ylabel):
    from vesicle_opt.branch import diagram
    figs = []
    monkeypatch.setattr(diagram.plt, "close", figs.append)  # keep the figure to read its labels
    rows = [{"target": v, "reduced_energy": e, "second_order_min_eigenvalue": m, "point": k}
            for k, (v, e, m) in enumerate([(0.9, 1.2, 0.1), (0.85, 1.4, 0.1), (0.8, 1.7, -0.1)])]
    diagram.plot([("branch", rows, None)], tmp_path / "d.png", dim=dim)
    ax = figs[0].axes[0]
    assert ax.get_xlabel() == xlabel and ylabel in ax.get_ylabel()
    styles = [ln.get_linestyle() for ln in ax.get_lines() if len(ln.get_xdata()) == 2]
    assert styles == ["-", "--"]  # stable segment solid, the one into the saddle dashed
