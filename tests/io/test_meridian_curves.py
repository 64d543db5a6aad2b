"""``io.meridian.meridian_curves`` on large meshes: its edge keys (i n + j) reach n^2, which wraps in
the int32 element arrays that scikit-fem's refinement returns above 46341 nodes (a KeyError(-1) at
the phase_diagram study's eps = 0.025, 48 k nodes)."""

import types

import numpy as np

from vesicle_opt.io.meridian import meridian_curves
from vesicle_opt.mesh import axisymmetric as ax


def test_one_curve_on_a_mesh_past_int32_keys():
    """A tanh sphere of radius 1.4 on a 48.5 k-node mesh with int32 elements (its equator through the
    last-numbered nodes, r > 1.36, whose keys pass 2^31): one open curve from the
    axis to the axis, every point at radius 1.4 to within the P1 interpolation's error (the profile's
    curvature over an edge of 0.0125: measured 2.0e-5)."""
    d = ax.p1(((0.0, 1.5), (-1.5, 1.5)), (120, 400))
    assert d.n_nodes > 46341  # (i n + j) > 2^31 for the last nodes
    mesh = types.SimpleNamespace(t=np.asarray(d.mesh.t, np.int32), p=d.mesh.p)
    phi = np.tanh((1.4 - np.hypot(*d.nodes.T)) / (np.sqrt(2) * 0.05))
    curves = meridian_curves(types.SimpleNamespace(mesh=mesh), phi)
    assert len(curves) == 1
    r, z = curves[0].T
    assert r[0] == 0 and r[-1] == 0 and np.abs(np.hypot(r, z) - 1.4).max() < 1e-4
