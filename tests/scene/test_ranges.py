"""One validation that cannot be bypassed: every ranged scene key refused the same way by the TOML
path (the CLI's ``--set``) and by ``Scene.replace`` / ``dataclasses.replace`` on its section."""

import dataclasses
import tomllib

import pytest

from vesicle_opt.errors import InputError
from vesicle_opt.scene import load
from vesicle_opt.scene.ranges import CHOICES, EPS_PER_H_RECOMMENDED, resolution_warning
from vesicle_opt.scene.bundled import resolve
from vesicle_opt.scene.schema import SCHEMA, from_dict

# key -> an out-of-range value for ellipse-2d (box [-4, 4]^2, FD 128^2, eps = 0.2)
BAD = {
    "model.epsilon": 100.0, "model.rigidity": 0.0, "constraints.beta": -1.0, "constraints.area": 0.0,
    "constraints.reduced_volume": 1.5, "constraints.alpha": 1e9,
    "solver.M": 1e13, "solver.tol": 1.0, "solver.max_iter": 0, "solver.second_order_max_iter": 0,
    "solver.M0": 0.0, "solver.M_factor": 1.0, "solver.M_max": 1e13, "solver.max_outer": 0,
    "solver.max_memory_gb": -1.0,
    "flow.gamma": 0.0, "flow.dt": -1e-3, "flow.t_end": 0.0, "flow.steps": 0, "flow.dt_min": 0.0,
    "flow.dt_max": 0.0, "flow.steady_tol": -1.0, "flow.law_tol": 0.0, "flow.frames": 0,
    "flow.checkpoint_every": 0, "mesh.n": 2, "mesh.levels": 9, "mesh.band": 2.0,
}
RANGED = [k for k, (kind, _, allowed) in SCHEMA.items()
          if kind in ("float", "float/auto", "int", "ints") and allowed != "any real"]


def test_every_ranged_key_has_a_bad_value():
    assert sorted(RANGED) == sorted(BAD)


def _replace(scene, key, value):
    section, field = key.split(".")
    if key == "mesh.n":
        value = (value,) * scene.dim
    if section == "constraints" and field in ("reduced_volume", "area"):
        other = {"reduced_volume": 0.9, "area": 8.0}
        other[field] = value
        return scene.replace(constraints=dataclasses.replace(scene.constraints, **other))
    return scene.replace(**{section: dataclasses.replace(getattr(scene, section), **{field: value})})


@pytest.mark.parametrize("key", sorted(BAD))
def test_out_of_range_refused_by_the_cli_path_and_by_replace_alike(key):
    scene = load("ellipse-2d")
    value = BAD[key]
    with pytest.raises(InputError) as via_replace:
        _replace(scene, key, value)
    assert via_replace.value.key == key
    with pytest.raises(InputError) as via_load:
        if key in ("constraints.reduced_volume", "constraints.area"):  # the pair, in place of the target
            raw = tomllib.loads(resolve("ellipse-2d")[1])
            raw["constraints"] = {"reduced_volume": 0.9, "area": 8.0, key.split(".")[1]: value}
            from_dict(raw)
        else:
            load("ellipse-2d", [f"{key}={value}"])
    assert via_load.value.key == key
    if key not in ("mesh.n", "constraints.alpha"):  # load's message names the integer / the list form
        assert str(via_load.value) == str(via_replace.value)


def test_the_issue_case_tol_1_is_refused_by_the_api():
    from vesicle_opt.api import solve
    scene = load("ellipse-2d")
    with pytest.raises(InputError, match="solver.tol"):  # before: converged=True at kkt 0.049
        solve(scene.replace(solver=dataclasses.replace(scene.solver, tol=1.0)))


@pytest.mark.parametrize("key", sorted(CHOICES))
def test_every_choice_key_refused_by_replace(key):
    scene = load("ellipse-2d")
    with pytest.raises(InputError) as exc:
        _replace(scene, key, "nonsense")
    assert exc.value.key == key


def test_cross_section_checks_on_replace():
    scene = load("ellipse-2d")
    with pytest.raises(InputError, match="model.epsilon"):  # eps below h / 10 once the mesh is coarsened
        scene.replace(mesh=dataclasses.replace(scene.mesh, n=(4, 4)), model=dataclasses.replace(scene.model, epsilon=0.01))
    with pytest.raises(InputError, match="domain.boundary"):
        scene.replace(domain=dataclasses.replace(scene.domain, boundary="natural"),
                      mesh=dataclasses.replace(scene.mesh, kind="fd"))


