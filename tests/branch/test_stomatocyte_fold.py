"""A fold in the reduced volume (c0 = 0) passed on the meridian mesh, from the stomatocyte's seed, by the
pseudo-arclength corrector with v free, on IPOPT (``branch.bordered``, each point certified by the
pinned fixed-v IPOPT solve) and on Newton-Krylov (``branch.nk_free``, GMRES on the bordered system,
each point certified as it stands), and both give the same fold.

The mesh: uniform, eps = 0.1, h = eps / 2 (4.2 k nodes), the study's box about the sharp stomatocyte
(``studies._meridian.layout``), the tanh profile of the sharp stomatocyte at v = 0.65 as the start.
At this eps the states are not stomatocytes: the cup's mouth closes (a shell round a pocket of outside
fluid) and the shell perforates into a torus before the fold (the last test); the fold is the discrete
problem's, which is what the correctors are tested on here. The stomatocyte's own fold (cups up to the
fold): docs/guide/bifurcation.md.
Before the axial pin (``branch.bordered.axial_pin``) this walk did not leave its start: the slide
between the natural walls is near-null, the warm IPOPT solves stalled (dv = 1e-2 ... 8e-5, every one at
its 6 iterations) and the bordered Newton's LU was singular (measured). Independent checks: the fold
is where v turns (the walk's own p), located on each backend from its own points (the vertex of
v(lambda), ``studies._stomatocyte.fold_of``), and the two backends' linear solvers (sparse LU on
IPOPT's Hessian, GMRES on the matrix-free one) share nothing but the discrete problem.
"""

import math

import numpy as np
import pytest

from vesicle_opt.branch.run import branch
from vesicle_opt.io.meridian import phase_field_of
from vesicle_opt.mesh import discretize
from vesicle_opt.scene import from_dict
from vesicle_opt.sharp import stomatocyte as sharp_s
from vesicle_opt.studies import _meridian
from vesicle_opt.studies._stomatocyte import fold_of

STEPS, NK_STEPS = 11, 7  # points of each walk: the fold passes at the 8th / 3rd, three or more on the far side
EPS, V0 = 0.1, 0.65  # the sharp seed below its fold (0.6604); the phase field's fold at this eps: 0.7064


def _scene(lay, v, start):
    raw = {"domain": {"box": lay["box"], "boundary": "natural"}, "mesh": lay["mesh"], "model": {"epsilon": EPS},
           "constraints": {"reduced_volume": v, "area": 4 * math.pi},
           "initial": {"shape": "file", "file": str(start)}, "solver": {"method": "exact"}}
    return from_dict(raw, name="stomatocyte-fold")


def _walk(b):
    pts = b.points(0)
    return [np.array([r[k] for r in pts], float) for k in ("target", "f", "dE_dp", "second_order_min_eigenvalue")]


NEAR = 0.705  # Newton-Krylov starts from the IPOPT walk's last point below this v (0.0017 below the fold)


