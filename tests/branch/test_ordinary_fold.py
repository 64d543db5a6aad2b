"""``branch.ordinary_fold``: an ordinary fold continued in a second parameter, with another mode
negative on both of its sheets (as the pair of droplets' rotation below nu_c), on closed forms;
the vesicle's fold line against independent walks (slow)."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from vesicle_opt.branch import ordinary_fold as of
from vesicle_opt.branch.events import Point

sys.path.insert(0, str(Path(__file__).resolve().parent))

# an orthogonal mixing of the three coordinates: the fold's null vector on no axis of u
R, _ = np.linalg.qr(np.array([[2.0, 1.0, 0.5], [-1.0, 1.5, 1.0], [0.3, -0.7, 2.0]]))
ERR = 1e-6  # the toy's eigenvalue bound: the size the vesicle's check gives at its folds (1.3e-6 - 1.7e-6)


class Toy:
    """E(u; p, q) = e(R^T u), e(x, y, z) = f(x; p, q) + k(p, q) y^2/2 - z^2/2 (the branch y = z = 0):
    the z mode negative everywhere (the least eigenvalue never changes sign); the critical one f''
    (a fold) or k (a branch point). ``free(q)``: Newton on ``branch.bordered``'s system, p free."""

    def __init__(self, f, fx, fxx, fxp, k=lambda p, q: 1.0, kp=lambda p, q: 0.0):
        self.f, self.fx, self.fxx, self.fxp, self.k, self.kp = f, fx, fxx, fxp, k, kp
        self.weights, self.solves = np.ones(3), 0

    def free(self, q):
        def point(u_pred, p_pred, t_u, t_p, theta):
            self.solves += 1
            u, p = np.array(u_pred, float), float(p_pred)
            for _ in range(60):
                x, y, z = R.T @ u
                J = np.zeros((4, 4))
                J[:3, :3] = R @ np.diag([self.fxx(x, p, q), self.k(p, q), -1.0]) @ R.T
                J[:3, 3] = R @ np.array([self.fxp(x, p, q), self.kp(p, q) * y, 0.0])
                J[3, :3], J[3, 3] = theta**2 * t_u, t_p
                g = R @ np.array([self.fx(x, p, q), self.k(p, q) * y, -z])
                d = np.linalg.solve(J, -np.concatenate([g, [theta**2 * (u - u_pred) @ t_u + (p - p_pred) * t_p]]))
                u, p = u + d[:3], p + d[3]
                if np.abs(d).max() < 1e-14 * max(1.0, np.abs(u).max(), abs(p)):  # round-off of the solve
                    x, y, z = R.T @ u
                    mu = tuple(np.linalg.eigvalsh(R @ np.diag([self.fxx(x, p, q), self.k(p, q), -1.0]) @ R.T))
                    return Point(p, u, self.f(x, p, q) + self.k(p, q) * y**2 / 2 - z**2 / 2, mu, (ERR,) * 3)
            return None
        return point


def cusp():
    """f = x^4/4 - q x^2/2 - p x: p = x^3 - q x folds where 3x^2 = q, at x_f = sqrt(q/3),
    p_f(q) = -(2q/3) sqrt(q/3), E_f = q^2/12 (the sheets above p_f); no fold for q < 0 (the cusp)."""
    return Toy(lambda x, p, q: x**4 / 4 - q * x**2 / 2 - p * x, lambda x, p, q: x**3 - q * x - p,
               lambda x, p, q: 3 * x**2 - q, lambda x, p, q: -1.0)


def p_fold(q):
    return -(2 * q / 3) * math.sqrt(q / 3)


def start(q, half=0.2):
    xf = math.sqrt(q / 3)
    return R @ np.array([xf - half, 1.0, 0.0]), R @ np.array([xf + half, 1.0, 0.0])


