"""The tree of branches on closed forms (``tests/branch/toy.py``): a pitchfork, a fold and two
branch points joined by a ring are detected, located, classified and switched; a branch landing on
a known one is not walked twice; deflation finds the other root; a diagram cut after any row
resumes to the same rows."""

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from vesicle_opt.branch import deflation, events, tree
from vesicle_opt.branch.store import COLUMNS

sys.path.insert(0, str(Path(__file__).parent))
from toy import Toy  # noqa: E402


def located(t, kind=None):
    return [r for r in t.rows() if r["corrector"] == "locate" and (kind is None or r["event"] == kind)]


def test_pitchfork_is_located_and_both_sides_switched_one_walked():
    """E = x^4/4 - p x^2/2: the branch point p = 0 located from a bracket of width 0.14; the
    branch leaving it is x^2 = p, stable; the other direction is its mirror image (x -> -x)."""
    t = Toy("pitchfork", -0.5, 0.5, 0.1, np.array([0.0, 1.0]))
    nodes = tree.grow(t, depth=1)
    (bp,) = located(t)
    assert bp["event"] == events.BRANCH_POINT and bp["located_by"] == "illinois"
    assert abs(bp["target"]) < 1e-4 * 0.1  # P_TOL of the step (the bracket's end condition)
    assert abs(bp["critical_eigenvalue"]) < 1e-4 * 0.1  # g = -p on the trivial branch: the same
    assert nodes[1].parent == 0 and nodes[1].stopped == "reached"
    assert nodes[2].stopped == "known: branch 1"
    new = t.points(1)[2:]  # after its branch point and the switched point
    x, p = np.array([q.phi[0] for q in new]), np.array([q.p for q in new])
    assert np.abs(x**2 - p).max() < 1e-12  # Newton to 1e-13 on the closed form x^2 = p
    assert all(q.index == 0 for q in new)  # the bifurcated branch is stable (H = 2p > 0)
    assert new[-1].p == 0.5


def test_without_symmetry_the_mirror_branch_is_walked():
    t = Toy("pitchfork", -0.5, 0.5, 0.1, np.array([0.0, 1.0]), symmetric=False)
    nodes = tree.grow(t, depth=1)
    assert nodes[2].stopped == "reached"
    assert np.allclose([q.phi[0] for q in t.points(2)[2:]], [-math.sqrt(q.p) for q in t.points(2)[2:]], atol=1e-12)


def test_no_switch_and_depth_zero_walk_the_root_only():
    for kw in ({"switch": False}, {"depth": 0}):
        t = Toy("pitchfork", -0.5, 0.5, 0.1, np.array([0.0, 1.0]))
        assert list(tree.grow(t, **kw)) == [0] and len(located(t)) == 1


def test_fold_is_passed_located_on_the_chord_and_not_switched():
    """E = x^3/3 - p x: from x = 1 towards p = -0.5 the branch turns at p = 0 (x = 0, the least
    eigenvalue 2x crosses zero there) and comes back on x = -sqrt(p), unstable."""
    t = Toy("fold", 1.0, -0.5, -0.1, np.array([1.0, 1.0]), max_points=40)
    nodes = tree.grow(t, depth=3)
    (f,) = located(t)
    assert f["event"] == events.FOLD and f["located_by"] == "chord" and list(nodes) == [0]
    assert abs(f["target"]) < 1e-8  # p = x^2 at the located point, x ~ tau_tol * chord ~ 1e-4
    assert abs(f["critical_eigenvalue"]) < 1e-4  # 2x, the chord located to TAU_TOL
    assert nodes[0].stopped.startswith("left the range")
    assert t.points(0)[-1].index == 1  # the returning sheet: a saddle


