"""scene.resolved.toml: the validated scene written back; loading it gives the same Scene."""

import json
import os
import tomllib

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt import cli
from vesicle_opt.scene import bundled, from_dict, resolved


@pytest.mark.parametrize("sets", [[], ["mesh.n=[20, 24]", 'solver.method="continuation"', "flow.dt=2e-3",
                                  "solver.backend='ipopt'", "model.c0=0.5"]])
def test_round_trip_of_every_bundled_scene(sets):
    for name in bundled.names():
        sc = vo.load_scene(name, [s for s in sets if "-2d" in name or "mesh.n" not in s])
        assert from_dict(tomllib.loads(resolved.dumps(sc)), sc.name) == sc, name


def test_round_trip_of_physical_targets_and_paths(tmp_path):
    """reduced_volume + area are written instead of the (alpha, beta) they set; a relative
    initial.file is written absolute, so the resolved scene works from any directory."""
    raw = tomllib.loads(bundled.text("ellipse-2d"))
    raw["constraints"] = {"reduced_volume": 0.9, "area": 9.0}
    sc = from_dict(raw, "phys")
    table = tomllib.loads(resolved.dumps(sc))
    assert set(table["constraints"]) == {"reduced_volume", "area"}
    assert from_dict(table, "phys") == sc
    np.savez(tmp_path / "start.npz", phi=np.zeros(4))
    raw["initial"] = {"shape": "file", "file": "start.npz"}
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        sc = from_dict(raw, "f")
        table = tomllib.loads(resolved.dumps(sc))
    finally:
        os.chdir(cwd)
    assert table["initial"]["file"] == str(tmp_path / "start.npz")


def test_cli_run_repeats_from_its_resolved_scene(tmp_path):
    """Solve, then solve DIR/scene.resolved.toml: the same numbers, bit for bit (determinism)."""
    a, b = tmp_path / "a", tmp_path / "b"
    assert cli.main(["solve", "ellipse-2d", "--out", str(a), "-q", "--set", "mesh.n=24",
                     "--set", "initial.semi_axes=[1.7, 1.1]"]) == 0
    assert cli.main(["solve", str(a / "scene.resolved.toml"), "--out", str(b), "-q"]) == 0
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    for key in ("energy", "lambda_volume", "lambda_area", "volume", "area", "iterations"):
        assert sa[key] == sb[key], key
    assert np.array_equal(np.load(a / "phi.npz")["phi"], np.load(b / "phi.npz")["phi"])
    assert sa["version"] == vo.__version__
