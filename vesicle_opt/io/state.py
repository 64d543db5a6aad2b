"""The state files a run resumes from, read through one checked loader.

``branch.csv`` / ``branch.json`` (``branch.store``), a study's CSV (``studies.runner``) and a flow's
``checkpoint.npz`` (``flows.trackers``) are read here before any work. The one repair is the one a
kill leaves: a torn last line (no newline at its end) is cut off (``read_csv`` says so; the caller
writes the repaired text). Anything else that does not parse (bytes that are not UTF-8, a line
with another number of fields than the header, a value of the wrong type, an npz that is not a
zip or lacks a key) or belongs to another run (other columns, another study's rows, another
problem's fingerprint, another shape or dtype) is a ``StateFileError``: one line naming the file,
what is wrong and what to do; the file is not touched. A garbage row is never kept, so a resume
never reports success over it.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Callable

import numpy as np

from vesicle_opt.errors import StateFileError

CheckRow = Callable[[dict, int], "str | None"]  # (row, index) -> what is wrong, or None


def read_text(path: Path, advice: str, key: str = "--out") -> str:
    """The text of ``path`` as UTF-8 (no NUL bytes), or a StateFileError."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise StateFileError(path, f"cannot be read ({exc.strerror or exc}); {advice}", key) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise StateFileError(path, f"is not a text file (byte {exc.start} is not UTF-8); {advice}", key) from None
    if "\x00" in text:
        raise StateFileError(path, f"is not a text file (it holds NUL bytes); {advice}", key)
    return text


def read_csv(path: Path, check_header: Callable[[list[str]], "str | None"], check_row: CheckRow,
             advice: str, key: str = "--out") -> tuple[list[str], list[dict], str | None] | None:
    """(header, rows, repaired text or None) of the CSV ``path``; None when it is missing or holds
    nothing (not even a whole header line). The repaired text is the file without its torn last
    line (module docstring); every other defect is a StateFileError naming the line."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return None
    text = read_text(path, advice, key)
    repaired = None
    if not text.endswith("\n"):  # a kill mid-write: the torn line is cut off
        text = repaired = text[: text.rfind("\n") + 1]
    if not text:
        return None
    try:
        lines = list(csv.reader(io.StringIO(text, newline=""), strict=True))  # an open quote: an error
    except csv.Error as exc:
        raise StateFileError(path, f"is not a CSV file ({exc}); {advice}", key) from None
    header = lines[0]
    why = check_header(header)
    if why is not None:
        raise StateFileError(path, f"its header is not this run's ({why}); {advice}", key)
    rows = []
    for k, fields in enumerate(lines[1:]):
        if len(fields) != len(header):
            raise StateFileError(path, f"line {k + 2} has {len(fields)} fields, the header {len(header)}; {advice}",
                                 key)
        row = dict(zip(header, fields))
        why = check_row(row, k)
        if why is not None:
            raise StateFileError(path, f"line {k + 2}: {why}; {advice}", key)
        rows.append(row)
    return header, rows, repaired


def is_number(text: str, kind: type = float) -> bool:
    """Whether ``text`` reads as a ``kind`` (int: digits with an optional sign; float: finite or not)."""
    try:
        kind(text)
    except ValueError:
        return False
    return True


def typed_row(row: dict, ints=(), floats=(), bools=()) -> str | None:
    """What is wrong with ``row``'s typed columns ('' is an empty value, allowed everywhere)."""
    for keys, kind, ok in ((ints, "an integer", lambda v: is_number(v, int)),
                           (floats, "a number", is_number), (bools, "true or false", lambda v: v in ("true", "false"))):
        for key in keys:
            value = row.get(key, "")
            if value != "" and not ok(value):
                return f"{key} = {value[:40]!r} is not {kind}"
    return None


def read_json(path: Path, advice: str, key: str = "--out") -> dict:
    """The JSON object of ``path``, or a StateFileError."""
    text = read_text(path, advice, key)
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise StateFileError(path, f"is not JSON ({exc.msg} at line {exc.lineno}); {advice}", key) from None
    except RecursionError:  # brackets nested past the parser's depth: no run writes that
        raise StateFileError(path, f"is not JSON (nested too deep); {advice}", key) from None
    if not isinstance(data, dict):
        raise StateFileError(path, f"is not a JSON object (a {type(data).__name__}); {advice}", key)
    return data


def read_npz(path: Path, keys: dict[str, tuple[str, int | None]], advice: str, key: str = "--out",
             optional: dict[str, tuple[str, int | None]] | None = None) -> dict:
    """The arrays of ``path`` (0-d ones as Python scalars). ``keys``: name -> (dtype kind, ndim or
    None), each checked ('f' finite floats, 'n' finite numbers, 'x' any numbers, nan included, 'i'
    integers, 'U' text); ``optional``: the same for keys that may be absent; other keys are kept
    unchecked. A StateFileError when the file is not an npz, a key is missing, or a kind, dimension
    or value is wrong."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except Exception as exc:  # noqa: BLE001 - np.load of damaged bytes raises many types (zip, zlib,
        # struct, header parsing, MemoryError for a forged shape): each means "not a checkpoint"
        raise StateFileError(path, f"is not an npz file ({type(exc).__name__}: {str(exc)[:80]}); {advice}",
                             key) from None
    for name, (kind, ndim) in {**keys, **{k: v for k, v in (optional or {}).items() if k in data}}.items():
        if name not in data:
            raise StateFileError(path, f"has no array {name!r} (it holds {', '.join(sorted(data)) or 'none'}); "
                                 f"{advice}", key)
        a = data[name]
        kinds = {"f": "f", "n": "fiu", "x": "fiu", "i": "iu", "U": "U"}[kind]
        if a.dtype.kind not in kinds or (ndim is not None and a.ndim != ndim):
            raise StateFileError(path, f"array {name!r} is {a.dtype} of shape {a.shape}, not this run's; {advice}",
                                 key)
        if kind in "fn" and not np.all(np.isfinite(a)):
            raise StateFileError(path, f"array {name!r} has non-finite values; {advice}", key)
    return {k: (a.item() if a.ndim == 0 else a) for k, a in data.items()}
