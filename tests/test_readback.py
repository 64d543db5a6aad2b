"""Output directories read back (``vo.load`` and friends, ``vesicle_opt.readback``) and the npz layout
(``io.fields``): each verb's directory round-trips into an object equal to what was written."""

import json

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt import cli
from vesicle_opt.errors import InputError
from vesicle_opt.io import fields

SMALL = ["mesh.n=32"]  # the ellipse at 32^2: a certified solve in ~0.5 s


def test_result_attributes_are_the_summary_values():
    res = vo.solve(vo.load_scene("ellipse-2d", SMALL))
    s = res.summary("ellipse-2d")
    # the properties are views of extra: exactly the numbers summary.json holds
    for key in ("volume", "area", "reduced_volume", "reduced_energy", "second_order_min_eigenvalue"):
        assert getattr(res, key) == s[key]
    assert res.second_order == s["second_order"] and res.topology == s["topology"] == "disk-like"
    # independent: nu = 4 pi V / S^2 in 2D (geometry's formula, not the summary's number)
    assert res.reduced_volume == pytest.approx(4 * np.pi * res.volume / res.area**2, rel=1e-14)  # round-off


def test_solve_round_trip_cli(tmp_path):
    assert cli.main(["solve", "ellipse-2d", "--out", str(tmp_path), "--set", SMALL[0], "-q"]) == 0
    res = vo.load(tmp_path)
    assert isinstance(res, vo.Result)
    written = json.loads((tmp_path / "summary.json").read_text())
    assert res.summary(written["scene"]) == written  # every key back, in its field or in extra
    assert res.converged and res.outcome is vo.Status.CONVERGED
    assert res.disc.n_nodes == res.phi.size == 32 * 32
    assert res.scene == vo.load_scene("ellipse-2d", SMALL)
    data = fields.read(tmp_path / "phi.npz")
    assert data["format_version"] == fields.FORMAT_VERSION and data["kind"] == "solve"
    assert set(data) >= {k for k, (when, _) in fields.KEYS.items() if when == "always"}
    np.testing.assert_array_equal(data["nodes"], res.disc.nodes)


def test_write_result_is_the_cli_output(tmp_path):
    res = vo.solve(vo.load_scene("ellipse-2d", SMALL))
    summary = vo.write_result(res, tmp_path / "py")
    assert {p.name for p in (tmp_path / "py").iterdir()} >= {"summary.json", "phi.npz", "phi.vtu", "phi.vti",
                                                               "phi.png", "scene.resolved.toml"}
    back = vo.load_result(tmp_path / "py")
    np.testing.assert_array_equal(back.phi, res.phi)
    assert back.energy == res.energy and back.reduced_volume == res.reduced_volume == summary["reduced_volume"]
    # a loaded result writes again (its disc rebuilt from scene.resolved.toml): the same phi.npz
    vo.write_result(back, tmp_path / "again")
    np.testing.assert_array_equal(fields.read(tmp_path / "again" / "phi.npz")["phi"], res.phi)
    with pytest.raises(InputError, match="scene"):
        vo.write_result(back.__class__(**{**back.__dict__, "scene": None}), tmp_path / "x")


def test_flow_round_trip(tmp_path):
    assert cli.main(["flow", "ellipse-2d", "--steps", "3", "--out", str(tmp_path), "--set", SMALL[0], "-q"]) == 0
    rec = vo.load(tmp_path)
    assert isinstance(rec, vo.FlowRecord)
    written = json.loads((tmp_path / "summary.json").read_text())
    assert rec.summary == written and rec.steps == 3 and rec.energy == written["energy"]
    assert rec.t == pytest.approx(written["t"], rel=0, abs=0)  # the same double, through npz and JSON
    assert [r["step"] for r in rec.history] == [1, 2, 3]
    assert rec.history[-1]["energy"] == pytest.approx(rec.energy, rel=1e-15)  # CSV repr round-trips doubles
    snap = rec.snapshot(0)
    assert snap["kind"] == "flow-snapshot" and snap["t"] == 0.0 and snap["phi"].shape == rec.phi.shape
    assert rec.scene.flow.steps == 3


def test_branch_round_trip(tmp_path):
    args = ["branch", "ellipse-2d", "--param", "reduced_volume", "--to", "0.89", "--step", "-0.025",
            "--out", str(tmp_path), "--set", SMALL[0], "-q"]
    assert cli.main(args) in (0, 1)
    meta = json.loads((tmp_path / "branch.json").read_text())
    assert isinstance(meta["scene_data"], dict) and meta["stopped"]["0"]  # JSON, not a repr string
    b = vo.load(tmp_path)
    assert isinstance(b, vo.Branch) and b.stopped[0] == meta["stopped"]["0"]
    assert b.scene == vo.load_scene("ellipse-2d", SMALL)
    assert len(b.rows) >= 2 and b.rows[0]["point"] == 0
    pt = b.points()[-1]
    snap = b.field(pt["point"])
    assert snap["kind"] == "branch-point" and snap["p"] == pt["target"]
    assert snap["nodes"].shape == (32 * 32, 2)
    # the same run into the same directory resumes (branch.json's 'stopped' is no argument)
    assert cli.main(args) in (0, 1)
    assert len(vo.load_branch(tmp_path).rows) == len(b.rows)