def test_the_fold_line_of_the_cusp_is_its_closed_form():
    """Continued from q = 1 to 1.5, 2 and down to 0.5, 0.25: each fold p_f(q) to round-off, E_f =
    q^2/12, the critical eigenvalue the second (the z mode below it on both sheets) and zero to its
    bound, both sheets' points above p_f (the parameter turns), the parabola's vertex the same."""
    toy = cusp()
    a, b = start(1.0)
    folds = of.line(toy, 1.0, (a + b) / 2, p_fold(1.0) + 0.01, (b - a) / np.linalg.norm(b - a), 0.2,
                    [1.5, 2.0, 0.5, 0.25])
    assert [f.q for f in folds] == [1.0, 1.5, 2.0, 0.5, 0.25] and all(f.converged for f in folds)
    for f in folds:
        # |mu| <= 1e-6 puts x within mu / (2 sqrt(3q)) of x_f and p within sqrt(3q) (x - x_f)^2 <= 3e-13 of p_f
        assert abs(f.p - p_fold(f.q)) < 1e-12 and abs(f.energy - f.q**2 / 12) < 1e-12, (f.q, f.p, f.energy)
        assert f.critical == 1 and abs(f.eigenvalue) <= f.error and f.point.eigenvalues[0] == pytest.approx(-1.0)
        assert min(f.sheets) > f.p  # the sheets on one side of p_f: a turn
        # the parabola through s = -h_a, 0, h_b (s = x - x_f, h_a + h_b = 2h: the ends at sigma = -+h)
        # misses p = p_f + sqrt(3q) s^2 + s^3 by a vertex shift (h_a h_b)^2 / (4 (sqrt(3q) + h_b - h_a)),
        # at most h^4 / (4 (sqrt(3q) - 2h)) (measured: 0.06-1.0 of the symmetric ends' h^4 / (4 sqrt(3q)))
        h = f.chord[1]
        assert abs(f.vertex - f.p) <= h**4 / (4 * (math.sqrt(3 * f.q) - 2 * h)), (f.q, f.vertex, f.p)
    assert max(f.solves for f in folds) <= 2 + of.ev.MAX_LOCATE  # the bracket's two, then Illinois (5-9)


def test_past_the_cusp_the_line_ends_with_its_reason():
    """Below q = 0 there is no fold: the direction ends there, said why, with no p."""
    toy = cusp()
    a, b = start(0.5)
    folds = of.line(toy, 0.5, (a + b) / 2, p_fold(0.5), (b - a) / np.linalg.norm(b - a), 0.2, [0.1, -0.3, -0.5])
    assert [f.q for f in folds] == [0.5, 0.1, -0.3]  # -0.5 not tried after the failure
    assert all(f.converged for f in folds[:2]) and abs(folds[1].p - p_fold(0.1)) < 1e-12
    last = folds[-1]
    assert not last.converged and last.p is None and "no fold" in last.reason


def test_an_index_change_without_a_turn_is_not_a_fold():
    """f = (x - p)^2/2, k = p - 0.3: the branch x = p is monotone in p and k crosses zero at p = 0.3
    (a branch point): located there, refused as a fold (the sheets on both sides of it)."""
    toy = Toy(lambda x, p, q: (x - p) ** 2 / 2, lambda x, p, q: x - p, lambda x, p, q: 1.0,
              lambda x, p, q: -1.0, k=lambda p, q: p - 0.3, kp=lambda p, q: 1.0)
    a, b = R @ np.array([0.25, 0.0, 0.0]), R @ np.array([0.35, 0.0, 0.0])
    f = of.locate(toy, 0.0, (a + b) / 2, 0.3, (b - a) / np.linalg.norm(b - a), 0.05)
    assert not f.converged and f.p is None and "does not turn" in f.reason
    assert f.sheets == pytest.approx((0.25, 0.35), abs=1e-14)  # p = x on the hyperplanes x = 0.3 -+ 0.05