def test_ring_the_second_branch_point_lands_on_the_known_branch():
    """E = x^4/4 + (p^2 - 1) x^2/2: branch points at p = -1, +1 joined by the circle x^2 + p^2 = 1.
    The circle is walked once (from p = -1 to the branch point at +1, which it joins); the three
    other switches land on it."""
    t = Toy("ring", -2.0, 2.0, 0.15, np.array([0.0, 1.0]))
    nodes = tree.grow(t, depth=2)
    bps = located(t, events.BRANCH_POINT)
    assert [round(r["target"], 5) for r in bps] == [-1.0, 1.0]
    assert all(abs(abs(r["target"]) - 1) < 1e-4 * 0.15 for r in bps)  # P_TOL of the step
    walked = [k for k, n in nodes.items() if not n.stopped.startswith("known")]
    assert walked == [0, 1] and nodes[1].stopped.startswith(f"joined branch point at point {bps[1]['point']}")
    ring = t.points(1)[1:]
    assert np.abs([q.phi[0] ** 2 + q.p**2 - 1 for q in ring]).max() < 1e-12  # the circle, to Newton's tol
    assert sum(n.stopped == "known: branch 1" for n in nodes.values()) == 3


def test_deflation_finds_the_other_root():
    """grad E = x^2 - 1 (E = x^3/3 - x): from x = 1.5 Newton goes to the known root 1; deflated by
    it, to -1 (Farrell et al.'s scaled step)."""
    F = lambda u: np.array([u[0] ** 2 - 1])  # noqa: E731
    J = lambda u: np.array([[2 * u[0]]])  # noqa: E731
    u, ok, _ = deflation.newton(F, J, np.array([1.5]), [], np.ones(1))
    assert ok and abs(u[0] - 1) < 1e-12
    u, ok, steps = deflation.newton(F, J, np.array([1.5]), [np.array([1.0])], np.ones(1))
    assert ok and abs(u[0] + 1) < 1e-12, (u, steps)


def test_deflation_is_the_trees_fallback():
    """The fold problem has no branch point: with deflate=1 the tree deflates the start (x = 1 at
    p = 1) and walks the other root, x = -1, as a new root branch."""
    t = Toy("fold", 1.0, 0.5, -0.1, np.array([1.0, 1.0]))
    nodes = tree.grow(t, deflate=1)
    assert nodes[1].parent is None and nodes[1].stopped == "reached"
    pts = t.points(1)
    assert abs(pts[0].phi[0] + 1) < 1e-12 and pts[0].index == 1  # the unstable root -sqrt(p)
    assert np.abs([q.phi[0] + math.sqrt(q.p) for q in pts]).max() < 1e-12


