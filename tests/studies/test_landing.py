"""The stomatocyte walks' seedless start (``studies._landing``): the landing's curve kept in ``states``
and read back, recomputed where the file is damaged, handed to ``phase_case`` in the seed's place;
the seed where the route does not get there, the rows saying so; and (slow) the curve handed to
another eps landing on the seeded cup."""

import math

import numpy as np
import pytest

from vesicle_opt.studies import _landing as L
from vesicle_opt.studies import _stomatocyte as S
from vesicle_opt.studies import phase_diagram as pd


def _cup_curve():
    t = np.linspace(0.0, math.pi, 33)
    return np.abs(np.sin(t)) * 0.8 * (t > 0) * (t < math.pi), 0.6 * np.cos(t)


@pytest.fixture
def route(monkeypatch):
    """``compute`` replaced by a known curve, its calls counted."""
    calls = []
    r, z = _cup_curve()

    def compute():
        calls.append(1)
        return r.copy(), z.copy(), "no seed: the landing"
    monkeypatch.setattr(L, "compute", compute)
    return calls, r, z


def test_curve_is_computed_once_and_read_back(tmp_path, route):
    calls, r, z = route
    a = L.curve(tmp_path)
    b = L.curve(tmp_path)
    assert len(calls) == 1 and (tmp_path / L.FILE).exists()
    for got in (a, b):
        assert np.array_equal(got[0], r) and np.array_equal(got[1], z) and got[2] == "no seed: the landing"
    assert not list(tmp_path.glob("*.tmp"))  # the temporary file was renamed over FILE


@pytest.mark.parametrize("damage", ["truncated", "garbage", "off_axis", "no_key"])
def test_an_unreadable_file_is_computed_again_and_replaced(tmp_path, route, damage):
    calls, r, z = route
    path = tmp_path / L.FILE
    L.curve(tmp_path)
    if damage == "truncated":
        path.write_bytes(path.read_bytes()[:100])
    elif damage == "garbage":
        path.write_bytes(b"not an npz file")
    elif damage == "off_axis":  # a curve that does not end on the axis: not what ``compute`` writes
        L.write(path, r + 0.1, z, "x")
    else:
        np.savez(path, r=r, note=np.array("x"))
    assert L.read(path) is None
    got = L.curve(tmp_path)
    assert len(calls) == 2 and np.array_equal(got[0], r)
    assert L.read(path) is not None  # replaced by a good one


def test_phase_case_walks_from_the_landing_curve(monkeypatch, tmp_path, route):
    """The start curve takes the seed's place: the layout is built about it, the walk's first shape is
    it, and the first row's ``seed`` is the landing's note."""
    calls, r, z = route
    seen = {}

    def fake_walk(lay, eps, vs, first, name, stop=None, start=None, states=None, case="", max_iter=None):
        seen["first"], seen["start"] = first, start
        yield vs[0], "res", "sharp shape"

    def fake_layout(meridians, *a):
        seen["layout"] = meridians
        return {"lay": True}

    def row(res, v, eps, lay, sharp_f, seed, side, walk):
        return {"kind": "point", "seed": seed, "walk": walk}

    monkeypatch.setattr(S, "walk", fake_walk)
    monkeypatch.setattr(S, "layout", fake_layout)
    case = {"epsilon": 0.04, "walk": "up", "vs": [0.62], "n_modes": 8, "eps_over_h": 4.0, "start": "landing",
            "states": str(tmp_path)}
    start, missed = L.start(case)
    rows = S.phase_case(case, row, start)
    assert missed == "" and rows[0]["seed"] == "no seed: the landing" and seen["start"] is None
    assert np.array_equal(seen["first"][0], r) and np.array_equal(seen["layout"][0][1], z)
    assert L.start({**case, "start": "seed"}) == (None, "")  # the sharp seed: no route run
    assert len(calls) == 1


def test_a_route_that_fails_leaves_the_seed_and_says_so(monkeypatch, tmp_path):
    def fail():
        raise L.NotReached("the walk in v ended at v 0.64: max_iterations")
    monkeypatch.setattr(L, "compute", fail)
    monkeypatch.setattr(pd.stoma, "phase_case", lambda case, row, start: [{"seed": f"start {start}"}])
    rows = pd.run({"case": "stomatocyte-eps0.03", "branch": "stomatocyte", "epsilon": 0.03, "start": "landing",
                   "states": str(tmp_path)})
    assert rows[0]["seed"] == "start None; the seedless landing was not reached: the walk in v ended at v 0.64: " \
                              "max_iterations"
    assert not (tmp_path / L.FILE).exists()  # nothing written for a route that failed


