"""Every public function of ``vesicle_opt`` given arguments of the wrong type or an impossible path:
a named exception of ``vesicle_opt.errors`` (``VesicleError``), never a raw TypeError, ValueError,
AttributeError or FileNotFoundError, and before any work (hypothesis; a few examples by default,
10 000 each under ``-m slow``). Also the operating system's limits at the boundary: a name over
255 characters, an unreadable scene path."""

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import vesicle_opt as vo
from vesicle_opt import cli
from vesicle_opt.errors import InputError, VesicleError
from vesicle_opt.studies import STUDIES

SCENE = vo.load_scene("ellipse-2d", ["mesh.n=16"])
WRONG = st.one_of(st.none(), st.integers(), st.floats(allow_nan=True), st.booleans(), st.binary(max_size=8),
                  st.lists(st.integers(), max_size=3), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
                  st.just(object()), st.text(max_size=12))
LONG = "a" * 300  # over the 255-byte limit of a path component (ext4, tmpfs, xfs...)


def _named(fn):
    try:
        fn()
    except VesicleError as exc:
        assert "\n" not in str(exc), str(exc)
        return exc
    return None


CALLS = {
    "load_scene": lambda a: vo.load_scene(a),
    "solve": lambda a: vo.solve(a),
    "solve x0": lambda a: vo.solve(SCENE, x0=a),
    "build_nlp": lambda a: vo.build_nlp(a),
    "flow": lambda a: vo.flow(a),
    "branch scene": lambda a: vo.branch(a, "reduced_volume", 0.9),
    "branch param": lambda a: vo.branch(SCENE, a, 0.9),
    "branch to": lambda a: vo.branch(SCENE, "reduced_volume", a),
    "run_study name": lambda a: vo.run_study(a, "never-made"),
}


def _refused(call, arg):
    """A wrong argument ends in a VesicleError; the few that are right by accident (a number that is
    a valid --to, a str that names a bundled scene) are not called with the solve behind them."""
    if call == "branch to" and isinstance(arg, (int, float)) and not isinstance(arg, bool) \
            and math.isfinite(arg) and 0 < arg <= 1:
        return
    if call == "solve x0" and arg is None:  # the default: no warm start
        return
    if call == "run_study name" and isinstance(arg, str) and arg.replace("-", "_") in STUDIES:
        return  # a registered study's name, which hypothesis finds among the module's strings (it ran one)
    if call in ("load_scene",) and isinstance(arg, str):
        return _named(lambda: CALLS[call](arg))
    exc = _named(lambda: CALLS[call](arg))
    assert exc is not None, f"{call}({arg!r}) was accepted"


@pytest.mark.parametrize("call", sorted(CALLS))
@settings(max_examples=8, deadline=None, suppress_health_check=list(HealthCheck))
@given(arg=WRONG)
def test_fuzz_a_wrong_argument_is_a_named_exception(call, arg):
    _refused(call, arg)


@pytest.mark.slow
@pytest.mark.parametrize("call", sorted(CALLS))
@settings(max_examples=10_000, deadline=None, suppress_health_check=list(HealthCheck))
@given(arg=WRONG)
def test_fuzz_a_wrong_argument_is_a_named_exception_10000(call, arg):
    _refused(call, arg)


def test_run_study_with_an_impossible_out_is_named_before_any_work(tmp_path):
    """Before: a raw FileNotFoundError (the directory below a file)."""
    blocker = tmp_path / "file"
    blocker.write_text("keep")
    for out in (blocker / "below", tmp_path / LONG, None, 3):
        with pytest.raises(InputError) as info:
            vo.run_study("penalty_continuation", out, quick=True)
        assert info.value.key == "out" and "\n" not in str(info.value)
    assert blocker.read_text() == "keep" and sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_load_scene_none_is_named():
    """Before: a raw TypeError from Path(None)."""
    with pytest.raises(InputError, match="scene"):
        vo.load_scene(None)


@pytest.mark.parametrize("argv, key", [
    (["solve", "ellipse-2d", "--out", f"out/{LONG}/x"], "--out"),  # before: an OSError traceback
    (["solve", f"{LONG}.toml"], "scene"),
    (["study", "penalty_continuation", "--quick", "--out", LONG], "--out"),
])
def test_a_path_over_the_name_limit_is_one_line_exit_2(argv, key, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith(f"vesicle-opt: error: {key}:"), err
    assert "name too long" in err[0].lower()


@pytest.mark.parametrize("call", ["load_scene", "solve x0", "branch param", "run_study name"])
def test_a_value_with_a_newline_is_refused_in_one_line(call):
    """Found by the 10 000-example run: the value echoed in the message broke it over two lines."""
    exc = _named(lambda: CALLS[call]("a\nb\r"))
    assert exc is not None and "a\\nb\\r" in str(exc)
