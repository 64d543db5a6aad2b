"""State files through the checked loader (``io.state``): branch.csv / branch.json, a study's CSV, a
flow's checkpoint. A torn last line is repaired; anything else that does not parse or is another
run's is refused with one line naming the file, exit 2, the file untouched; no garbage row kept.
The hypothesis properties run a few examples by default and 10 000 each under ``-m slow``."""

import io
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vesicle_opt import cli
from vesicle_opt.branch.store import COLUMNS, Store, texts
from vesicle_opt.errors import InputError, StateFileError
from vesicle_opt.flows.api import fingerprint
from vesicle_opt.flows.run import write_flow
from vesicle_opt.flows.stepper import FlowState
from vesicle_opt.flows.trackers import CheckpointTracker
from vesicle_opt.io.state import read_csv
from vesicle_opt.scene.schema import from_dict
from vesicle_opt.studies.runner import CsvLog

META = {"scene": "small", "param": "reduced_volume", "to": 0.8}
RAW = {"domain": {"box": [[-4.0, 4.0], [-4.0, 4.0]], "boundary": "periodic"}, "mesh": {"kind": "fd", "n": 16},
       "model": {"epsilon": 0.6}, "constraints": {"reduced_volume": 0.95, "area": 8.0},
       "initial": {"shape": "ellipse", "semi_axes": [1.45, 1.1]},
       "flow": {"scheme": "penalty", "dt": 1e-3, "steps": 3}}


def branch_csv(n=3) -> str:
    rows = [{"point": k, "branch": 0, "param": "reduced_volume", "target": 0.95 - 0.01 * k, "energy": 5.0 + k,
             "second_order": "not checked", "converged": True, "accepted": True, "iterations": 3, "wraps": "none"}
            for k in range(n)]
    return ",".join(COLUMNS) + "\n" + "".join(",".join(texts(r)[c] for c in COLUMNS) + "\n" for r in rows)


def study_csv(study="s", n=2) -> str:
    log_cols = ["study", "scene", "energy", "status", "case", "case_rows"]
    lines = [",".join(log_cols)] + [f"{study},sc,{k}.5,ok,c{k},1" for k in range(n)]
    return "\n".join(lines) + "\n"


def _one_line(exc, path):
    msg = str(exc)
    assert "\n" not in msg and str(path) in msg, msg


# --- branch -----------------------------------------------------------------------------------

def test_a_torn_last_line_of_branch_csv_is_cut_and_the_rest_kept(tmp_path):
    text = branch_csv(3)
    (tmp_path / "branch.csv").write_text(text[:-25])  # a kill in the middle of the third row
    (tmp_path / "branch.json").write_text(json.dumps(META))
    rows = Store(tmp_path, META).rows()
    assert [r["point"] for r in rows] == [0, 1]
    assert (tmp_path / "branch.csv").read_text() == text[: text[:-25].rfind("\n") + 1]


@pytest.mark.parametrize("damage", [
    lambda t: t + "garbage,row\n",  # a garbage row ending in a newline (kept before: the resume "succeeded")
    lambda t: t.replace("\n1,0,", "\n1,zero,"),  # an integer column that is not
    lambda t: t.replace("\n2,0,", "\n7,0,"),  # a point out of order (another run's rows spliced in)
    lambda t: t.replace("true", "maybe", 1),
    lambda t: "a,b,c\n1,2,3\n",  # another file's columns
    lambda t: '"' + t[t.index("\n"):],  # a quote opening a field over every line (found by the slow fuzz)
])
def test_a_damaged_branch_csv_is_refused_and_left_untouched(tmp_path, damage):
    (tmp_path / "branch.csv").write_text(damage(branch_csv(3)))
    before = (tmp_path / "branch.csv").read_bytes()
    with pytest.raises(StateFileError) as info:
        Store(tmp_path, META)
    _one_line(info.value, tmp_path / "branch.csv")
    assert (tmp_path / "branch.csv").read_bytes() == before
    assert not (tmp_path / "branch.json").exists()  # nothing written for a refused run


