"""Scene loading, overrides and bad input (one-line InputError naming the key)."""

from pathlib import Path

import pytest

import vesicle_opt
from vesicle_opt import scene
from vesicle_opt.errors import InputError
from vesicle_opt import load_scene


FOLDER = Path(vesicle_opt.__file__).parent / "problems"


def test_bundled_names_are_the_shipped_files():
    assert scene.bundled.names() == sorted(p.stem for p in FOLDER.glob("*.toml"))
    assert "ellipse-2d" in scene.bundled.names()


@pytest.mark.parametrize("name", scene.bundled.names())
def test_bundled_scene_loads_by_name_as_from_its_file(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # by name from any directory (importlib.resources)
    by_name = scene.load(name)
    assert by_name.name == name
    assert by_name == scene.load(FOLDER / f"{name}.toml") == scene.load(f"{name}.toml")


def test_override_parses_toml_values():
    sc = load_scene("ellipse-2d", ["mesh.n=[32, 16]", "model.c0=0.5", "mesh.kind=fem-p1", 'initial.center=[0.5, 0.0]'])
    assert sc.mesh.n == (32, 16) and sc.model.c0 == 0.5 and sc.mesh.kind == "fem-p1"
    assert sc.initial.center == (0.5, 0.0)


@pytest.mark.parametrize("override, key", [
    ("model.epsilon=0", "model.epsilon"),
    ("model.rigidity=-1", "model.rigidity"),
    ("mesh.n=3", "mesh.n"),
    ("mesh.kind='fx'", "mesh.kind"),
    ("domain.box=[[1, 0], [0, 1]]", "domain.box"),
    ("constraints.alpha=1e6", "constraints.alpha"),
    ("constraints.beta=-2", "constraints.beta"),
    ("solver.tol=0", "solver.tol"),
    ("solver.M=-1", "solver.M"),
    ("solver.method='newton'", "solver.method"),
    ("model.epsilon='small'", "model.epsilon"),
    ("nope.key=1", "nope.key"),
    ("initial.shape='cube'", "initial.shape"),
    ("initial.semi_axes=[1.0]", "initial.semi_axes"),
    ("mesh.quadrature='gauss'", "mesh.quadrature"),  # gauss needs fem-p1; ellipse-2d is fd
    # issue 12: ranges that mean something (scene.schema.TOL_RANGE, EPS_PER_H_MIN, EPS_PER_BOX_MAX)
    ("solver.tol=1", "solver.tol"),  # certified a saddle with kkt 0.2 before
    ("solver.tol=2e-4", "solver.tol"),
    ("solver.tol=1e-15", "solver.tol"),
    ("model.epsilon=1e-300", "model.epsilon"),  # died inside the feasibility bound's radial grid
    ("model.epsilon=0.006", "model.epsilon"),  # h/10 = 0.00625 on the 128^2 grid of the 8-wide box
    ("model.epsilon=4.5", "model.epsilon"),  # above half the box's side
    ("solver.max_memory_gb=-1", "solver.max_memory_gb"),
])
def test_bad_input_names_the_key(override, key):
    with pytest.raises(InputError) as info:
        load_scene("ellipse-2d", [override])
    assert info.value.key == key and "\n" not in str(info.value)


@pytest.mark.parametrize("override", ["solver.tol=1e-4", "solver.tol=1e-14", "model.epsilon=0.00625",
                                      "model.epsilon=4.0", "solver.max_memory_gb=0.5"])
def test_the_ends_of_the_ranges_are_accepted(override):
    load_scene("ellipse-2d", [override])


def test_missing_required_key():
    with pytest.raises(InputError, match="model.epsilon: missing"):
        scene.from_dict({"domain": {"box": [[0, 1], [0, 1]]}, "mesh": {"n": 8}, "initial": {"shape": "circle", "radius": 0.3},
                         "constraints": {"alpha": 0.0, "beta": 1.0}})


def test_warm_start_file_restarts_at_the_solution(tmp_path):
    from vesicle_opt import cli
    assert cli.main(["solve", "ellipse-2d", "--out", str(tmp_path / "a"), "--set", "mesh.n=32"]) == 0
    from vesicle_opt.api import solve
    res = solve(load_scene("ellipse-2d", ["mesh.n=32", "initial.shape='file'", f"initial.file='{tmp_path / 'a' / 'phi.npz'}'"]))
    assert res.converged and res.iterations <= 3  # already optimal: IPOPT only confirms it


@pytest.mark.parametrize("content", [b"garbage", None, "wrong-size"])
def test_bad_warm_start_file_is_bad_input(tmp_path, content):
    import numpy as np
    from vesicle_opt.nlp import build_nlp
    path = tmp_path / "phi.npz"
    if content == "wrong-size":
        np.savez(path, phi=np.zeros(7))
    elif content is not None:
        path.write_bytes(content)
    with pytest.raises(InputError) as info:
        build_nlp(load_scene("ellipse-2d", ["mesh.n=32", "initial.shape='file'", f"initial.file='{path}'"]))
    assert info.value.key == "initial.file" and "\n" not in str(info.value)


def _physical_scene(**constraints):
    return {"domain": {"box": [[-4, 4], [-4, 4]]}, "mesh": {"kind": "fd", "n": 16}, "model": {"epsilon": 0.3},
            "initial": {"shape": "circle", "radius": 1.0}, "constraints": constraints}


def test_reduced_volume_and_area_set_alpha_and_beta():
    sc = scene.from_dict(_physical_scene(reduced_volume=0.8, area=9.0))
    c = sc.constraints
    V = 0.8 * 9.0**2 / (4 * 3.141592653589793)  # nu = 4 pi V / S^2 (2D)
    assert c.alpha == pytest.approx(2 * V - 64.0, rel=1e-14)  # alpha = 2V - |Omega|: round-off only
    assert c.beta == pytest.approx(4 * 9.0 / (3 * 2**0.5), rel=1e-14)  # beta = 4S/(3 sqrt 2)
    assert (c.reduced_volume, c.area) == (0.8, 9.0)


@pytest.mark.parametrize("constraints, key", [
    ({"reduced_volume": 0.8}, "constraints.area"),
    ({"area": 9.0}, "constraints.reduced_volume"),
    ({"reduced_volume": 1.2, "area": 9.0}, "constraints.reduced_volume"),
    ({"reduced_volume": 0.0, "area": 9.0}, "constraints.reduced_volume"),
    ({"reduced_volume": float("nan"), "area": 9.0}, "constraints.reduced_volume"),
    ({"reduced_volume": 0.8, "area": -1.0}, "constraints.area"),
    ({"reduced_volume": 0.8, "area": 40.0}, "constraints.area"),  # V = 102 > |Omega| = 64
    ({"reduced_volume": 0.8, "area": 9.0, "alpha": 0.0}, "constraints.alpha"),
    ({"reduced_volume": 0.8, "area": 9.0, "beta": 1.0}, "constraints.beta"),
])
def test_bad_physical_targets_name_the_key(constraints, key):
    with pytest.raises(InputError) as info:
        scene.from_dict(_physical_scene(**constraints))
    assert info.value.key == key and "\n" not in str(info.value)
