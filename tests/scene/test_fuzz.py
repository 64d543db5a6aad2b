"""Property-based fuzzing of the scene boundary (hypothesis): generated scene dicts and ``--set``
strings (wrong types, NaN/inf, huge and tiny numbers, wrong shapes, unknown keys) either validate
or raise the project's InputError, never any other exception; a scene that validates also passes
or fails the resource guard and the backend choice with InputError only.

The default run is short (a few seconds); ``-m slow`` runs 10 000 examples of each property.
"""

import copy
import math
import tomllib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vesicle_opt import resources
from vesicle_opt.backends import choose_backend
from vesicle_opt.errors import InputError
from vesicle_opt.scene import bundled
from vesicle_opt.scene.schema import SCHEMA, apply_overrides, from_dict
from vesicle_opt.scene.shape_spec import SHAPE_KEYS, SHAPES

BASES = {name: tomllib.loads(bundled.text(name)) for name in bundled.names()}
KEYS = sorted(SCHEMA) + [f"initial.{k}" for k in SHAPE_KEYS] + [f"constraints.target.{k}" for k in SHAPE_KEYS]
NASTY_FLOATS = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, 5e-324, 1e-300, 1e300, 1.7e308,
                                -1e300, 1e-16, 2.0**63, -1.0])
NUMBERS = st.one_of(st.integers(min_value=-2**70, max_value=2**70), st.floats(allow_nan=True), NASTY_FLOATS,
                    st.sampled_from([0, 1, 3, 4, 16, 2**31, 2**63 - 1, 10**30]))
LEAVES = st.one_of(NUMBERS, st.booleans(), st.text(max_size=12), st.sampled_from(list(SHAPES)),
                   st.sampled_from(["fd", "spectral", "fem-p1", "periodic", "natural", "exact", "penalty",
                                    "newton-krylov", "auto", "lagrange", "file"]))
VALUES = st.recursive(LEAVES, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                      st.dictionaries(st.sampled_from(list(SHAPE_KEYS) + ["x"]),
                                                                      inner, max_size=3)), max_leaves=8)
KEY_NAMES = st.one_of(st.sampled_from(KEYS), st.text(alphabet="abcdefghij._", min_size=1, max_size=14))


def _judge(fn):
    """Run fn: a result or InputError is fine; anything else propagates and fails the property."""
    try:
        return fn()
    except InputError as exc:
        assert "\n" not in str(exc)  # one line
        assert str(exc).split(":", 1)[0]  # names a key
        return None


def _downstream(sc) -> None:
    """A valid scene: the backend choice and the resource guard answer, or refuse with InputError."""
    if sc is None:
        return
    for backend in (None, "ipopt", "newton-krylov", "auto"):
        chosen = _judge(lambda: choose_backend(sc, backend))
        if chosen is not None:
            _judge(lambda: resources.check(sc, chosen))
    _judge(lambda: resources.check(sc, "flow"))


def _set_dotted(d: dict, key: str, value) -> None:
    parts = key.split(".")
    for p in parts[:-1]:
        nxt = d.get(p)
        if not isinstance(nxt, dict):
            nxt = d[p] = {}
        d = nxt
    d[parts[-1]] = value


@st.composite
def scene_dicts(draw):
    raw = copy.deepcopy(BASES[draw(st.sampled_from(sorted(BASES)))])
    for _ in range(draw(st.integers(1, 4))):
        key = draw(KEY_NAMES)
        if draw(st.booleans()) and "." in key:
            _set_dotted(raw, key, draw(VALUES))
        else:
            section = key.split(".")[0]
            raw[section] = draw(VALUES) if draw(st.integers(0, 5)) == 0 else raw.get(section, {})
            if isinstance(raw[section], dict) and "." in key:
                _set_dotted(raw, key, draw(VALUES))
    return raw


TOML_TEXT = st.one_of(st.text(max_size=20), st.sampled_from(
    ["nan", "inf", "-inf", "1e400", "1e-400", "[1, 2, 3]", "[[0, 1]]", "{shape = 'file'}", "'spectral'",
     "true", "[]", "{}", "0", "-1", "9223372036854775807", "18446744073709551616", "1e-320", "[nan, 1]",
     "{shape = 'circle', radius = nan}", "{shape = 'ellipse', semi_axes = [1e308, 1e308]}", "= =", "'"]))


@st.composite
def set_strings(draw):
    items = []
    for _ in range(draw(st.integers(1, 4))):
        key = draw(KEY_NAMES)
        items.append(draw(st.sampled_from([f"{key}={draw(TOML_TEXT)}", f"{key}={draw(VALUES)!r}", key, f"={key}"])))
    return draw(st.sampled_from(sorted(BASES))), items


FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SLOW = settings(max_examples=10_000, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _check_dict(raw):
    _downstream(_judge(lambda: from_dict(raw)))


def _check_sets(case):
    name, items = case
    _downstream(_judge(lambda: from_dict(apply_overrides(copy.deepcopy(BASES[name]), items), name=name)))


@FAST
@given(scene_dicts())
def test_scene_dicts_validate_or_raise_input_error(raw):
    _check_dict(raw)


@FAST
@given(set_strings())
def test_set_strings_validate_or_raise_input_error(case):
    _check_sets(case)


@pytest.mark.slow
@SLOW
@given(scene_dicts())
def test_scene_dicts_10000(raw):
    _check_dict(raw)


@pytest.mark.slow
@SLOW
@given(set_strings())
def test_set_strings_10000(case):
    _check_sets(case)