def test_resolution_warning_below_the_recommended_eps_over_h():
    fine = load("ellipse-2d")
    h = (fine.domain.box[0][1] - fine.domain.box[0][0]) / fine.mesh.n[0]
    assert fine.model.epsilon / h >= EPS_PER_H_RECOMMENDED and resolution_warning(fine) is None
    coarse = load("ellipse-2d", ["mesh.n=16"])
    line = resolution_warning(coarse)
    assert line is not None and "raise mesh.n" in line


def test_cli_warns_before_the_solve(capsys, tmp_path):
    from vesicle_opt.cli import main
    main(["solve", "ellipse-2d", "--set", "mesh.n=32", "--set", "solver.second_order=false", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    warn = err.index("epsilon / h = 0.8 is below the recommended 2")
    assert warn < err.index("method exact")  # before the solve's first line


def test_the_choices_checked_are_the_schemas():
    """scene.ranges.CHOICES (checked in __post_init__) lists what the key table allows, key by key
    (a kind added to the table only, mesh.kind = 'axisymmetric', was refused by the dataclass)."""
    from vesicle_opt.scene import ranges
    from vesicle_opt.scene.schema import SCHEMA
    for key, allowed in ranges.CHOICES.items():
        assert tuple(SCHEMA[key][2]) == tuple(allowed), key


def test_cli_flow_warns_once_after_its_refusals(capsys, tmp_path):
    """The flow verb's eps / h warning comes from write_flow after the state files' checks (a refused
    checkpoint is one line alone: tests/io/test_state.py), once per run."""
    from vesicle_opt.cli import main
    assert main(["flow", "ellipse-2d", "--set", "mesh.n=16", "--steps", "1", "-q", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert err.count("epsilon / h = 0.4 is below the recommended 2") == 1, err  # eps 0.2, h = 8/16


def test_solver_M_is_auto_by_default_or_a_number():
    """solver.M = 'auto' (the default): the penalty method's choice, starting at M_DEFAULT; a number is
    kept as given (an explicit 1e4 is no longer taken for the default); any other string is refused
    by both paths with the same InputError."""
    from vesicle_opt.scene.ranges import M_AUTO, M_DEFAULT
    scene = load("ellipse-2d")
    assert scene.solver.M == M_AUTO and scene.solver.M_auto and scene.solver.M_value == M_DEFAULT
    given = load("ellipse-2d", ["solver.M=1e4"])
    assert given.solver.M == 1e4 and not given.solver.M_auto and given.solver.M_value == 1e4
    assert load("ellipse-2d", ["solver.M='auto'"]).solver == scene.solver
    with pytest.raises(InputError) as via_load:
        load("ellipse-2d", ["solver.M='big'"])
    with pytest.raises(InputError) as via_replace:
        _replace(scene, "solver.M", "big")
    assert via_load.value.key == via_replace.value.key == "solver.M"
    assert "'auto'" in str(via_load.value) and "'auto'" in str(via_replace.value)


def test_replacing_the_physical_targets_alone_is_refused_and_with_overrides_rederives_them():
    """``Scene.replace`` of ``constraints.reduced_volume`` kept the alpha, beta derived from the old
    value and solved at the old volume without a word; it is refused now, naming the key."""
    from vesicle_opt.geometry import targets
    sc = load("prolate-axisymmetric")
    with pytest.raises(InputError) as err:
        sc.replace(constraints=dataclasses.replace(sc.constraints, reduced_volume=0.7))
    assert err.value.key == "constraints.reduced_volume" and "with_overrides" in str(err.value)
    moved = sc.with_overrides({"constraints.reduced_volume": 0.7})
    alpha, beta = targets(0.7, sc.constraints.area, 3, sc.domain.volume)
    assert (moved.constraints.alpha, moved.constraints.beta) == (alpha, beta)  # the same formula, bit for bit


def test_resolution_warning_is_silent_at_exactly_the_recommended_eps_over_h():
    """eps / h = 2 exactly on paper, 1.9999999 by the box's float division (0.03 / (1.44 / 24 / 4)):
    no warning that "2 is below the recommended 2"."""
    sc = load("oblate-axisymmetric")
    assert resolution_warning(sc) is None
    coarse = sc.with_overrides({"mesh.levels": 1})  # eps / h = 1
    assert "epsilon / h = 1" in resolution_warning(coarse)
