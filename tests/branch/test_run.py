"""``vesicle_opt.branch`` on small 2D scenes: certified points, the envelope identity at its order,
branch switching off a saddle, bad input (exit 2, nothing computed lost), resume after a kill."""

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from vesicle_opt import cli
from vesicle_opt.branch import COLUMNS, branch
from vesicle_opt.errors import InputError
from vesicle_opt.mesh.spectral import FourierGrid
from vesicle_opt.scene.schema import from_dict

ROOT = Path(__file__).resolve().parents[2]


# shape_check off: this toy (eps = 0.5, perimeter 8: eps/R0 = 0.4) is a circle whose bulk carries
# 27-38 % of the volume at every nu (verify.shape: wrong_shape); the tests here check the branch's
# machinery on its KKT points; test_a_wrong_shape_stops_the_branch the check
def raw_scene(n=32, eps=0.5, second_order=False, initial=None, c0=0.0, shape_check=False):
    return {"domain": {"box": [[-4.0, 4.0], [-4.0, 4.0]], "boundary": "periodic"},
            "mesh": {"kind": "fd", "n": n}, "model": {"epsilon": eps, "c0": c0},
            "constraints": {"reduced_volume": 0.95, "area": 8.0},
            "initial": initial or {"shape": "ellipse", "semi_axes": [1.45, 1.1]},
            "solver": {"method": "exact", "tol": 1e-8, "second_order": second_order, "max_iter": 60,
                       "shape_check": shape_check}}


def scene(**kw):
    return from_dict(raw_scene(**kw), "small-2d")


def first_interval_residuals(param, steps, **kw):
    out = []
    for h in steps:
        start = 0.95 if param == "reduced_volume" else 0.0
        b = branch(scene(**kw), param, to=start + steps[0], step=h)
        pts = b.points()
        assert all(r["converged"] for r in pts) and b.stopped == {0: "reached"}
        out.append(pts[1]["envelope_residual"])
    return np.array(out)


def test_a_wrong_shape_stops_the_branch_and_says_why(tmp_path):
    """With the check on (the default), the toy's start is a KKT point but a circle whose bulk carries
    27 % of V (verify.shape): the start fails with outcome wrong_shape, the reason in its row."""
    b = branch(scene(shape_check=True), "reduced_volume", to=0.91, step=-0.04, out=tmp_path / "w")
    assert b.points() == [] and b.stopped == {0: "start failed"} and not b.converged
    row = b.rows[0]
    assert row["outcome"] == "wrong_shape" and "round" in row["reason"] and row["shape"] == "wrong_shape"


def test_envelope_identity_is_second_order_in_the_step():
    """dE*/dnu = lambda_volume dalpha/dnu against the finite difference of E along the branch: the
    trapezoid rule's error, O(step^2) (measured 3.7e-4, 9.9e-5, 2.6e-5: order 1.9)."""
    steps = [-0.04, -0.02, -0.01]
    res = first_interval_residuals("reduced_volume", steps)
    order = np.polyfit(np.log(np.abs(steps)), np.log(res), 1)[0]
    assert 1.7 < order < 2.3, (order, res)  # the trapezoid rule's order 2 (window: the fit's spread)
    assert res[-1] < 1e-4, res  # and small: the solver's tol 1e-8 is far below


def test_envelope_identity_in_c0_includes_the_explicit_derivative():
    """In c0 the targets are fixed: dE*/dc0 = rigidity dE_h/dc0 at fixed phi, same order."""
    steps = [0.1, 0.05]
    res = first_interval_residuals("c0", steps)
    order = np.log(res[0] / res[1]) / np.log(2)
    assert 1.6 < order < 2.4, (order, res)  # order 2 (measured 2e-3 at step 0.1)


