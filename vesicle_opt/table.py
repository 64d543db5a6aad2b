"""CSV result tables that survive a kill: rows are appended and flushed as they finish, and a
re-run skips the rows already present (keyed by chosen columns). The one CSV writer of the project.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path


class CsvTable:
    def __init__(self, path: str | Path, columns: list[str], key: tuple[str, ...]):
        self.path = Path(path)
        self.columns = list(columns)
        self.key = key
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._done: set[tuple[str, ...]] = set()
        if self.path.exists() and self.path.stat().st_size > 0:
            with self.path.open(newline="") as fh:
                reader = csv.DictReader(fh)
                if reader.fieldnames != self.columns:  # a table of another layout: keep it, start anew
                    self.path.rename(self.path.with_suffix(".old.csv"))
                else:
                    self._done = {tuple(row[k] for k in key) for row in reader}
        if not self.path.exists():
            with self.path.open("w", newline="") as fh:
                csv.writer(fh).writerow(self.columns)

    @staticmethod
    def _fmt(value) -> str:
        if value is None:
            return ""
        if isinstance(value, float):
            return repr(value) if math.isfinite(value) else ""
        return str(value)

    def key_of(self, case: dict) -> tuple[str, ...]:
        return tuple(self._fmt(case[k]) for k in self.key)

    def done(self, case: dict) -> bool:
        return self.key_of(case) in self._done

    def append(self, row: dict) -> None:
        with self.path.open("a", newline="") as fh:
            csv.writer(fh).writerow([self._fmt(row.get(c)) for c in self.columns])
            fh.flush()
        self._done.add(self.key_of(row))

    def rows(self) -> list[dict]:
        with self.path.open(newline="") as fh:
            return list(csv.DictReader(fh))
