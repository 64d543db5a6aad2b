"""Recognition of a known branch on mirror (octant) grids: the exchange of axes of equal extent and
spacing (``branch.symmetry.align_mirror``), through ``VesicleProblem.align`` and ``switch.known``."""

from types import SimpleNamespace

import numpy as np

from vesicle_opt.branch import switch
from vesicle_opt.branch.events import Point
from vesicle_opt.branch.symmetry import align_mirror, exchanges
from vesicle_opt.branch.vesicle import VesicleProblem
from vesicle_opt.mesh import discretize
from vesicle_opt.scene.schema import from_dict

# an octant box square in y, z (as the prolate's: 50 x 20 x 20 at eps 0.2), longer in x
BOX, N = [[0.0, 3.0], [0.0, 1.5], [0.0, 1.5]], [16, 8, 8]


def _scene(box=BOX, n=N):
    raw = {"domain": {"box": box, "boundary": "natural"}, "mesh": {"kind": "spectral", "n": n},
           "model": {"epsilon": 0.3, "c0": 0.0}, "constraints": {"reduced_volume": 0.8, "area": 12.0},
           "initial": {"shape": "ellipsoid", "semi_axes": [1.6, 0.8, 0.8], "center": [0.0, 0.0, 0.0]},
           "solver": {"method": "exact", "tol": 1e-8}}
    return from_dict(raw, "octant")


def _field(disc, axes):
    """A smoothed ellipsoid centred at the corner with semi-axes ``axes`` (not symmetric in y, z)."""
    X = np.asarray(disc.nodes, float)
    r = np.sqrt(sum((X[:, i] / a) ** 2 for i, a in enumerate(axes)))
    return np.tanh((1.0 - r) / 0.2)


def test_a_field_and_its_y_z_exchange_are_one_branch_a_different_field_is_not():
    """On the square-based octant, phi(x, y, z) and phi(x, z, y) are images under the grid's exchange
    (the nodes map onto nodes: the image is a permutation of the values, so alignment is exact); an
    ellipsoid of other semi-axes is not brought onto it (its distance stays that of two shapes)."""
    sc = _scene()
    disc = discretize(sc)
    assert disc.grid_shape == (16, 8, 8) and exchanges(disc.grid_shape, disc.box) == [(0, 1, 2), (0, 2, 1)]
    a = _field(disc, (1.6, 0.9, 0.6))
    b = np.transpose(a.reshape(16, 8, 8), (0, 2, 1)).ravel()  # the y <-> z mirror image
    c = _field(disc, (1.4, 0.9, 0.75))  # another shape, not an image
    prob = SimpleNamespace(ipopt=None, scene=sc)
    w = disc.weights
    assert np.sqrt(w @ (b - a) ** 2) > 0.1 * np.sqrt(w @ a**2)  # the image differs before alignment
    assert np.abs(VesicleProblem.align(prob, b, a) - a).max() == 0.0  # a permutation of values: exact
    dc = np.sqrt(w @ (VesicleProblem.align(prob, c, a) - a) ** 2)
    assert dc == np.sqrt(w @ (c - a) ** 2) and dc > 0.05 * np.sqrt(w @ a**2)  # no exchange brings c closer
    # switch.known: a candidate on the exchanged image of branch 1 is branch 1, not the parent's
    pts = [Point(p, a + p * (c - a), 0.0, ()) for p in (0.0, 0.1)]
    parent = [Point(p, c + 0.3 + p, 0.0, ()) for p in (0.0, 0.1)]
    cand = Point(0.05, np.transpose((a + 0.05 * (c - a)).reshape(16, 8, 8), (0, 2, 1)).ravel(), 0.0, ())
    align = lambda phi, ref: VesicleProblem.align(prob, phi, ref)  # noqa: E731
    assert switch.known(cand, parent, {1: pts}, align, w, 1.0) == 1
    assert switch.known(cand, parent, {1: pts}, lambda phi, ref: phi, w, 1.0) is None  # plain distance: not


def test_no_exchange_where_extents_or_spacings_differ():
    """A box with y and z of different length (or node count) admits no exchange: the image stays apart."""
    for box, n in (([[0.0, 3.0], [0.0, 1.5], [0.0, 1.8]], N), (BOX, [16, 8, 10])):
        shape = tuple(n)
        assert exchanges(shape, box) == [(0, 1, 2)]
    a = np.random.default_rng(0).standard_normal(16 * 8 * 8)
    b = np.transpose(a.reshape(16, 8, 8), (0, 2, 1)).ravel()
    assert np.array_equal(align_mirror(b, a, (16, 8, 8), [[0.0, 3.0], [0.0, 1.5], [0.0, 1.8]]), b)