def test_every_point_certified_with_its_columns(tmp_path):
    b = branch(scene(n=32, second_order=True), "reduced_volume", to=0.87, step=-0.04, out=tmp_path / "b")
    pts = b.points()
    assert len(pts) == 3 and b.converged
    for r in pts:
        assert r["converged"] and r["second_order"] in ("minimum", "saddle")
        assert r["second_order_min_eigenvalue"] is not None and r["topology"] == "disk-like"
        assert abs(r["reduced_volume"] - r["target"]) < 1e-6  # A = alpha to tol 1e-8 relative to |Omega|
    with open(tmp_path / "b" / "branch.csv") as fh:
        header = next(csv.reader(fh))
    assert header == COLUMNS
    for name in ("point", "reduced_volume", "c0", "energy", "reduced_energy", "lambda_volume", "lambda_area",
                 "second_order", "second_order_min_eigenvalue", "topology", "converged", "iterations",
                 "wall_time_s", "epsilon", "n", "sharp_reduced_energy"):
        assert name in header
    assert (tmp_path / "b" / "energy_diagram.png").stat().st_size > 0
    assert (tmp_path / "b" / "points" / "point-0002.vtu").exists()


@pytest.mark.slow
def test_a_stability_change_reads_the_verdicts_sign():
    """The walk's ``stability change`` compares the least eigenvalue's certified signs (``events.sign``,
    the verdict's): a saddle's Ritz value is negative whatever its bound (the matrix-free check's
    0.05 past the meridian cup's fold, measured); a positive one within its bound of zero ("marginal")
    is no reference; a row without bounds reads as the assembled check's round-off (~1e-11)."""
    from vesicle_opt.branch.vesicle import _least_sign
    assert _least_sign(-2.7e-4, "0.055;0.24;0.027") == -1 and _least_sign(-2.7e-4, (0.055,)) == -1
    assert _least_sign(5e-5, "0.001;0.1") == 0 and _least_sign(-5e-7, "1e-11") == 0  # marginal either side
    assert _least_sign(5e-5, "1e-11;0.1") == 1 and _least_sign(5e-5, None) == 1
    assert _least_sign(None, "") == 0 and _least_sign(0.1, "nan") == 0  # no check, no finite bound


def test_the_circle_saddle_switches_along_its_critical_mode(tmp_path):
    """The circle start converges to a symmetric saddle; the walk, the tree's fixed-p/free switch
    from the saddle's branch point and the located events hold together (every row certified)."""
    sc = scene(n=48, eps=0.4, second_order=True, initial={"shape": "circle", "radius": 1.27})
    b = branch(sc, "reduced_volume", to=0.9, step=-0.025, out=tmp_path / "s", max_points=4, depth=1)
    saddle = b.points(0)[0]
    assert saddle["second_order"] == "saddle" and saddle["second_order_min_eigenvalue"] < 0
    assert saddle["index"] >= 1 and saddle["second_order_eigenvalues"]
    assert all(r["converged"] for r in b.points())


def test_resume_in_process_matches_an_uninterrupted_run(tmp_path):
    sc = scene()
    part = branch(sc, "reduced_volume", to=0.89, step=-0.02, out=tmp_path / "a", max_points=2, snapshots=False)
    a = branch(sc, "reduced_volume", to=0.89, step=-0.02, out=tmp_path / "a", snapshots=False)
    b = branch(sc, "reduced_volume", to=0.89, step=-0.02, out=tmp_path / "b", snapshots=False)
    assert len(part.rows) == 2 and len(a.rows) == len(b.rows) >= 4
    for x, y in zip(a.rows, b.rows):
        assert {k: v for k, v in x.items() if k != "wall_time_s"} == {k: v for k, v in y.items() if k != "wall_time_s"}


def _cli(args, capsys):
    code = cli.main(args)
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