@pytest.mark.parametrize("name", ["branch.csv", "branch.json"])
def test_garbage_bytes_in_a_branch_state_file_are_one_line_exit_2_through_the_cli(tmp_path, capsys, name):
    toml = tmp_path / "s.toml"
    toml.write_text('[domain]\nbox = [[-4.0, 4.0], [-4.0, 4.0]]\nboundary = "periodic"\n[mesh]\nkind = "fd"\n'
                    'n = 16\n[model]\nepsilon = 0.6\n[constraints]\nreduced_volume = 0.95\narea = 8.0\n'
                    '[initial]\nshape = "ellipse"\nsemi_axes = [1.45, 1.1]\n')
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_bytes(b"\xff\xfe\x00garbage\x89PNG\n" * 20)
    code = cli.main(["branch", str(toml), "--param", "reduced_volume", "--to", "0.9", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and name in err[0] and "another --out" in err[0], err
    assert (out / name).read_bytes() == b"\xff\xfe\x00garbage\x89PNG\n" * 20
    assert not (out / "points").exists() or not any((out / "points").iterdir())


# --- study CSV --------------------------------------------------------------------------------

def test_a_study_csv_with_a_torn_line_and_an_incomplete_case_is_repaired(tmp_path):
    path = tmp_path / "s.csv"
    path.write_text(study_csv() + "s,sc,9.5,ok,c9,2\n" + "s,sc,1")  # c9 has 1 of its 2 rows; a torn line
    log = CsvLog(path, study="s")
    assert log.done() == {"c0", "c1"}


@pytest.mark.parametrize("damage", [
    lambda t: t.replace("s,sc,1.5", "other,sc,1.5"),  # a row of another study
    lambda t: t + "\x00\x01\x02 binary\n",
    lambda t: t + "s,sc,1.5,ok\n",  # too few fields
    lambda t: t.replace("c1,1", "c1,x"),
    lambda t: "point,branch\n0,0\n",  # a branch.csv given as a study's
])
def test_a_damaged_or_foreign_study_csv_is_refused_and_left_untouched(tmp_path, damage):
    path = tmp_path / "s.csv"
    path.write_text(damage(study_csv()))
    before = path.read_bytes()
    with pytest.raises(StateFileError) as info:
        CsvLog(path, study="s")
    _one_line(info.value, path)
    assert path.read_bytes() == before


# --- flow checkpoint --------------------------------------------------------------------------

def _flow_dir(tmp_path, npz: bytes):
    sc = from_dict(RAW, "small")
    out = tmp_path / "out"
    out.mkdir()
    (out / "checkpoint.id").write_text(fingerprint(sc) + "\n")
    (out / "checkpoint.npz").write_bytes(npz)
    return sc, out


def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


GOOD = {"phi": np.zeros(256), "phi_prev": np.zeros(0), "t": 0.001, "step": 1, "k_try": 1e-3, "k_last": 1e-3,
        "rate0": np.nan, "rejections": 0, "wall_time_s": 0.1}


@pytest.mark.parametrize("npz", [
    b"PK\x03\x04 not really a zip",
    _npz(**{**GOOD, "phi": np.zeros(100)}),  # another grid's field
    _npz(**{**GOOD, "phi": np.array(["a"] * 256)}),  # another dtype
    _npz(**{k: v for k, v in GOOD.items() if k != "step"}),  # a key missing
    _npz(**{**GOOD, "fingerprint": np.array("0123456789abcdef")}),  # another problem's
    _npz(**{**GOOD, "phi": np.full(256, np.nan)}),
], ids=["not-a-zip", "shape", "dtype", "missing-key", "fingerprint", "non-finite"])
def test_a_corrupt_or_foreign_checkpoint_is_refused_before_any_work(tmp_path, npz):
    sc, out = _flow_dir(tmp_path, npz)
    with pytest.raises(StateFileError) as info:
        write_flow(sc, out, frames=False)
    _one_line(info.value, out / "checkpoint.npz")
    assert "--restart" in str(info.value)
    assert (out / "checkpoint.npz").read_bytes() == npz
    assert not (out / "history.csv").exists() and not (out / "summary.json").exists()


def test_the_cli_flow_refuses_a_garbage_checkpoint_with_one_line_exit_2(tmp_path, capsys):
    _, out = _flow_dir(tmp_path, b"\x00" * 64)
    toml = tmp_path / "s.toml"
    lines = []
    for section, body in RAW.items():
        lines.append(f"[{section}]")
        lines += [f"{k} = {json.dumps(v)}" for k, v in body.items()]
    toml.write_text("\n".join(lines) + "\n")
    code = cli.main(["flow", str(toml), "--out", str(out), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "checkpoint.npz" in err[0], err


def test_a_good_checkpoint_resumes(tmp_path):
    sc, out = _flow_dir(tmp_path, _npz(**GOOD))
    run = write_flow(sc, out, frames=False)
    assert run.summary["resumed_from_step"] == 1 and run.result.steps == 3


# --- fuzz (hypothesis) ------------------------------------------------------------------------

def _damage(data: st.DataObject, text: bytes, kinds=("truncate", "insert", "replace-line", "flip", "foreign")) -> bytes:
    kind = data.draw(st.sampled_from(kinds))
    if kind == "truncate":
        return text[: data.draw(st.integers(0, len(text)))]
    if kind == "insert":
        at = data.draw(st.integers(0, len(text)))
        return text[:at] + data.draw(st.binary(min_size=1, max_size=40)) + text[at:]
    if kind == "replace-line":
        lines = text.split(b"\n")
        k = data.draw(st.integers(0, len(lines) - 1))
        lines[k] = data.draw(st.one_of(st.binary(max_size=60), st.text(max_size=60).map(str.encode)))
        return b"\n".join(lines)
    if kind == "flip":
        b = bytearray(text)
        for _ in range(data.draw(st.integers(1, 5))):
            if b:
                b[data.draw(st.integers(0, len(b) - 1))] ^= data.draw(st.integers(1, 255))
        return bytes(b)
    return data.draw(st.sampled_from([branch_csv().encode(), study_csv("other").encode(), _npz(**GOOD),
                                      b"", b"\n\n", b'{"scene": 1}', b"\xef\xbb\xbfpoint\n"]))


FUZZ = settings(max_examples=30, deadline=None, suppress_health_check=list(HealthCheck))
FUZZ_SLOW = settings(max_examples=10_000, deadline=None, suppress_health_check=list(HealthCheck))


def _branch_property(tmp_path_factory, data):
    d = tmp_path_factory.mktemp("b")
    truncated = data.draw(st.booleans())  # a kill's damage, where the rows kept must be the original's
    damaged = _damage(data, branch_csv(4).encode(), ("truncate",) if truncated else ("insert", "replace-line",
                                                                                      "flip", "foreign"))
    (d / "branch.csv").write_bytes(damaged)
    (d / "branch.json").write_bytes(_damage(data, json.dumps(META).encode()) if data.draw(st.booleans())
                                    else json.dumps(META).encode())
    try:
        rows = Store(d, META).rows()
    except InputError as exc:  # StateFileError, or a branch.json of other arguments
        assert "\n" not in str(exc)
        assert (d / "branch.csv").read_bytes() == damaged  # untouched
        return
    again = read_csv(d / "branch.csv", lambda h: None, lambda r, k: None, "")  # the repaired file reads whole
    assert again is None or again[2] is None
    assert [r["point"] for r in rows] == list(range(len(rows)))
    # whole original rows only, whatever the damage: a flipped digit that still reads as a number is
    # found by the row's checksum (branch.store's row_crc)
    original = branch_csv(4).splitlines()
    kept = (d / "branch.csv").read_text().splitlines()
    assert kept == original[: len(kept)]


def _study_property(tmp_path_factory, data):
    d = tmp_path_factory.mktemp("s")
    damaged = _damage(data, study_csv("s", 3).encode())
    (d / "s.csv").write_bytes(damaged)
    try:
        log = CsvLog(d / "s.csv", study="s")
    except StateFileError as exc:
        assert "\n" not in str(exc) and (d / "s.csv").read_bytes() == damaged
        return
    assert all(r["study"] == "s" and r["case_rows"].isdigit() for r in log.rows())


def _checkpoint_property(tmp_path_factory, data):
    d = tmp_path_factory.mktemp("c")
    damaged = _damage(data, _npz(**GOOD))
    (d / "checkpoint.npz").write_bytes(damaged)
    try:
        st_ = CheckpointTracker.load(d / "checkpoint.npz", "f" * 16, 256)
    except StateFileError as exc:
        assert "\n" not in str(exc) and (d / "checkpoint.npz").read_bytes() == damaged
        return
    assert isinstance(st_, FlowState) and st_.phi.shape == (256,) and np.all(np.isfinite(st_.phi))


PROPERTIES = [_branch_property, _study_property, _checkpoint_property]


@pytest.mark.parametrize("prop", PROPERTIES, ids=lambda p: p.__name__.strip("_"))
@FUZZ
@given(data=st.data())
def test_fuzz_a_damaged_state_file_is_refused_or_repaired(prop, tmp_path_factory, data):
    prop(tmp_path_factory, data)


@pytest.mark.slow
@pytest.mark.parametrize("prop", PROPERTIES, ids=lambda p: p.__name__.strip("_"))
@FUZZ_SLOW
@given(data=st.data())
def test_fuzz_a_damaged_state_file_is_refused_or_repaired_10000(prop, tmp_path_factory, data):
    prop(tmp_path_factory, data)
