"""API conventions: overrides as a mapping or KEY=VALUE strings (and a clear refusal otherwise),
``Scene.with_overrides``, physical targets replacing the other ones, the unscaled objective of
``NLP.as_dict(scaled=False)``, and a docstring and annotations on every public callable."""

import inspect
import logging

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt import cli
from vesicle_opt.model import functionals


def test_overrides_mapping_list_and_refusal():
    a = vo.load_scene("ellipse-2d", {"mesh.n": 64, "model.epsilon": 0.3})
    b = vo.load_scene("ellipse-2d", ["mesh.n=64", "model.epsilon=0.3"])
    assert a == b and a.mesh.n == (64, 64)
    with pytest.raises(vo.InputError, match=r"^overrides: expected a mapping .*got 'mesh.n=64'$"):
        vo.load_scene("ellipse-2d", "mesh.n=64")  # a bare string was iterated character by character
    with pytest.raises(vo.InputError, match="overrides"):
        vo.load_scene("ellipse-2d", [("mesh.n", 64)])
    with pytest.raises(vo.InputError, match="unknown scene key 'mesh.nn'"):
        vo.load_scene("ellipse-2d", {"mesh.nn": 64})


def test_with_overrides_is_load_with_the_same_keys():
    base = vo.load_scene("sphere-3d")
    assert base.with_overrides({"mesh.n": 8, "solver.tol": 1e-9}) == vo.load_scene("sphere-3d", ["mesh.n=8", "solver.tol=1e-9"])
    assert base.with_overrides({}) == base  # the resolved table round-trips
    with pytest.raises(vo.InputError, match="solver.tol"):
        base.with_overrides({"solver.tol": 1.0})


def test_physical_targets_replace_alpha_beta(caplog):
    with caplog.at_level(logging.INFO, logger="vesicle_opt"):
        sc = vo.load_scene("circle-2d", ["constraints.reduced_volume=0.8", "constraints.area=8"])
    assert any("constraints.target dropped" in r.getMessage() for r in caplog.records)
    assert sc.constraints.reduced_volume == 0.8 and sc.constraints.area == 8.0
    # the targets they mean (geometry.targets, Section 3.1): 2D, V = nu S^2 / (4 pi), alpha = 2 V - |Omega|
    V = 0.8 * 64 / (4 * np.pi)
    assert sc.constraints.alpha == pytest.approx(2 * V - sc.domain.volume, rel=1e-14)  # round-off
    assert sc.constraints.beta == pytest.approx(4 * 8 / (3 * np.sqrt(2)), rel=1e-14)  # round-off
    # and back: alpha/beta replace a scene's physical targets
    with caplog.at_level(logging.INFO, logger="vesicle_opt"):
        back = sc.with_overrides({"constraints.alpha": -40.0, "constraints.beta": 8.0})
    assert back.constraints.reduced_volume is None and back.constraints.alpha == -40.0
    assert "constraints.reduced_volume, constraints.area dropped" in caplog.records[-1].getMessage()


def test_cli_physical_targets_on_a_bundled_scene(tmp_path, capsys):
    # ellipse-2d's own target: nu 0.915 at perimeter 9.66 (32^2); a nearby one keeps the solve short
    args = ["solve", "ellipse-2d", "--set", "constraints.reduced_volume=0.9", "--set", "constraints.area=9.6",
            "--set", "mesh.n=32", "--out", str(tmp_path)]
    assert cli.main(args) == 0  # not refused as bad input (2): it was "give either ... not both"
    assert "the scene's constraints.target dropped" in capsys.readouterr().err
    assert vo.load(tmp_path).reduced_volume == pytest.approx(0.9, abs=1e-6)  # constraint held to tol


def test_as_dict_unscaled_objective_is_the_energy():
    import casadi as ca
    sc = vo.load_scene("ellipse-2d", ["mesh.n=24"])
    nlp = vo.build_nlp(sc)
    f_unscaled = ca.Function("f", [nlp.x, nlp.p], [nlp.as_dict(scaled=False)["f"]])
    f_scaled = ca.Function("f", [nlp.x, nlp.p], [nlp.as_dict()["f"]])
    p = np.zeros(nlp.p.shape[0])
    E = functionals.evaluate(nlp.disc, nlp.x0, sc.model.epsilon, sc.model.C)["E"] * sc.model.rigidity
    # the numpy energy of the same field (an independent evaluation): equal to round-off
    assert float(f_unscaled(nlp.x0, p)) == pytest.approx(E, rel=1e-12)
    assert float(f_scaled(nlp.x0, p)) * nlp.f_scale == pytest.approx(E, rel=1e-12)
    assert abs(nlp.f_scale - 1.0) > 1e-3  # the scale is not the identity: the docstring's warning matters


def _public_callables():
    for name in vo.__all__:
        obj = getattr(vo, name)
        if inspect.isfunction(obj):
            yield name, obj
        elif inspect.isclass(obj) and obj.__module__.startswith("vesicle_opt") and not issubclass(obj, Exception):
            yield name, obj
            for attr, member in vars(obj).items():
                if attr.startswith("_"):
                    continue
                member = member.fget if isinstance(member, property) else member
                member = member.__func__ if isinstance(member, (staticmethod, classmethod)) else member
                if inspect.isfunction(member):
                    yield f"{name}.{attr}", member


def test_public_api_has_docstrings_and_annotations():
    missing = []
    for name, obj in _public_callables():
        if not inspect.getdoc(obj):
            missing.append(f"{name}: no docstring")
        if inspect.isfunction(obj):
            sig = inspect.signature(obj)
            for p, par in sig.parameters.items():
                if p in ("self", "cls") or par.kind in (par.VAR_KEYWORD, par.VAR_POSITIONAL):
                    continue
                if par.annotation is inspect.Parameter.empty:
                    missing.append(f"{name}: parameter {p} not annotated")
            if sig.return_annotation is inspect.Signature.empty:
                missing.append(f"{name}: return not annotated")
    assert not missing, "\n".join(missing)


def test_solve_list_names_every_bundled_scene(capsys):
    from vesicle_opt.scene import bundled
    assert cli.main(["solve", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == bundled.names() and all(len(ln.split()) > 2 for ln in lines)
    assert cli.main(["solve"]) == 2  # neither a scene nor --list: one line, bad input


@pytest.mark.parametrize("args", [["study", "energy_diagram", "--help"], ["--help"], ["study", "--list"]])
def test_no_broken_pipe_traceback(args):
    import subprocess
    import sys
    # a reader that closes at once (`| head -0`): the writer must end quietly with status 0
    p = subprocess.Popen([sys.executable, "-m", "vesicle_opt", *args], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 0 and "Traceback" not in err and "BrokenPipe" not in err, err


def test_study_summaries_print_for_people_not_as_reprs():
    from vesicle_opt.studies._common import human
    line = human({"points": 5, "certified": 5, "crossing": {"v": 0.651234567, "eps": [0.1, 0.2]}, "x": None})
    assert line == "points 5, certified 5, crossing (v 0.651235, eps 0.1, 0.2), x none"
    assert "{" not in line and "'" not in line  # no dict repr