@pytest.mark.parametrize("args, flag", [
    (["--param", "volume", "--to", "0.8"], "--param"),
    (["--param", "reduced_volume", "--to", "1.5"], "--to"),
    (["--param", "reduced_volume", "--to", "0"], "--to"),
    (["--param", "reduced_volume", "--to", "-0.2"], "--to"),
    (["--param", "reduced_volume", "--to", "0.8", "--step", "0.02"], "--step"),
    (["--param", "reduced_volume", "--to", "0.8", "--step", "0"], "--step"),
    (["--param", "c0", "--to", "0.5", "--step", "-0.1"], "--step"),
    (["--param", "reduced_volume", "--to", "0.8", "--set", "constraints.alpha=-30.0"], "constraints.alpha"),
    (["--param", "reduced_volume", "--to", "0.8", "--depth", "-1"], "--depth"),
    (["--param", "reduced_volume", "--to", "0.8", "--deflate", "-2"], "--deflate"),
    (["--param", "c0", "--to", "0.5", "--values", "0.8,0.9"], "--second"),
    (["--param", "c0", "--to", "0.5", "--second", "c0", "--values", "0.8,0.9"], "--second"),
    (["--param", "c0", "--to", "0.5", "--second", "reduced_volume", "--values", "0.8"], "--values"),
    (["--param", "c0", "--to", "0.5", "--second", "reduced_volume", "--values", "0.8,1.2"], "--values"),
    (["--param", "c0", "--to", "0.5", "--fold-line"], "--second"),
    (["--param", "c0", "--to", "0.5", "--fold-line", "--second", "reduced_volume", "--values", "0.8"], "--values"),
    (["--param", "c0", "--to", "0.5", "--fold-line", "--second", "reduced_volume", "--values", "0.8,0.9",
      "--set", 'domain.boundary="natural"'], "mesh.kind"),
    (["--param", "reduced_volume", "--to", "0.8", "--fold-line", "--transition", "initial.semi_axes=[1.3,1.1]",
      "--second", "c0", "--values", "0.1"], "--fold-line"),
    (["--param", "c0", "--to", "0.5", "--fold-line", "--fold-kind", "ordinary", "--second", "reduced_volume",
      "--values", "0.8,0.9"], "solver.second_order"),
    (["--param", "c0", "--to", "0.5", "--fold-line", "--fold-kind", "ordinary", "--second", "reduced_volume",
      "--values", "0.8,0.9", "--set", 'mesh.kind="spectral"', "--set", "solver.second_order=true"], "backend"),
])
def test_bad_input_is_one_line_exit_2_before_any_work(tmp_path, capsys, args, flag):
    toml = tmp_path / "s.toml"
    toml.write_text(_toml(raw_scene()))
    out = tmp_path / "out"
    out.mkdir()
    (out / "branch.csv").write_text("computed before\n")  # nothing already computed is touched
    code, err = _cli(["branch", str(toml), "--out", str(out), *args], capsys)
    assert code == 2 and len(err) == 1 and flag in err[0], err
    assert (out / "branch.csv").read_text() == "computed before\n"
    assert not (out / "points").exists() and not (out / "branch.json").exists()