def test_study_round_trip(tmp_path):
    (tmp_path / "cases.csv").write_text("n,energy,converged\n32,1.5,true\n64,1.25,false\n")
    (tmp_path / "summary.json").write_text('{"order": 2.0}')
    rec = vo.load_study(tmp_path)
    assert rec.tables["cases"] == ({"n": 32, "energy": 1.5, "converged": True},
                                   {"n": 64, "energy": 1.25, "converged": False})
    assert rec.data["summary"] == {"order": 2.0}


def test_legacy_npz_and_bad_paths(tmp_path):
    np.savez(tmp_path / "old.npz", phi=np.ones(4), nodes=np.zeros((4, 2)), t=0.5)
    old = fields.read(tmp_path / "old.npz")
    assert old["format_version"] == 0 and old["kind"] == "flow"
    np.savez(tmp_path / "new.npz", phi=np.ones(4), format_version=fields.FORMAT_VERSION + 1)
    with pytest.raises(InputError, match="format_version"):
        fields.read(tmp_path / "new.npz")
    with pytest.raises(InputError, match="not a directory"):
        vo.load(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="not an output directory"):
        vo.load(tmp_path / "empty")


def test_cli_branch_sharp_refuses_what_it_cannot_cover(tmp_path, capsys):
    assert cli.main(["branch", "curvature-3d", "--param", "reduced_volume", "--to", "0.7",
                     "--out", str(tmp_path), "--sharp"]) == 2
    assert "--sharp" in capsys.readouterr().err  # c0 = 0.5: no reference; before any solve
    assert not (tmp_path / "branch.csv").exists()


def test_a_finished_branch_extends_with_a_further_to_and_sharp_fills_its_column(tmp_path):
    from vesicle_opt.sharp import elastica
    base = ["branch", "elastica-2d", "--param", "reduced_volume", "--set", "mesh.n=48", "--out", str(tmp_path),
            "--sharp", "-q"]
    assert cli.main([*base, "--to", "0.78", "--step", "-0.02"]) == 0
    first = vo.load_branch(tmp_path)
    assert first.stopped == {0: "reached"}
    assert cli.main([*base, "--to", "0.76"]) == 0  # no --step: the stored first step is kept
    ext = vo.load_branch(tmp_path)
    assert ext.to == 0.76 and ext.stopped == {0: "reached"}
    assert ext.rows[: len(first.rows)] == first.rows  # nothing recomputed or rewritten
    assert [r["target"] for r in ext.points()][-1] == 0.76 and len(ext.points()) > len(first.points())
    # the other direction is another run: refused, nothing changed
    assert cli.main([*base, "--to", "0.9"]) == 2
    assert vo.load_branch(tmp_path).rows == ext.rows
    # --sharp: the column is the sharp elastica's own number at each target (sharp.elastica, no phase field)
    pts = ext.points()
    assert all(r["sharp_reduced_energy"] is not None for r in pts)
    assert pts[-1]["sharp_reduced_energy"] == pytest.approx(elastica.solve(pts[-1]["target"]).reduced_energy, rel=1e-12)


def test_a_branch_tree_reads_back_with_its_parents(tmp_path):
    """The tree of a run (branch.tree's nodes: pitchfork at p = 0, both sides switched) against
    load_branch's parents, rebuilt from branch.csv's parent column alone."""
    import sys
    from pathlib import Path

    from vesicle_opt.branch import tree
    sys.path.insert(0, str(Path(__file__).parent / "branch"))
    from toy import Toy  # closed-form problems behind branch.problem.TreeProblem

    t = Toy("pitchfork", -0.5, 0.5, 0.1, np.array([0.0, 1.0]), out=tmp_path)
    nodes = tree.grow(t, depth=1)
    t.store.finish({k: n.stopped for k, n in nodes.items()})
    meta = json.loads((tmp_path / "branch.json").read_text())
    (tmp_path / "branch.json").write_text(json.dumps({**meta, "param": "p", "scene": "pitchfork"}))
    b = vo.load_branch(tmp_path)
    assert b.parents == {k: n.parent for k, n in nodes.items()} == {0: None, 1: 0, 2: 0}
    assert b.children(0) == [1, 2] and b.children(1) == []
    assert b.stopped == {k: n.stopped for k, n in nodes.items()}