@pytest.fixture(scope="module")
def walks(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fold")
    r, z = sharp_s.start_point(V0, 0.0, 24).meridian(2048)
    r2, z2 = sharp_s.start_point(0.66, 0.0, 24).meridian(2048)  # the box holds the shape near the fold too
    lay = _meridian.layout([(r, z), (r2, z2)], EPS, 2.0, refine=False)
    disc = discretize(_scene(lay, V0, tmp / "none.npz"))
    np.savez(tmp / "seed.npz", phi=phase_field_of(r, z, disc.nodes, EPS), nodes=disc.nodes)
    ip = branch(_scene(lay, V0, tmp / "seed.npz"), "reduced_volume", to=0.75, step=0.01, turn=2.0,
                switch=False, depth=0, max_points=STEPS, out=tmp / "ipopt")
    # Newton-Krylov from a certified IPOPT point below the fold (its field and its own v)
    pts = ip.points(0)
    top = int(np.argmax([r["target"] for r in pts]))
    row = [r for r in pts[:top] if r["target"] < NEAR][-1]  # the lower sheet
    np.savez(tmp / "near.npz", phi=ip.field(row["point"])["phi"], nodes=disc.nodes)
    nk = branch(_scene(lay, row["target"], tmp / "near.npz"), "reduced_volume", to=0.75, step=0.002,
                backend="newton-krylov", switch=False, depth=0, max_points=NK_STEPS, snapshots=False)
    return ip, nk


def _turns(b):
    """The walk's points certified, v rising to an interior maximum and falling after it (the fold
    passed); returns (v, f, lambda) of the points."""
    v, f, lam, _ = _walk(b)
    assert b.stopped[0] == "max_points" and all(r["converged"] for r in b.points(0))
    k = int(np.argmax(v))
    assert 0 < k <= len(v) - 3  # two points past the turn
    assert np.all(np.diff(v[:k + 1]) > 0) and np.all(np.diff(v[k:]) < 0)
    return v, f, lam


def _fold(b):
    rows = [r for r in b.located(0) if r["event"] == "fold"]
    assert len(rows) == 1 and rows[0]["converged"]
    return rows[0]["target"], rows[0]["f"]


def test_ipopt_passes_the_stomatocyte_fold(walks):
    ip, _ = walks
    _turns(ip)
    v_star, f_star = _fold(ip)
    # the phase field's fold lies above the sharp one (0.6604) at every eps (0.6657 at eps 0.04, the
    # study's fold_of): at eps 0.1 (measured 0.7064385, f 1.9249315) it is the turn of the walk's points
    assert max(_walk(ip)[0]) <= v_star < 0.71
    # before the fold one eigenvalue crossed zero with v still rising (located "branch point" at
    # v 0.69260, measured): every point from there on is a saddle, the fold adds the second
    assert [r["event"] for r in ip.located(0)] == ["branch point", "fold"]


SHELL, TORUS = "sphere-like (genus 0), enclosing 1 cavity", "genus 1 (torus-like)"


def test_the_eps01_walk_is_no_stomatocyte_and_its_branch_point_is_the_perforation(walks):
    """At eps = 0.1 the seed's cup does not stay a cup: its mouth (radius < eps) closes at once, so
    the walk's states are shells round a pocket of outside fluid (the revolved solid's topology,
    ``verify.topology``), and the branch point before the fold is where the shell's two polar layers
    (thinner than the interface) perforate: the inside leaves the axis and the solid becomes a
    torus. Measured: the axis's largest phi falls 0.51, 0.40, 0.29, 0.18, 0.06 from v 0.65 to 0.688,
    -0.06 at 0.6955; at the located branch point -0.001. So the fold this file passes is the
    discrete problem's, not the stomatocyte's (docs/guide/bifurcation.md)."""
    ip, _ = walks
    pts = ip.points(0)
    topo = [r["topology"] for r in pts]
    k = topo.index(TORUS)
    assert k > 0 and set(topo[:k]) == {SHELL} and set(topo[k:]) == {TORUS}  # one change, shell -> torus
    bp = [r for r in ip.located(0) if r["event"] == "branch point"][0]
    # the perforation between the last shell and the first torus, as the branch point is
    assert pts[k - 1]["target"] < bp["target"] < pts[k]["target"]
    assert pts[k - 1]["second_order_min_eigenvalue"] > 0 > pts[k]["second_order_min_eigenvalue"]


def test_newton_krylov_passes_the_same_fold(walks):
    ip, nk = walks
    v, f, lam = _turns(nk)
    assert all(r["krylov_iterations"] for r in nk.points(0))  # every point by the bordered GMRES Newton
    (v_ip, f_ip), (v_nk, f_nk) = _fold(ip), _fold(nk)
    # both located where the critical eigenvalue crosses zero on the chord (``branch.events``), v and f
    # stationary there; their agreement (measured 4.0e-10 in v, 5.6e-10 in f) is held to the resolution
    # of the fold by the NK walk's own points, the vertex of v(lambda) (``fold_of``: 1.7e-6 from both)
    vertex = fold_of(v, f, lam)
    assert vertex is not None
    res = max(abs(vertex[0] - v_nk), abs(vertex[1] - f_nk))
    assert res < 1e-5  # a parabola through points dv ~ 1e-4 apart near the vertex: O(dlambda^3)
    tol = max(res, 1e-8)  # 1e-8: the certificate's relative tolerance, below which two certified points
    assert abs(v_nk - v_ip) <= tol and abs(f_nk - f_ip) <= tol  # of one discrete problem are not told apart