@pytest.mark.parametrize("turn", ["wide", -0.1])
def test_a_bad_turn_is_refused_before_the_output_is_touched(tmp_path, turn):
    """The Python keyword ``turn`` (no CLI flag): InputError naming it, before the store is opened."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "branch.csv").write_text("computed before\n")
    with pytest.raises(InputError, match="turn"):
        branch(scene(), "reduced_volume", to=0.9, step=-0.01, out=out, turn=turn)
    assert (out / "branch.csv").read_text() == "computed before\n"
    assert not (out / "branch.json").exists()


def test_a_resume_under_other_arguments_is_refused(tmp_path, capsys):
    toml = tmp_path / "s.toml"
    toml.write_text(_toml(raw_scene()))
    out = tmp_path / "out"
    assert _cli(["branch", str(toml), "--out", str(out), "--param", "reduced_volume", "--to", "0.93",
                 "--step", "-0.02"], capsys)[0] == 0
    before = (out / "branch.csv").read_text()
    # another first step to the same end is another run (a further --to extends it: tests/test_readback.py)
    code, err = _cli(["branch", str(toml), "--out", str(out), "--param", "reduced_volume", "--to", "0.93",
                      "--step", "-0.01"], capsys)
    assert code == 2 and len(err) == 1 and "--out" in err[0], err
    assert (out / "branch.csv").read_text() == before


def _toml(raw: dict) -> str:
    lines = []
    for section, body in raw.items():
        lines.append(f"[{section}]")
        for k, v in body.items():
            lines.append(f"{k} = {_value(v)}")
    return "\n".join(lines) + "\n"


def _value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return repr(v)


@pytest.mark.slow
def test_a_branch_killed_mid_way_resumes_without_a_lost_or_duplicated_row(tmp_path):
    toml = tmp_path / "s.toml"
    toml.write_text(_toml(raw_scene()))
    args = [sys.executable, "-m", "vesicle_opt.cli", "branch", str(toml), "--param", "reduced_volume",
            "--to", "0.8", "--step", "-0.02"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    ref = subprocess.run(args + ["--out", str(tmp_path / "ref")], env=env, capture_output=True, timeout=600)
    assert ref.returncode == 0, ref.stderr.decode()[-2000:]
    killed = tmp_path / "killed"
    proc = subprocess.Popen(args + ["--out", str(killed)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    t0 = time.time()
    while time.time() - t0 < 300:
        path = killed / "branch.csv"
        if path.exists() and path.read_text().count("\n") >= 4:  # header and >= 3 rows
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    n_before = (killed / "branch.csv").read_text().count("\n") - 1
    resumed = subprocess.run(args + ["--out", str(killed)], env=env, capture_output=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr.decode()[-2000:]

    def rows(d):
        with open(d / "branch.csv") as fh:
            return [{k: v for k, v in r.items() if k != "wall_time_s"} for r in csv.DictReader(fh)]
    a, b = rows(killed), rows(tmp_path / "ref")
    assert 3 <= n_before < len(b)
    assert [r["point"] for r in a] == [str(k) for k in range(len(a))]  # none lost, none twice
    assert a == b


def test_an_output_path_that_is_a_file_is_bad_input(tmp_path, capsys):
    toml = tmp_path / "s.toml"
    toml.write_text(_toml(raw_scene()))
    target = tmp_path / "taken"
    target.write_text("keep me\n")
    code, err = _cli(["branch", str(toml), "--out", str(target), "--param", "reduced_volume", "--to", "0.9"], capsys)
    assert code == 2 and len(err) == 1 and "--out" in err[0], err
    assert target.read_text() == "keep me\n"


@pytest.mark.slow
def test_deflation_finds_another_certified_point_at_the_start():
    """The circle start's saddle branch has no branch point down to 0.925; deflated by it, the
    bordered Newton from the scene's start field (and the saddle pushed along its mode) finds
    another KKT point at nu = 0.95, certified by IPOPT, neither the saddle nor an image of it
    (measured: the elastica minimum, reduced energy 1.8605 against the saddle's 1.971, from the
    pushed saddle in 20 line-searched steps; the same with the mode's sign flipped, or the mode
    perturbed by 1e-6 relative noise, where the undamped iteration's outcome flipped at 6e-10)."""
    sc = scene(n=48, eps=0.4, second_order=True, initial={"shape": "circle", "radius": 1.27})
    b = branch(sc, "reduced_volume", to=0.925, step=-0.025, deflate=1)
    root, other = b.points(0)[0], b.points(1)[0]
    assert b.parents == {0: None, 1: None} and b.stopped[1] == "reached"
    assert other["corrector"] == "deflation" and other["converged"] and other["target"] == 0.95
    assert abs(other["energy"] - root["energy"]) > 1e-3 * abs(root["energy"])  # another point, not round-off
    assert other["topology"] == root["topology"] == "disk-like"  # one membrane (two far drops are refused)
    assert all(r["converged"] for r in b.points(1))


def test_cli_switch_depth_and_deflate_reach_the_run(tmp_path, capsys):
    """--no-switch, --depth, --deflate are recorded with the run (a resume under others is refused);
    the defaults keep the older runs' branch.json keys."""
    import json
    toml = tmp_path / "s.toml"
    toml.write_text(_toml(raw_scene()))
    out = tmp_path / "out"
    assert _cli(["branch", str(toml), "--out", str(out), "--param", "reduced_volume", "--to", "0.93",
                 "--step", "-0.02", "--no-switch", "--depth", "0"], capsys)[0] == 0
    meta = json.loads((out / "branch.json").read_text())
    assert meta["switch"] is False and meta["depth"] == 0 and "deflate" not in meta
    code, err = _cli(["branch", str(toml), "--out", str(out), "--param", "reduced_volume", "--to", "0.93",
                      "--step", "-0.02", "--depth", "2"], capsys)
    assert code == 2 and len(err) == 1 and "depth" in err[0], err
    with open(out / "branch.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["branch"] for r in rows] == ["0", "0"] and all(r["parent"] == "" for r in rows)


@pytest.mark.slow
def test_a_turning_point_in_c0_is_reported_once_as_a_fold(tmp_path):
    """The nu = 0.8 ellipse at 48^2 (eps 0.4) in c0 splits into two droplets (by c0 ~ 0.3) that drift
    apart along the branch; it turns back at c0 = 0.734765 (measured; the chord location with p free
    gave 0.7347652, the parabola 0.7347663), where they sit half a box apart: a symmetric turning
    point (the sheets beyond are the half-box shifts of those before), whose critical eigenvalue
    (the droplets' relative translation) touches zero and stays >= 0 within its bound. So the fold
    is one row located by the parabola, not switched, and the walk comes back on the other sheet.
    The rotation of the pair is kept in the check (``verify.verdict``) and is a real mode of the
    periodic box: its eigenvalue crosses zero at c0 = 0.723573 on both sheets (decidedly: -4.6e-5
    +- 7.9e-7 one point later, -4.7e-4 +- 9.8e-5 at the turn), 0.011 below the turn, p monotone
    there: two branch points (the second the half-box image of the first), each critical mode the
    rotation generator's direction (overlap 0.9999, 0.995); the branches they start are one (tilted)
    branch, which turns at c0 = 0.719274, a crossing at a turn: located as a fold on the chord."""
    raw = raw_scene(n=48, eps=0.4, second_order=True, initial={"shape": "ellipse", "semi_axes": [1.6, 0.9]})
    raw["constraints"]["reduced_volume"] = 0.8
    b = branch(from_dict(raw, "ellipse-c0"), "c0", to=2.5, step=0.1, max_points=50, out=tmp_path / "c")
    folds = [r for r in b.located(0) if r["event"] == "fold"]
    assert len(folds) == 1 and folds[0]["located_by"] == "parabola"
    assert abs(folds[0]["target"] - 0.734765) < 1e-5  # the two locations agree to 1.1e-6; the walk's zigzag ~5e-6
    assert b.stopped[0] == "max_points" and max(r["target"] for r in b.points(0)) < 0.73477
    assert b.points(0)[-1]["target"] < 0.733 and all(r["converged"] for r in b.points(0))  # back: 300x the zigzag
    bps = [r for r in b.located(0) if r["event"] != "fold"]
    assert [r["event"] for r in bps] == ["branch point"] * 2 and all(r["located_by"] == "illinois" for r in bps)
    # both off the turn by 2000x the zigzag (no turn there: a branch point is right), at one c0 (images):
    # to the location's bracket, tree.P_TOL x step = 1e-4 (measured 4.7e-6 apart)
    assert all(r["target"] < folds[0]["target"] - 0.01 for r in bps)
    assert abs(bps[0]["target"] - bps[1]["target"]) < 1e-4
    for r in bps:  # the critical mode is the rotation x d_y phi - y d_x phi (measured overlaps 0.9999, 0.995)
        snap = b.field(r["point"])
        phi, x, v = snap["phi"], np.asarray(snap["nodes"]), snap["mode"]
        dx, dy = FourierGrid(snap["box"], tuple(snap["grid_shape"])).derivatives(phi)
        rot = x[:, 0] * dy - x[:, 1] * dx
        assert abs(v @ rot) / np.linalg.norm(v) / np.linalg.norm(rot) > 0.99  # the next modes are of other parity
    # the two images: the second point's field is the first's shifted by half the box (24 cells) in x
    # (measured max 4.8e-5 against 0.79 unshifted: the points are 4.7e-6 apart in c0, |dphi/dc0| ~ 10)
    f0, f1 = (b.field(r["point"])["phi"].reshape(48, 48) for r in bps)
    assert np.abs(np.roll(f0, 24, axis=0) - f1).max() < 1e-3 < np.abs(f0 - f1).max()
    # the four switches (two per branch point) walk one tilted branch; the other three land on it
    assert len(b.stopped) == 5 and sum(v == "known: branch 1" for v in b.stopped.values()) == 3
    tilted = [r for r in b.located() if r["branch"] != 0]
    assert [(r["event"], r["located_by"]) for r in tilted] == [("fold", "chord")]
    assert tilted[0]["target"] < min(r["target"] for r in b.points(tilted[0]["branch"]))  # below every point
    # Illinois to TAU_TOL = 1e-3 of the chord: |g| within ~1e-3 of the ends' 1.1e-5 (measured 1.3e-9)
    assert abs(tilted[0]["critical_eigenvalue"]) < 2e-8