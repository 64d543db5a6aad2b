"""io.meridian on a meridian mesh of more than 46 341 nodes, where the edge keys i n + j pass 2^31
(scikit-fem's element indices are int32): a sphere's phi = 0 curve is one curve from the axis to the
axis (before the keys were int64 it raised KeyError: -1 at 90 k nodes, the c0 = 2.4 pear cases)."""

from __future__ import annotations

import types

import numpy as np

from vesicle_opt.io.meridian import meridian_curves
from vesicle_opt.mesh.refine import mirrored_tensor


def test_sphere_meridian_on_a_mesh_past_the_int32_keys():
    mesh = mirrored_tensor([[0.0, 1.0], [-1.0, 1.0]], [160, 320])  # 51 681 nodes: (n - 1) n > 2^31
    assert mesh.p.shape[1] ** 2 > 2**31 and mesh.t.dtype == np.int32
    r, z = mesh.p
    phi = 0.9 - np.hypot(r, z)  # through nodes r > 0.81: indices past 2^31 / n (numbered along r)
    curves = meridian_curves(types.SimpleNamespace(mesh=mesh), phi)
    assert len(curves) == 1
    c = curves[0]
    assert c[0][0] == 0.0 and c[-1][0] == 0.0  # from the axis to the axis
    # the P1 interpolant's zero line of the cone phi = 0.5 - rho: on the circle to O(h^2) (h = 1/160)
    assert np.abs(np.hypot(c[:, 0], c[:, 1]) - 0.9).max() < 1e-4
    assert len(c) > 500  # one point per cut edge along the half circle (measured ~1100)