def _pair(nu):
    from test_run import raw_scene

    from vesicle_opt.scene.schema import from_dict
    raw = raw_scene(n=48, eps=0.4, second_order=True, initial={"shape": "ellipse", "semi_axes": [1.6, 0.9]})
    raw["constraints"]["reduced_volume"] = nu
    return from_dict(raw, "ellipse-c0")


@pytest.mark.slow
def test_the_pairs_fold_line_below_nu_c_agrees_with_an_independent_walk(tmp_path):
    """The 2D pair of droplets (FD 48^2, eps 0.4) walked in c0 at nu = 0.78: below nu_c ~ 0.802 its
    first fold is ordinary (the relative translation's eigenvalue crosses zero while the rotation's
    stays negative: index 1 -> 2), continued to nu = 0.77 against the walk at 0.77 (its own bracket,
    its own chord location) and the vertex of p(s) through that walk's three points round the turn
    (no eigenvalue). Measured: 0.7269758050166 vs 0.7269758050201 (chord), 0.7269733 (vertex)."""
    import csv

    from vesicle_opt.branch import branch
    from vesicle_opt.branch import events as ev
    from vesicle_opt.branch.ordinary_fold_vesicle import from_branch
    walks = {nu: branch(_pair(nu), "c0", to=2.5, step=0.1, max_points=45, switch=False, out=tmp_path / f"{nu}")
             for nu in (0.78, 0.77)}
    folds = from_branch(walks[0.78], "reduced_volume", [0.77])  # auto: the walk's fold was on the chord
    assert [f.q for f in folds] == [0.78, 0.77] and all(f.converged and f.kind == "ordinary" for f in folds)
    rows = list(csv.DictReader(open(tmp_path / "0.78" / "fold_line.csv")))
    assert [r["fold_kind"] for r in rows] == ["ordinary"] * 2 and [r["located_by"] for r in rows] == ["chord"] * 2
    for f in folds:
        assert abs(f.eigenvalue) <= f.error < 5e-6  # zero to its bound (measured |mu| 1e-8..1.5e-7, bounds 1.6e-6)
        assert f.critical == 1 and f.point.eigenvalues[0] < -100 * f.point.errors[0]  # the rotation, negative
        assert max(f.sheets) < f.p  # both sheets' points below the fold: the parameter turns
        # the vertex of p(sigma) through the two sheets' points and the fold: O(h^3) of the ends
        # (measured 1.5e-8, 8.6e-8); 1e-5 is the walk's own vertex error below
        assert abs(f.vertex - f.p) < 1e-5
    # the mode below the critical one is the pair's rotation x d_y phi - y d_x phi, the critical one is
    # not (measured overlaps 0.9997 and 6.5e-7 at nu = 0.78; the next modes are of other parity)
    from vesicle_opt.branch.params import parameter
    from vesicle_opt.mesh import discretize
    from vesicle_opt.mesh.spectral import FourierGrid
    from vesicle_opt.nk.setup import prepare
    from vesicle_opt.verify import lobpcg
    from vesicle_opt.verify import verdict as V
    sc = parameter(_pair(0.78), "c0").scene_at(_pair(0.78), folds[0].p)
    _, _, vec = lobpcg.reduced_hessian_eigenvalues(sc, folds[0].point.payload, prepare(sc, None), k=3,
                                                   rotations=V.excludes_rotations(sc), vectors=True)
    disc = discretize(sc)
    dx, dy = FourierGrid(disc.box, tuple(disc.grid_shape)).derivatives(folds[0].point.phi)
    x = np.asarray(disc.nodes)
    rot = x[:, 0] * dy - x[:, 1] * dx
    overlap = [abs(vec[:, m] @ rot) / np.linalg.norm(vec[:, m]) / np.linalg.norm(rot) for m in (0, 1)]
    assert overlap[0] > 0.99 and overlap[1] < 1e-3, overlap
    other = walks[0.77]
    chord = [r for r in other.located(0) if r["event"] == "fold"][0]
    assert chord["located_by"] == "chord"
    # two locations to the eigenvalue's bound: p - p_f ~ (mu / mu')^2, ~1e-11 (measured 3.5e-12)
    assert abs(folds[1].p - chord["target"]) < 1e-9, (folds[1].p, chord["target"])
    pts = [ev.Point(r["target"], other.field(r["point"])["phi"], r["energy"], ()) for r in other.points(0)]
    k = ev.turns(pts)[0]
    vx = ev.locate_fold_parabola(pts[k - 1:k + 2], np.full(pts[0].phi.size, (8 / 48) ** 2), 1.0)
    # the walked points' vertex is O(ds^3) of the walk's steps: measured 2.5e-6 here, 3.3e-6 and 6.4e-6 at 0.78, 0.76
    assert abs(folds[1].p - vx.p) < 2e-5, (folds[1].p, vx.p)


