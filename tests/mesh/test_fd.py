"""Discrete Laplacians of Definition 2.2: identities to round-off and observed convergence orders."""

import numpy as np
import pytest

from vesicle_opt import scene as S
from vesicle_opt.backends import SUPPORT
from vesicle_opt.errors import NotSupported
from vesicle_opt.flows.api import check_supported
from vesicle_opt.mesh import fd
from vesicle_opt.mesh import fem
from vesicle_opt.mesh.base import LUMPED, require_lumped
from vesicle_opt.nlp.exact import build_exact
from vesicle_opt.nlp.scp import scp

BOX2 = ((0.0, 2 * np.pi), (0.0, 2 * np.pi))


@pytest.mark.parametrize("box, n", [(BOX2, (8, 8)), (((0.0, 2.0), (0.0, 1.0)), (8, 6)),
                                    (((0.0, 1.0),) * 3, (5, 5, 5))])
def test_fd_equals_periodic_fem_lumped(box, n):
    """On tensor meshes of a periodic box P1 + lumping is the (2d+1)-point FD scheme (Section 2)."""
    a, b = fd.grid(box, n), fem.p1(box, n, periodic=True)
    assert np.allclose(a.nodes, b.nodes, atol=1e-12)
    # round-off of assembled entries of size 1/h^2 * h^d; measured 1e-15
    assert abs(a.K - b.K).max() < 1e-12 and np.abs(a.weights - b.weights).max() < 1e-14


def _smooth(nodes):
    x, y = nodes[:, 0], nodes[:, 1]
    return np.sin(x) * np.cos(2 * y), -5 * np.sin(x) * np.cos(2 * y)


@pytest.mark.parametrize("make", [
    lambda n: fd.grid(BOX2, (n, n)),
    lambda n: fem.p1(BOX2, (n, n), periodic=True, mass="lumped"),
    lambda n: fem.p1(BOX2, (n, n), periodic=True, mass="consistent"),
], ids=["fd", "fem-lumped", "fem-consistent"])
def test_laplacian_second_order(make):
    """max-norm error of Delta_h u at the nodes of a smooth periodic u decays at O(h^2)."""
    ns = [8, 16, 32, 64]
    errs = []
    for n in ns:
        d = make(n)
        u, lap = _smooth(d.nodes)
        errs.append(np.abs(d.apply_laplacian(u) - lap).max())
    order = -np.polyfit(np.log(ns), np.log(errs), 1)[0]
    assert order > 1.9, f"observed order {order:.3f}, errors {errs}"  # theory: 2 on uniform meshes


def test_consistent_lumped_fd_agree_as_h_to_zero():
    """The three Laplacians differ by O(h^2) on a smooth function."""
    diffs = []
    for n in (16, 32, 64):
        a = fd.grid(BOX2, (n, n))
        c = fem.p1(BOX2, (n, n), periodic=True, mass="consistent")
        u, _ = _smooth(a.nodes)
        diffs.append(np.abs(a.apply_laplacian(u) - c.apply_laplacian(u)).max())
    order = np.log2(diffs[0] / diffs[1]), np.log2(diffs[1] / diffs[2])
    assert min(order) > 1.9, f"orders {order}, differences {diffs}"  # both are O(h^2) accurate


def test_natural_boundary_stiffness_kills_constants_and_is_symmetric():
    d = fem.p1(((0.0, 1.0), (0.0, 2.0)), (6, 9), periodic=False)
    assert abs(d.K @ np.ones(d.n_nodes)).max() < 1e-12  # row sums vanish to round-off
    assert abs(d.K - d.K.T).max() < 1e-14
    assert np.isclose(d.volume, 2.0, rtol=1e-14)  # lumped weights integrate 1 exactly


# --- the one lumped-only guard (mesh.base.require_lumped) and its users ------------------------

def test_require_lumped_names_the_key_and_what_is_supported():
    require_lumped("a feature", "lumped", "nodal")  # the supported setting passes
    for mass, quad, key, supported in (("consistent", "nodal", "mesh.mass", "'lumped'"),
                                       ("lumped", "gauss", "mesh.quadrature", "'nodal'")):
        with pytest.raises(NotSupported) as info:
            require_lumped("a feature", mass, quad, "a reason")
        msg = str(info.value)
        assert info.value.key == key and msg.startswith(key) and supported in msg
        assert "a feature" in msg and "a reason" in msg and len(msg.splitlines()) == 1
    assert fd.grid(BOX2, (6, 6)).quadrature == "nodal"
    fd.grid(BOX2, (6, 6)).require_lumped("a feature")
    for kwargs, key in (({"mass": "consistent"}, "mesh.mass"), ({"quadrature": "gauss"}, "mesh.quadrature")):
        with pytest.raises(NotSupported, match=key):
            fem.p1(BOX2, (6, 6), periodic=True, **kwargs).require_lumped("a feature")


@pytest.mark.parametrize("sets, key", [(("mesh.mass='consistent'",), "mesh.mass"),
                                       (("mesh.quadrature='gauss'",), "mesh.quadrature")])
def test_every_lumped_only_feature_uses_the_guard(sets, key):
    """Flows (on the scene, before any work), the SCP baseline, and the backend table's entries."""
    sc = S.load("ellipse-2d", ["mesh.n=8", "mesh.kind='fem-p1'", *sets])
    with pytest.raises(NotSupported, match=key):
        check_supported(sc)
    with pytest.raises(NotSupported, match=key):
        scp(build_exact(sc, check=False))
    assert SUPPORT["newton-krylov"][key] == (LUMPED[key],)
