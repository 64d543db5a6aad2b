"""``row_crc``, the last column of branch.csv (``branch.store``): a character changed inside a row is
found on resume and on read-back (a swapped digit that still reads as a number included); a timing
is left out of it; a branch.csv of the previous column set resumes, rewritten with the checksums.
And a damaged branch.json beside it (what the fuzz found) is another run's, refused in one line."""

import json

import pytest

import vesicle_opt as vo
from vesicle_opt.branch.store import CHECKSUM, COLUMNS, Store, texts
from vesicle_opt.errors import InputError, StateFileError

META = {"scene": "small", "param": "reduced_volume", "to": 0.8}


def _rows(n=3):
    return [{"point": k, "branch": 0, "param": "reduced_volume", "target": 0.95 - 0.01 * k,
             "energy": 5.25 + 1.5 * k, "converged": True, "accepted": True, "iterations": 3 + k,
             "wall_time_s": 0.125 * (k + 1), "second_order": "not checked"} for k in range(n)]


def _csv(rows, columns=COLUMNS) -> str:
    return ",".join(columns) + "\n" + "".join(",".join(texts(r)[c] for c in columns) + "\n" for r in rows)


def _resume(d, text):
    (d / "branch.csv").write_text(text)
    (d / "branch.json").write_text(json.dumps(META))
    return Store(d, META).rows()


def test_every_changed_character_of_a_row_is_refused_naming_its_line(tmp_path):
    """Each position of row 2 (the third line) changed to another digit or letter, one at a time:
    every change but those inside wall_time_s is refused, with the line named; the file untouched."""
    good = _csv(_rows())
    lines = good.splitlines(keepends=True)
    head = "".join(lines[:2])
    row = lines[2]
    cells = row.rstrip("\n").split(",")
    wall = COLUMNS.index("wall_time_s")
    start = len(",".join(cells[:wall])) + 1
    in_wall = range(start, start + len(cells[wall]))
    refused = accepted = 0
    for i, ch in enumerate(row.rstrip("\n")):
        if ch == "," or i in in_wall:
            continue
        new = "7" if ch != "7" else "3"
        text = head + row[:i] + new + row[i + 1:] + "".join(lines[3:])
        with pytest.raises(StateFileError) as info:
            _resume(tmp_path, text)
        assert "branch.csv: line 3:" in str(info.value), (i, str(info.value))
        assert (tmp_path / "branch.csv").read_text() == text  # untouched
        refused += 1
    # the timing: another value there is no damage the checksum claims to see (it differs on reruns)
    text = head + row[:start] + "9.5" + row[start + len(cells[wall]):] + "".join(lines[3:])
    assert [r["wall_time_s"] for r in _resume(tmp_path, text)] == [0.125, 9.5, 0.375]
    accepted += 1
    assert refused > 40 and accepted == 1  # the row has ~50 characters outside its timing


def test_a_swapped_digit_that_still_reads_as_a_number_is_refused_on_read_back(tmp_path):
    good = _csv(_rows())
    swapped = good.replace(",8.25,", ",8.52,")  # point 2's energy, digits swapped: still a number
    assert swapped != good
    (tmp_path / "branch.csv").write_text(swapped)
    (tmp_path / "branch.json").write_text(json.dumps({**META, "step": -0.01}))
    with pytest.raises(StateFileError, match=f"line 4: {CHECKSUM}"):
        vo.load_branch(tmp_path)
    (tmp_path / "branch.csv").write_text(good)
    assert [r["energy"] for r in vo.load_branch(tmp_path).rows] == [5.25, 6.75, 8.25]


def test_a_branch_csv_of_the_previous_columns_resumes_with_its_checksums_added(tmp_path):
    old = _csv(_rows(), COLUMNS[:-1])
    assert CHECKSUM not in old.splitlines()[0]
    rows = _resume(tmp_path, old)
    assert [r["point"] for r in rows] == [0, 1, 2] and rows[1]["energy"] == 6.75
    assert (tmp_path / "branch.csv").read_text() == _csv(_rows())  # rewritten whole, the column last
    assert [r[CHECKSUM] for r in rows] == [texts(r)[CHECKSUM] for r in _rows()]
    assert Store(tmp_path, META).rows() == rows  # and it resumes again as written


@pytest.mark.parametrize("stored", [{**META, "to": 0.9}, {**META, "to": 0.7, "step": "x"}, {**META, "to": [0.7]}])
def test_a_branch_json_without_a_numeric_to_or_step_is_another_run(tmp_path, stored):
    """Found by the 10 000-example fuzz of tests/io/test_state.py: a stored branch.json whose ``to``
    differs and whose ``step`` is missing or not a number raised KeyError / ValueError in
    ``extends``; it is another run's file, refused with one line, untouched."""
    (tmp_path / "branch.json").write_text(json.dumps(stored))
    with pytest.raises(InputError, match="other") as info:
        Store(tmp_path, {**META, "step": -0.01})
    assert "\n" not in str(info.value)
    assert json.loads((tmp_path / "branch.json").read_text()) == stored