def test_auto_picks_the_method_by_how_the_walk_located_its_fold(monkeypatch, tmp_path):
    """auto: a fold the walk located on the chord (an index change) is continued as ordinary, a turn
    it saw with no index change (parabola) as symmetric; ordinary asked for with no chord fold is no
    line; a kind the scene cannot run is refused before any work."""
    from types import SimpleNamespace

    from vesicle_opt.branch import ordinary_fold_vesicle as ofv
    from vesicle_opt.errors import InputError
    calls = []
    monkeypatch.setattr(ofv.sf, "from_branch", lambda b, *a, **k: calls.append("symmetric") or ["s"])
    monkeypatch.setattr(ofv, "line", lambda *a, **k: calls.append("ordinary") or [])
    monkeypatch.setattr(ofv, "_ordinary_start", lambda b, row: ({"point": 0}, {"point": 1}))

    def run(located_by, kind, scene=None):
        rows = [{"event": "branch point", "located_by": "illinois"}, {"event": "fold", "located_by": located_by,
                                                                       "target": 0.73, "detected_at": 1}]
        b = SimpleNamespace(scene=scene or _pair(0.8), param="c0", out=tmp_path, located=lambda k: rows,
                            field=lambda k: {"phi": np.zeros(3)})
        calls.clear()
        out = ofv.from_branch(b, "reduced_volume", [0.79], kind=kind)
        return calls[:], out
    assert run("chord", "auto")[0] == ["ordinary"]
    assert run("parabola", "auto")[0] == ["symmetric"]
    assert run("chord", "symmetric")[0] == ["symmetric"]
    assert run("parabola", "ordinary") == ([], [])
    # a 3D grid has no symmetric turn's line (2D only): auto continues the chord's fold as ordinary,
    # a turn no more; a spectral grid has no IPOPT (the bordered corrector): auto goes symmetric
    cube = _grid(dim=3)
    assert run("chord", "auto", cube)[0] == ["ordinary"] and run("parabola", "auto", cube) == ([], [])
    with pytest.raises(InputError, match="mesh.kind"):
        run("chord", "symmetric", cube)
    spectral = _grid(kind="spectral")
    assert run("chord", "auto", spectral)[0] == ["symmetric"]
    with pytest.raises(InputError, match="backend"):
        run("chord", "ordinary", spectral)
    with pytest.raises(InputError, match="--fold-kind"):
        run("chord", "both")


def _grid(dim=2, kind="fd"):
    from test_run import raw_scene

    from vesicle_opt.scene.schema import from_dict
    raw = raw_scene(n=16, eps=0.8, second_order=True, initial={"shape": "ellipse", "semi_axes": [1.6, 0.9]})
    raw["mesh"]["kind"] = kind
    if dim == 3:
        raw["domain"]["box"] = [[-4.0, 4.0]] * 3
        raw["initial"] = {"shape": "ellipsoid", "semi_axes": [1.6, 0.9, 0.9]}
        raw["constraints"]["area"] = 20.0
    return from_dict(raw, "grid")
