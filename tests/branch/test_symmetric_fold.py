"""``branch.symmetric_fold``: the symmetric turn of the nu = 0.8 ellipse's c0 branch (two droplets half a
box apart, 2D FD 48^2) continued in the reduced volume in its symmetric subspace, against the turn of
the ordinary branch walk at each nu; the group's projector and odd basis on their own."""

import sys
from pathlib import Path

import numpy as np
import pytest

from vesicle_opt.branch import branch
from vesicle_opt.branch import symmetric_fold as sf
from vesicle_opt.errors import InputError
from vesicle_opt.scene.schema import from_dict

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_run import raw_scene  # noqa: E402


def test_the_odd_basis_is_orthonormal_and_of_its_character():
    """On a 6 x 4 grid (half shift along axis 0): every column v has g v = chi(g) v for all 8 group
    elements, the columns are orthonormal, and their number is the character's multiplicity,
    (1/|G|) sum chi(g) (fixed nodes of g) (exact integers)."""
    shape = (6, 4)
    perms = sf.group(shape, 0)
    Q = sf.odd_basis(perms, 24)
    assert np.abs(Q.T @ Q - np.eye(Q.shape[1])).max() < 1e-14
    for p, chi in perms:
        assert np.abs(Q[p] - chi * Q).max() < 1e-15
    mult = sum(chi * int(np.sum(p == np.arange(24))) for p, chi in perms) / len(perms)
    assert Q.shape[1] == mult
    rng = np.random.default_rng(1)
    phi = rng.standard_normal(24)
    s = sf.symmetric(phi, perms)
    assert sf.asymmetry(s, perms) < 1e-15 and np.abs(sf.symmetric(s, perms) - s).max() < 1e-15
    assert abs(Q.T @ s).max() < 1e-14  # the symmetric part has no odd component
    two = np.zeros(shape)
    two[1, 1] = two[4, 1] = 1.0  # two bumps half a box apart along axis 0
    assert sf.pair_axis(two.ravel(), shape) == 0


def _scene(nu):
    raw = raw_scene(n=48, eps=0.4, second_order=True, initial={"shape": "ellipse", "semi_axes": [1.6, 0.9]})
    raw["constraints"]["reduced_volume"] = nu
    return from_dict(raw, "ellipse-c0")


def test_bad_input_is_named_before_any_solve():
    sc = _scene(0.8)
    with pytest.raises(InputError, match="--second"):
        sf.line(sc, "c0", "c0", [0.81], at=0.73, warm=np.zeros(48 * 48))
    with pytest.raises(InputError, match="dp"):
        sf.line(sc, "c0", "reduced_volume", [0.81], at=0.73, warm=np.zeros(48 * 48), dp=0.0)


@pytest.mark.slow
def test_the_fold_line_agrees_with_the_walks_turn_at_two_volumes(tmp_path):
    """Above nu_c ~ 0.802 the walked branch's turn in c0 is the branch point of the S-symmetric branch
    (the droplets exactly half a box apart) where their relative translation's eigenvalue crosses
    zero (measured linear: -1.25e-5, +1.26e-5 mu_ref at p* -+ 2e-5). The line (symmetric subspace,
    Illinois on that eigenvalue) continued from nu = 0.81 to 0.82 against an independent walk in c0 at
    each nu (full space, its turn the parabola's vertex through the walked points): measured
    0.7376034152 vs 0.7376034095 and 0.7404285485 vs 0.7404286520."""
    folds = {}
    for nu in (0.81, 0.82):
        b = branch(_scene(nu), "c0", to=2.5, step=0.1, max_points=45, switch=False, out=tmp_path / f"{nu}")
        turn = [r for r in b.located(0) if r["event"] == "fold"]
        assert len(turn) == 1 and turn[0]["located_by"] == "parabola"
        folds[nu] = turn[0]["target"]
        if nu == 0.81:
            near = max(b.points(0), key=lambda r: r["target"])
            warm = b.field(near["point"])["phi"]
    line = sf.line(_scene(0.81), "c0", "reduced_volume", [0.82], at=folds[0.81], warm=warm)
    assert [t.q for t in line] == [0.81, 0.82] and all(t.converged for t in line)
    for t in line:
        # the walk's vertex is O(ds^3) of the points around the turn (measured 5.7e-9, 1.0e-7);
        # 1e-6 is 1/140 of the gap to the folds below nu_c (1.4e-4 at nu = 0.79)
        assert abs(t.p - folds[t.q]) < 1e-6, (t.q, t.p, folds[t.q])
        # certified: zero to its bound or bracketed to P_TOL, on the symmetric branch to round-off
        assert abs(t.eigenvalue) <= t.error or t.bracket <= sf.P_TOL
        assert t.error < 1e-9 and t.asymmetry < 1e-10  # measured bounds 2e-11, asymmetry 2e-13
        assert t.point.payload.converged