def test_the_full_study_starts_its_stomatocyte_walks_from_the_landing():
    walks = [c for c in pd.cases(quick=False) if c.get("branch") == "stomatocyte" and c.get("walk")]
    assert walks and all(c["start"] == "landing" for c in walks)


@pytest.mark.slow
def test_the_landing_curve_reaches_the_seeded_cup_at_another_eps(tmp_path):
    """The route at eps 0.03 (uniform eps/h = 2), its phi = 0 curve handed to eps 0.04 on the study's
    refined eps/h = 4 mesh: a certified cup, the state the 24-mode sharp seed reaches there (measured:
    f 1.9699170065 both, 2.6e-12 apart; field distance 4.3e-7; the route ~190 CPU s)."""
    from vesicle_opt.sharp import stomatocyte as sharp_s
    from vesicle_opt.studies import _same_state as same
    from vesicle_opt.studies._meridian import SEED_MAX_ITER, layout, scene, seed, solve_quiet
    from vesicle_opt.verify import updown

    r, z, note = L.curve(tmp_path)
    assert note.startswith("no seed") and L.read(tmp_path / L.FILE) is not None
    eps, got = 0.04, []
    for curve in ((r, z), sharp_s.start_point(S.V_SEED, 0.0, 24).meridian(2048)):
        lay = layout([curve], eps, 4.0, True)
        sc = scene(lay, eps, S.V_SEED, "landing-eps0.04", max_iter=SEED_MAX_ITER)
        got.append(solve_quiet(sc, seed(sc, *curve, eps, lay["h"])))
    for res in got:
        assert res.converged and res.extra["second_order"] == "minimum"
        assert updown.describe(res.disc, res.phi)["form"] == "cup"
    c = same.compare(*got)
    assert c["f_rel"] < 1e-7  # two meshes refined about two curves of one state: measured 2.6e-12 (1e-7: IPOPT's tol)
    assert max(c["distance"]) < 1e-4  # the same state; another one (a torus) lies at ~0.08 (measured)


def test_the_h_levels_walk_from_the_landing_where_states_hold_it(monkeypatch, tmp_path):
    """``_hlevel._walked`` (a state's field was not saved): the stomatocyte's walk starts from the
    landing's curve kept beside the states, else from the sharp stomatocyte."""
    from vesicle_opt.studies import _hlevel as hl

    r, z = _cup_curve()
    seen = []
    monkeypatch.setattr(hl, "layout", lambda meridians, eps, eoh: {"h": eps / eoh})
    monkeypatch.setattr(hl, "walk", lambda lay, eps, vs, first, name, stop=None: seen.append(first) or iter(()))
    sharp = (np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, -1.0]))
    monkeypatch.setattr(hl.sharp_s, "start_point", lambda v, c0, n: type("P", (), {"meridian": lambda self, m: sharp})())
    case = {"case": "h-fold-stomatocyte0-eps0.03", "epsilon": 0.03, "walk_vs": [S.V_SEED, 0.63],
            "branch": "stomatocyte", "v": 0.63, "state": str(tmp_path / "stomatocyte-eps0.03-v0.63.npz")}
    hl._walked(case)
    L.write(tmp_path / L.FILE, r, z, "no seed")
    hl._walked(case)
    assert seen[0] is sharp and np.array_equal(seen[1][0], r) and np.array_equal(seen[1][1], z)


def test_prepare_makes_the_landing_once_before_the_cases(tmp_path, route, monkeypatch):
    """``prepare`` (the study's process, before its parallel cases): the route once, the cases read its
    file; where it does not land, the landing's cases start from the seed and carry why, and no case
    runs the route again."""
    calls, r, z = route
    cs = [{"case": f"stomatocyte-eps{e:g}", "start": "landing", "states": str(tmp_path)} for e in (0.03, 0.02)]
    cs.append({"case": "oblate-low-eps0.03", "states": str(tmp_path)})
    assert L.prepare(cs) == cs and len(calls) == 1
    assert all(np.array_equal(L.start(c)[0][0], r) for c in cs[:2]) and len(calls) == 1

    def fail():
        calls.append(1)
        raise L.NotReached("the switched branch did not reach c0 = 0 (CPU budget)")
    monkeypatch.setattr(L, "compute", fail)
    (tmp_path / L.FILE).unlink()
    got = L.prepare(cs)
    assert len(calls) == 2 and got[2] == cs[2] and all(c["start"] == "seed" for c in got[:2])
    why = "the seedless landing was not reached: the switched branch did not reach c0 = 0 (CPU budget)"
    assert [L.start(c) for c in got[:2]] == [(None, why)] * 2
    assert len(calls) == 2