@pytest.mark.parametrize("name, args, depth", [
    pytest.param("ring", (-2.0, 2.0, 0.15, np.array([0.0, 1.0])), 2, marks=pytest.mark.slow),  # ~15 s: 20 cuts
    ("pitchfork", (-0.5, 0.5, 0.1, np.array([0.0, 1.0])), 1),
])
def test_a_diagram_cut_after_any_row_resumes_to_the_same_rows(tmp_path, name, args, depth):
    """The CSV cut after each row in turn (a kill), then resumed: the same rows, none lost or twice."""
    full = Toy(name, *args, out=tmp_path / "full")
    tree.grow(full, depth=depth)
    ref = (tmp_path / "full" / "branch.csv").read_text().splitlines()
    col = COLUMNS.index("corrector")  # every tree row (locate, branch point, switch) and every 9th walk row
    cuts = [n for n in range(2, len(ref)) if n % 9 == 0 or ref[n].split(",")[col] in ("locate", "branch point", "switch")]
    for n in cuts:
        d = tmp_path / f"cut{n}"
        Toy(name, *args, out=d)  # the directory, its meta
        (d / "points").mkdir(exist_ok=True)
        for f in (tmp_path / "full" / "points").iterdir():
            (d / "points" / f.name).write_bytes(f.read_bytes())
        (d / "branch.csv").write_text("\n".join(ref[:n]) + "\n" + ref[n][: len(ref[n]) // 2])  # a torn line
        t = Toy(name, *args, out=d)
        tree.grow(t, depth=depth)
        got = (d / "branch.csv").read_text().splitlines()

        def strip(lines):
            return [",".join(x for i, x in enumerate(line.split(",")) if i != WALL) for line in lines]
        assert strip(got) == strip(ref), n


WALL = COLUMNS.index("wall_time_s")


def test_a_mode_within_its_bound_of_zero_is_passed_over():
    """Two far components have a soft relative translation (measured on a deflated 2D branch:
    -1e-3 ... +5e-5 mu_ref, bound ~2e-3). It is certified negative (index 2 -> 1: a Ritz value below
    -TOL_REL) but not decidedly (the events' count 1 -> 0), and the location follows the eigenvalue
    that crosses, g(p) = p - 0.3, not the soft one, sorted first near the root."""
    def point(p):
        eig = sorted([p - 0.3, -8e-4])
        err = [2e-3 if mu == -8e-4 else 1e-9 for mu in eig]
        return events.Point(p, np.zeros(2), 0.0, tuple(eig), tuple(err))
    a, b = point(0.0), point(0.6)
    assert (a.decided, b.decided) == (1, 0) and (a.index, b.index) == (2, 1)
    assert events.critical_values(a, b) == (-0.3, pytest.approx(0.3))
    loc = events.locate_branch_point(lambda p, phi, lam: point(p), a, b, 1e-9)
    assert abs(loc.p - 0.3) <= 1e-9 and loc.located_by == "illinois"  # |g| <= its bound 1e-9 or the bracket
    assert loc.eigenvalue == pytest.approx(loc.p - 0.3, abs=0)


def test_the_index_is_the_verdicts_count_and_the_decided_count_within_it():
    """The CSV's index counts what the certificate calls negative: for a point's least eigenvalue,
    index >= 1 exactly where ``verdict.classify`` reads "saddle" (a Ritz value bounds its eigenvalue
    from above, so one below -TOL_REL is negative whatever its bound: the matrix-free check stops once
    a saddle is decided, bounds 0.05-0.3 against mu -3e-4 ... -6e-3 on the meridian cup past its
    fold, measured), 0 where it reads "minimum"; the events' decided count is at most the index and
    needs mu < -err as well; ``events.sign`` (the walk's "stability change") is the verdict's. Ritz values
    and bounds on both sides of every threshold."""
    from vesicle_opt.verify.verdict import TOL_REL, classify
    mus = [-0.3, -6e-3, -2.7e-4, -2e-6, -TOL_REL, -5e-7, 0.0, 5e-7, TOL_REL, 2e-6, 8e-4, 0.2]
    errs = [0.0, 1e-11, 1e-7, TOL_REL, 6.6e-6, 0.055, 0.3, float("nan"), float("inf")]
    for mu in mus:
        for err in errs:
            verdict = classify(mu, err)[0]
            i, d = events.index((mu, 0.5), (err, 0.0)), events.decided((mu, 0.5), (err, 0.0))
            assert (i == 1) == (verdict == "saddle") and i in (0, 1), (mu, err, verdict, i)
            finite = err == err and abs(err) < float("inf")
            assert d <= i and d == (1 if finite and mu < -max(err, TOL_REL) else 0), (mu, err, d)
            assert verdict != "minimum" or i == 0
            assert events.sign(mu, err) == {"saddle": -1, "minimum": 1}.get(verdict, 0), (mu, err, verdict)


def test_an_end_undecided_within_tol_rel_of_the_other_sign_is_located_past_it():
    """g(p) = 0.65 (p - p*), bound 2e-11 (the symmetric fold line's odd eigenvalue, measured). The end
    b sits 8e-10 below p*: g(b) = -5.2e-10, within ``TOL_REL`` so index 0, yet of a's sign. The zero is
    found one secant step past b, to g's own bound (not to TOL_REL: a location stopped at |g| <= 1e-6
    would be 1.5e-6 off in p); bisecting towards b, as before, left a 1.2e-7 bracket after 12 solves."""
    p_star, slope, bound = 0.7376034, 0.65, 2e-11

    def point(p):
        return events.Point(p, np.zeros(2), 0.0, (slope * (p - p_star),), (bound,))
    a, b = point(p_star - 1e-3), point(p_star - 8e-10)
    assert (a.index, b.index) == (1, 0) and events.critical_values(a, b)[1] < 0
    loc = events.locate_branch_point(lambda p, phi, lam: point(p), a, b, 1e-7)
    assert loc.solves <= 3 and abs(loc.eigenvalue) <= loc.error == bound  # its own bound, not TOL_REL
    assert abs(loc.p - p_star) <= 2 * bound / slope  # g's bound over its slope (+ round-off of p)


def test_align_undoes_a_grid_rotation_and_a_translation():
    """A field rotated by 90 degrees, reflected and shifted on a periodic square grid is brought
    back exactly (grid symmetries: the image is a permutation of the values); a rectangle's grid
    has no axis exchange, so there the rotated field is not matched."""
    from vesicle_opt.branch.symmetry import align
    x = np.linspace(0, 1, 16, endpoint=False)
    X, Y = np.meshgrid(x, x, indexing="ij")
    a = np.exp(-10 * (X - 0.3) ** 2 - 40 * (Y - 0.6) ** 2)
    b = np.roll(np.rot90(a)[::-1], (3, 5), axis=(0, 1))
    assert np.abs(align(b.ravel(), a.ravel(), (16, 16), [[0, 1], [0, 1]]) - a.ravel()).max() == 0.0
    assert np.abs(align(b.ravel(), a.ravel(), (16, 16), [[0, 1], [0, 2]]) - a.ravel()).max() > 0.1


def test_pitchfork_switched_with_a_fixed_p_corrector_only():
    """Without a p-free corrector the switch tries p* + dp/2 and p* - dp/2 from u* + a v: at p < 0
    Newton falls back to x = 0 (the parent, refused), at p > 0 it lands on x = sqrt(p)."""
    class FixedOnly(Toy):
        free = None

        def free_attempt(self, k):
            return None
    t = FixedOnly("pitchfork", -0.5, 0.5, 0.1, np.array([0.0, 1.0]))
    nodes = tree.grow(t, depth=1)
    switched = [r for r in t.rows() if r["corrector"] == "switch"]
    assert "p fixed at p* + 0.05" in switched[0]["event"] and nodes[1].stopped == "reached"
    assert switched[0]["target"] == pytest.approx(0.05, abs=1e-5)  # p* + dp/2, p* located to 1e-5
    assert abs(t.points(1)[1].phi[0] - math.sqrt(switched[0]["target"])) < 1e-12
    assert nodes[2].stopped == "known: branch 1"


def test_parabola_vertex_of_a_fold_without_a_free_corrector():
    """Three points of x^2 = p around the fold at p = 0 (x = 0.3, -0.1, -0.4): the vertex of p(s)
    (s the chord arclength) is within the parabola's error of the fold: O(h^3) of the chord,
    here |p| < 0.02 (measured 2.9e-3; the points are 0.1-0.3 apart), and no solve is made."""
    pts = [events.Point(x * x, np.array([x, 1.0]), x**3 / 3 - x * x * x, (2 * x, 1.0)) for x in (0.3, -0.1, -0.4)]
    loc = events.locate_fold_parabola(pts, np.ones(2), 1.0)
    assert loc.kind == events.FOLD and loc.located_by == "parabola" and loc.solves == 0
    assert abs(loc.p) < 0.02 and loc.p < min(q.p for q in pts)  # below every point: the turn is passed


def test_a_one_point_blip_is_no_crossing_and_a_zigzag_is_one_turn():
    """The measured symmetric turning point in c0 (2D ellipse, nu = 0.8, 48^2): the parameter
    creeps round the top (a zigzag of ~1e-6), one point's critical eigenvalue (the relative
    translation of the two droplets it has become; measured when the check excluded the rotation)
    is negative beyond its bound (-8.4e-7, bound 1.5e-7) but above the certificate's saddle threshold
    (``verdict.TOL_REL`` = 1e-6: marginal), between undecided and positive ones: no decided negative,
    one turn, no crossing (two points, -2.2e-6 and -2.7e-6 with bound 4.9e-3, are certified negative,
    index 1, their verdict "saddle", but not decidedly); the same point ten times lower (decidedly
    negative) is a one-point blip: still no crossing."""
    ps = [0.73437251, 0.73464357, 0.73474587, 0.73476515, 0.73476171, 0.73475984, 0.73476227, 0.73476518,
          0.73475825, 0.73471667, 0.73459087]
    mus = [1.3e-3, 4.0e-4, 7.7e-5, 1.6e-6, -2.2e-6, -1.6e-7, -2.7e-6, -8.4e-7, 3.4e-5, 1.7e-4, 5.6e-4]
    errs = [2.3e-4, 1.9e-4, 7.7e-5, 1.5e-6, 4.9e-3, 4.6e-7, 4.9e-3, 1.5e-7, 2.9e-5, 1.7e-4, 2.0e-4]
    pts = [events.Point(p, np.zeros(1), 0.0, (mu, 4.7), (e, 1e-3)) for p, mu, e in zip(ps, mus, errs)]
    assert [q.decided for q in pts].count(1) == 0 and events.crossings(pts) == []
    assert [k for k, q in enumerate(pts) if q.index] == [4, 6]
    blip = [events.Point(p, np.zeros(1), 0.0, (mu * (10 if k == 7 else 1), 4.7), (e, 1e-3))
            for k, (p, mu, e) in enumerate(zip(ps, mus, errs))]
    assert [q.decided for q in blip].count(1) == 1 and events.crossings(blip) == []
    assert events.turns(pts) == [3]
    loc = events.locate_fold_parabola(pts[2:5], np.ones(1), 1.0)
    assert abs(loc.p - 0.734765) < 5e-6  # the vertex within the zigzag's amplitude


def test_fold_line_by_sweeps_follows_the_closed_form():
    """E = x^3/3 - (p - q^2) x: in p the fold is at p = q^2 for each q (``branch.lines.fold_line``)."""
    from vesicle_opt.branch.lines import fold_line

    def diagram_at(q):
        t = Toy("fold", 1.0 + q * q, -0.5 + q * q, -0.1, np.array([1.0, 1.0]), max_points=40, shift=q * q)
        tree.grow(t)
        return t.rows()
    line = fold_line(diagram_at, [0.0, 0.5, 1.0], "q", "p")
    assert [r["value"] for r in line] == [0.0, 0.5, 1.0]
    assert max(abs(r["target"] - r["value"] ** 2) for r in line) < 1e-8  # the chord location, as for one fold
    assert all(r["located_by"] == "chord" for r in line)


def test_a_crossing_whose_new_side_is_undecided_at_a_turn_is_the_fold():
    """Measured on the switched (tilted) branch of the nu = 0.8 pair in c0 (2D, FD 48^2, eps 0.4):
    the least eigenvalue crosses zero where the parameter turns, the point after the change within
    its bound (-4.35e-6 +- 6.6e-6) and the turn one point later. The bracket is widened to the
    first decided point, so the crossing is the fold (not a branch point, as the bare pair of points
    classified it) and the critical values are the crossing eigenvalue's (not the next mode's)."""
    data = [(0.71965997, (-2.81e-05, 0.0762), (5.3e-06, 0.00017)),
            (0.71953075, (-2.32e-05, 0.0769), (5.6e-06, 0.00016)),
            (0.71941790, (-1.75e-05, 0.0774), (5.9e-06, 0.00015)),
            (0.71933076, (-1.09e-05, 0.0777), (6.3e-06, 0.00014)),
            (0.71928332, (-4.35e-06, 0.0778), (6.6e-06, 0.00013)),
            (0.71927788, (2.7e-06, 0.0775), (2.6e-07, 3.8e-06)),
            (0.71932100, (9.33e-06, 0.0769), (8e-06, 0.00011)),
            (0.71941148, (1.53e-05, 0.076), (8.4e-06, 0.0001))]
    pts = [events.Point(p, np.zeros(1), 0.0, mu, err) for p, mu, err in data]
    assert events.crossings(pts) == [4]
    ps = [q.p for q in pts]
    assert events.classify(ps, 4) == events.BRANCH_POINT  # the bare bracket (3, 4) misses the turn at 5
    assert events.critical_values(pts[3], pts[4]) == (-1.09e-05, 0.0778)  # and takes the next mode
    a, b = events.bracket(pts, 4)
    assert (a, b) == (3, 5) and events.classify(ps, 4, a, b) == events.FOLD
    assert events.critical_values(pts[a], pts[b]) == (-1.09e-05, 2.7e-06)
    # a soft mode within its bound at both ends (far components' relative translation) widens nothing
    soft = [dataclasses.replace(q, eigenvalues=(-8e-4, *q.eigenvalues), errors=(2e-3, *q.errors)) for q in pts]
    assert events.bracket(soft[:4] + [dataclasses.replace(soft[4], eigenvalues=(-8e-4, 1e-5, 0.0778),
                                                          errors=(2e-3, 1e-7, 1e-4))] + soft[5:], 4) == (3, 4)
