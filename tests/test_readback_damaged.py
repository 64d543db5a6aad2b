"""Damaged output directories read back through the API (``vo.load`` and friends) raise the named
``StateFileError`` (an ``InputError``) naming the file, never a raw exception or a half-parsed
object: every file goes through the checked loader of the state files (``io.state``). The good
files of each verb still read, and a torn last CSV line (a killed run's) is read past with a warning.
The hypothesis property runs a few examples by default and 10 000 under ``-m slow``."""

import json
import logging
import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import vesicle_opt as vo
from vesicle_opt import cli
from vesicle_opt.branch.store import COLUMNS, texts
from vesicle_opt.errors import InputError, StateFileError
from vesicle_opt.readback import read_csv

SMALL = ["--set", "mesh.n=32", "-q"]  # the ellipse at 32^2: a solve in ~0.5 s, a 3-step flow in less
META = {"scene": "small", "param": "reduced_volume", "to": 0.9, "step": -0.01, "stopped": {"0": "reached"}}


def _branch_csv(n=3) -> str:
    rows = [{"point": k, "branch": 0, "param": "reduced_volume", "target": 0.95 - 0.01 * k, "energy": 5.0 + k,
             "converged": True, "accepted": True, "iterations": 3} for k in range(n)]
    return ",".join(COLUMNS) + "\n" + "".join(",".join(texts(r)[c] for c in COLUMNS) + "\n" for r in rows)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One directory per verb: solve and flow written by the CLI, branch and study files as they write them."""
    base = tmp_path_factory.mktemp("runs")
    assert cli.main(["solve", "ellipse-2d", "--out", str(base / "solve"), *SMALL]) == 0
    assert cli.main(["flow", "ellipse-2d", "--steps", "3", "--out", str(base / "flow"), *SMALL]) == 0
    (base / "branch").mkdir()
    (base / "branch" / "branch.csv").write_text(_branch_csv())
    (base / "branch" / "branch.json").write_text(json.dumps(META))
    (base / "study").mkdir()
    (base / "study" / "cases.csv").write_text("n,energy,converged\n32,1.5,true\n64,1.25,false\n")
    (base / "study" / "summary_fit.json").write_text('{"order": 2.0}')
    return base


@pytest.fixture
def copy(runs, tmp_path):
    def make(verb):
        shutil.copytree(runs / verb, tmp_path / verb)
        return tmp_path / verb
    return make


def test_the_good_files_of_each_verb_read(copy):
    assert isinstance(vo.load(copy("solve")), vo.Result)
    assert vo.load(copy("flow")).steps == 3
    b = vo.load(copy("branch"))
    assert [r["point"] for r in b.rows] == [0, 1, 2] and b.rows[2]["energy"] == 7.0 and b.stopped == {0: "reached"}
    rec = vo.load(copy("study"))
    assert rec.tables["cases"][1] == {"n": 64, "energy": 1.25, "converged": False}


GARBAGE = b"\x89PNG\r\n\x1a\n\xff\xfe garbage \x00\x01"
# (verb, file, new content or a function of the old bytes, what the message says)
CASES = [
    ("solve", "summary.json", GARBAGE, "not a text file"),
    ("solve", "summary.json", b"[1, 2]", "not a JSON object"),
    ("solve", "summary.json", b'{"energy": 1.0}', "has no 'outcome'"),
    ("solve", "summary.json", lambda b: json.dumps({**json.loads(b), "iterations": "many"}).encode(), "wrong type"),
    ("solve", "summary.json", lambda b: json.dumps({**json.loads(b), "outcome": "sideways"}).encode(), "wrong type"),
    ("solve", "phi.npz", GARBAGE, "not an npz file"),
    ("solve", "phi.npz", lambda b: _npz(phi=np.array(["a", "b"])), "array 'phi'"),
    ("solve", "phi.npz", lambda b: _npz(phi=np.zeros(4), nodes=np.zeros((3, 2))), "'nodes' has 3 entries"),
    ("solve", "phi.npz", lambda b: _npz(phi=np.zeros(4), kind=np.str_("painting")), "kind 'painting'"),
    ("flow", "summary.json", lambda b: json.dumps({**json.loads(b), "steps": [3]}).encode(), "wrong type"),
    ("flow", "phi.npz", lambda b: _npz(phi=np.zeros(4), kind=np.str_("flow")), "no 'nodes' or 't'"),
    ("flow", "history.csv", lambda b: b + b"1,2\n", "fields, the header"),
    ("flow", "history.csv", lambda b: b[:40] + GARBAGE + b[40:], "not a text file"),
    ("branch", "branch.csv", GARBAGE, "not a text file"),
    ("branch", "branch.csv", lambda b: b.replace(b"\n1,0,", b"\nX,0,"), "point = 'X'"),
    ("branch", "branch.csv", lambda b: b.replace(b",6.0,", b",6.O,"), "energy = '6.O' is not a number"),
    ("branch", "branch.csv", lambda b: b + b"garbage row\n", "fields, the header"),
    ("branch", "branch.csv", lambda b: b.replace(b"point,branch", b"pt,branch"), "unknown columns 'pt'"),
    ("branch", "branch.json", GARBAGE, "not a text file"),
    ("branch", "branch.json", b'{"scene": "small"', "not JSON"),
    ("branch", "branch.json", json.dumps({**META, "to": "far"}).encode(), "wrong type"),
    ("branch", "branch.json", json.dumps({**META, "stopped": {"zero": "reached"}}).encode(), "wrong type"),
    ("branch", "branch.json", json.dumps({"scene": "small"}).encode(), "has no 'param'"),
    ("study", "cases.csv", GARBAGE, "not a text file"),
    ("study", "cases.csv", b"n,energy\n1,2,3\n", "fields, the header"),
    ("study", "cases.csv", b"n,n\n1,2\n", "a column named twice"),
    ("study", "cases.csv", b'n,energy\n1,"2\n', "not a CSV file"),
    ("study", "summary_fit.json", b"\x00{}", "not a text file"),
]


def _npz(**arrays) -> bytes:
    import io
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


@pytest.mark.parametrize("verb, name, content, says", CASES, ids=[f"{c[0]}-{c[1]}-{k}" for k, c in enumerate(CASES)])
def test_a_damaged_file_raises_the_named_error_naming_it(copy, verb, name, content, says):
    d = copy(verb)
    path = d / name
    path.write_bytes(content(path.read_bytes()) if callable(content) else content)
    before = path.read_bytes()
    with pytest.raises(StateFileError) as info:
        vo.load(d)
    msg = str(info.value)
    assert str(path) in msg and says in msg and "\n" not in msg, msg
    assert info.value.key == "path" and isinstance(info.value, InputError)
    assert path.read_bytes() == before  # reading never repairs or rewrites


def test_a_torn_last_line_is_read_past_with_a_warning(copy, caplog):
    d = copy("branch")
    (d / "branch.csv").write_text(_branch_csv()[:-7])  # a kill mid-row: the third row torn
    with caplog.at_level(logging.WARNING, logger="vesicle_opt"):
        b = vo.load_branch(d)
    assert [r["point"] for r in b.rows] == [0, 1]
    assert any("torn" in r.getMessage() and "branch.csv" in r.getMessage() for r in caplog.records)
    assert (d / "branch.csv").read_text() == _branch_csv()[:-7]  # not rewritten by a read


def test_read_csv_and_missing_files(copy, tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_csv(tmp_path / "none.csv")
    d = copy("solve")
    (d / "phi.npz").unlink()
    assert np.isnan(vo.load(d).phi).all()  # a summary without its field (as before): no phi to show
    d = copy("branch")
    (d / "branch.csv").unlink()
    with pytest.raises(InputError, match="no branch.csv"):
        vo.load(d)


# --- fuzz (hypothesis): any damage of any file of any verb's directory -----------------------------

FILES = {"solve": ("summary.json", "phi.npz", "scene.resolved.toml"),
         "flow": ("summary.json", "phi.npz", "history.csv"),
         "branch": ("branch.csv", "branch.json"), "study": ("cases.csv", "summary_fit.json")}


def _damage(data, text: bytes) -> bytes:
    kind = data.draw(st.sampled_from(("truncate", "insert", "flip", "replace")))
    if kind == "truncate":
        return text[: data.draw(st.integers(0, len(text)))]
    if kind == "insert":
        at = data.draw(st.integers(0, len(text)))
        return text[:at] + data.draw(st.binary(min_size=1, max_size=40)) + text[at:]
    if kind == "flip":
        b = bytearray(text)
        for _ in range(data.draw(st.integers(1, 5))):
            if b:
                b[data.draw(st.integers(0, len(b) - 1))] ^= data.draw(st.integers(1, 255))
        return bytes(b)
    return data.draw(st.sampled_from([b"", b"{}", b"[]", b"null", b"a,b\n1\n", _branch_csv().encode(),
                                      json.dumps(META).encode(), _npz(phi=np.zeros(3))]))


def _property(runs, tmp_path_factory, data):
    verb = data.draw(st.sampled_from(sorted(FILES)))
    d = tmp_path_factory.mktemp("fz") / verb
    shutil.copytree(runs / verb, d)
    name = data.draw(st.sampled_from(FILES[verb]))
    (d / name).write_bytes(_damage(data, (d / name).read_bytes()))
    try:
        vo.load(d, disc=False) if verb == "solve" else vo.load(d)
    except InputError as exc:  # StateFileError, or the scene's own InputError for a damaged TOML
        assert "\n" not in str(exc), str(exc)


FUZZ = settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))
FUZZ_SLOW = settings(max_examples=10_000, deadline=None, suppress_health_check=list(HealthCheck))


@FUZZ
@given(data=st.data())
def test_fuzz_a_damaged_directory_reads_or_raises_the_named_error(runs, tmp_path_factory, data):
    _property(runs, tmp_path_factory, data)


@pytest.mark.slow
@FUZZ_SLOW
@given(data=st.data())
def test_fuzz_a_damaged_directory_reads_or_raises_the_named_error_10000(runs, tmp_path_factory, data):
    _property(runs, tmp_path_factory, data)
