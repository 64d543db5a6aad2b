"""Topology report on closed-form shapes: disk, annulus, ball, solid torus, slab, two bodies."""

import numpy as np
import pytest

from vesicle_opt.mesh import fd
from vesicle_opt.mesh import fem
from vesicle_opt.verify import topology
from vesicle_opt.scene.shape_spec import Shape
from vesicle_opt.scene.shapes import phase_field

BOX2 = ((-2.0, 2.0), (-2.0, 2.0))
BOX3 = ((-2.0, 2.0),) * 3


def _grid(box, n, f):
    d = fd.grid(box, (n,) * len(box))
    return d, f(d.nodes)


@pytest.mark.parametrize("dim, field, expected", [
    (2, lambda x: 1 - np.hypot(*x.T), (1, 1, ())),  # disk
    (2, lambda x: 0.3 - np.abs(np.hypot(*x.T) - 1), (1, 0, ())),  # annulus
    (2, lambda x: 0.5 - np.abs(x[:, 1]), (1, 0, (0,))),  # band across the box along x
    (2, lambda x: 0.5 - np.minimum(np.hypot(x[:, 0] - 1, x[:, 1]), np.hypot(x[:, 0] + 1, x[:, 1])), (2, 2, ())),
    (3, lambda x: 1 - np.linalg.norm(x, axis=1), (1, 1, ())),  # ball
    (3, lambda x: 0.4 - np.hypot(np.hypot(x[:, 0], x[:, 1]) - 1.2, x[:, 2]), (1, 0, ())),  # solid torus
    (3, lambda x: 0.5 - np.abs(x[:, 2]), (1, 0, (0, 1))),  # slab: wraps along x and y
    # a ball across the periodic face x = -2 = 2: inside cells on both x faces, one ball, no wrap
    (3, lambda x: 1 - np.minimum(np.linalg.norm(x - [-2, 0, 0], axis=1), np.linalg.norm(x - [2, 0, 0], axis=1)),
     (1, 1, ())),
])
def test_grid_topology(dim, field, expected):
    box = BOX2 if dim == 2 else BOX3
    d, phi = _grid(box, 32 if dim == 2 else 24, field)
    t = topology.analyse(d, phi)
    assert (t.components, t.euler_characteristic, t.wraps) == expected


def test_torus_phase_field_reads_as_genus_one():
    d = fd.grid(BOX3, (24, 24, 24))
    phi = phase_field(Shape("torus", radii=(1.2, 0.45)), d.nodes, d.box, 0.1)
    assert topology.analyse(d, phi).describe(3) == "genus 1 (torus-like)"


def test_unstructured_mesh_counts_components():
    d = fem.p1(BOX2, (16, 16), periodic=False)  # natural boundaries: no grid ordering, graph path
    phi = 0.5 - np.minimum(np.hypot(d.nodes[:, 0] - 1, d.nodes[:, 1]), np.hypot(d.nodes[:, 0] + 1, d.nodes[:, 1]))
    t = topology.analyse(d, phi)
    assert t.components == 2 and t.euler_characteristic is None


def test_hollow_ball_is_genus_zero_with_a_cavity():
    """chi = 2 for a ball with an enclosed pocket: genus 0, one cavity (not 'genus -1')."""
    d, phi = _grid(BOX3, 24, lambda x: 0.4 - np.abs(np.linalg.norm(x, axis=1) - 1.2))
    t = topology.analyse(d, phi)
    assert (t.components, t.euler_characteristic, t.cavities) == (1, 2, 1)
    assert t.describe(3) == "sphere-like (genus 0), enclosing 1 cavity"


@pytest.mark.parametrize("name, field, expected", [
    # (r, z) -> phi on the meridian half-plane; expected (components, chi, cavities, words) of the solid
    ("ball", lambda r, z: 1 - np.hypot(r, z), (1, 1, 0, "sphere-like (genus 0)")),
    ("solid torus", lambda r, z: 0.4 - np.hypot(r - 1.0, z), (1, 0, 0, "genus 1 (torus-like)")),
    ("hollow ball", lambda r, z: 0.4 - np.abs(np.hypot(r, z) - 1.2), (1, 2, 1, "sphere-like (genus 0), enclosing 1 cavity")),
    # a cup: the hollow ball with its mouth open (the shell cut away above z = 0.7 within r < 0.5)
    ("cup", lambda r, z: np.minimum(0.4 - np.abs(np.hypot(r, z) - 1.2), np.maximum(r - 0.5, 0.7 - z)),
     (1, 1, 0, "sphere-like (genus 0)")),
    ("two balls on the axis", lambda r, z: 0.5 - np.minimum(np.hypot(r, z - 1), np.hypot(r, z + 1)),
     (2, 2, 0, "2 components")),
])
def test_meridian_topology_is_the_solid_of_revolutions(name, field, expected):
    """On the meridian half-plane (``mesh.axisymmetric``) the topology is that of the revolved solid,
    against the closed forms: chi = the inside's intervals on the axis, cavities = the outside's
    components beyond the exterior (a pocket on the axis revolves to one cavity)."""
    from vesicle_opt.mesh import axisymmetric as ax

    d = ax.p1(((0.0, 2.0), (-2.0, 2.0)), (40, 80))
    phi = field(d.nodes[:, 0], d.nodes[:, 1])
    t = topology.analyse(d, phi)
    assert (t.components, t.euler_characteristic, t.cavities, t.describe(3)) == expected
