"""Run a study's cases through any ``concurrent.futures.Executor`` into one resumable CSV.

* A *case* is a dict of plain values with a unique ``case`` id; a module-level function (picklable)
  turns it into a list of rows (dicts). Cases run on ``executor`` (default: a local process pool;
  a ``dask.distributed`` ``Client(...).get_executor()`` works unchanged).
* ONE writer, in the calling process, appends each finished case's rows to the CSV in a single
  write, flushed and fsynced at once; every row carries ``case`` and ``case_rows`` (how many rows
  the case has), so a case is finished iff all its rows are in the file.
* Re-running resumes: a torn last line (a kill mid-write) is cut off, rows of incomplete cases are
  dropped, and finished cases are skipped. Every row is therefore in the file exactly once.
* Progress (``show_progress``): cases done / total with an ETA and the last case's wall time on
  stderr (``io.progress.bar``: tqdm on a terminal, one plain line per finished case otherwise).
* No orphans: the runner's own pools (``process_pool``) start workers that watch their parent and
  exit within ``PARENT_POLL_S`` once it is gone, however it ended (SIGKILL included: no handler
  of the parent runs then, so the workers themselves must notice; a re-parented process sees a
  new ``os.getppid()``). The watch starts in the pool's initializer, after a spawned worker's
  imports: a worker killed-around while still importing exits as soon as its imports end.
* Interrupts (SIGINT, SIGTERM; ``io.interrupt``): the workers ignore SIGINT (a Ctrl-C reaches the
  whole process group; the parent alone decides), and the parent, interrupted, terminates its own
  pool's workers at once instead of waiting for their cases; no row of an unfinished case is
  written, so the rerun resumes after the last finished one.
"""

from __future__ import annotations

import contextlib
import csv
import gc
import io
import logging
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from vesicle_opt.errors import InputError
from vesicle_opt.io import interrupt, progress
from vesicle_opt.io.files import json_safe, write_json
from vesicle_opt.io.state import read_csv

COLUMNS = ["study", "scene", "method", "n", "h", "M", "energy", "volume_residual", "area_residual",
           "lambda_volume", "lambda_area", "error_h1", "error_energy", "iterations", "wall_time_s",
           "status"]
BOOKKEEPING = ["case", "case_rows"]
FAILURE = ["outcome", "reason", "certifiable_tol"]  # a row that failed says how and why (``failed_line``); after the
# bookkeeping columns, so that the rows of a CSV written before them keep their places
PARENT_POLL_S = 0.5  # a worker notices its parent's death within this (the SIGKILL test allows a few s)
SCHEDULER_TIMEOUT_S = 10.0  # a dask scheduler that does not answer in this long is bad input (``dask_executor``)
TERMINATE_WAIT_S = 5.0  # a SIGTERMed worker is gone in ~10 ms; a bound, so an interrupt never hangs


def _exit_with_parent(parent_pid: int, log_level: int | None = None) -> None:
    """Pool initializer: a daemon thread ends this worker at once when ``parent_pid`` is gone; with
    ``log_level``, the worker's ``vesicle_opt`` logger at the parent's level (``worker_logging``)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides (module docstring)
    if log_level is not None:
        worker_logging(log_level)

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(1)  # the parent is gone: nobody will read this worker's result
    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def terminate(executor: Executor) -> None:
    """End a process pool's workers now (SIGTERM) and drop its queued work: what an interrupted
    parent does to its own pool instead of ``shutdown(wait=True)``, which waits for every running
    case. ``_processes`` is the pool's private table of its workers (CPython's, 3.8 to 3.13)."""
    procs = list((getattr(executor, "_processes", None) or {}).values())
    for proc in procs:
        try:
            proc.terminate()
        except (OSError, ValueError):  # already gone
            pass
    for proc in procs:
        proc.join(timeout=TERMINATE_WAIT_S)
    # with the workers gone the pool's manager thread ends at once; joining it drops the pool's last
    # references to its queues, whose semaphores the collection then unlinks (the CLI leaves by
    # os._exit, where no finalizer runs: the resource tracker would warn of leaked semaphores)
    closer = threading.Thread(target=executor.shutdown, kwargs={"wait": True, "cancel_futures": True},
                              name="pool-shutdown", daemon=True)
    closer.start()
    closer.join(timeout=TERMINATE_WAIT_S)
    gc.collect()


def process_pool(workers: int = 1, log_level: int | None = None, **kwargs) -> ProcessPoolExecutor:
    """A spawn-context process pool whose workers end with this process (module docstring) and log
    at ``log_level`` (the parent's, for a study's own pool)."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                               initializer=_exit_with_parent, initargs=(os.getpid(), log_level), **kwargs)


class CsvLog:
    """The single appending writer of a study CSV (see the module docstring). ``study``: the
    study's name, which every row of an existing file must carry (another study's CSV is refused)."""

    def __init__(self, path: Path, extra_columns: Iterable[str] = (), study: str | None = None):
        self.path = Path(path)
        self.study = study
        extra = [c for c in extra_columns if c not in COLUMNS]
        self.columns = COLUMNS + extra + BOOKKEEPING + [c for c in FAILURE if c not in extra]
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._repair()

    def _check_header(self, header: list[str]) -> str | None:
        missing = [c for c in ("study", *BOOKKEEPING) if c not in header]
        if missing:
            return f"no {', '.join(missing)} column"
        if len(set(header)) != len(header) or "" in header:
            return "empty or repeated column names"
        return None

    def _check_row(self, row: dict, index: int) -> str | None:
        if not row["case"] or not row["case_rows"].isdigit() or int(row["case_rows"]) < 1:
            return f"case {row['case'][:40]!r} with case_rows {row['case_rows'][:40]!r} (a row of no case)"
        if self.study is not None and row["study"] != self.study:
            return f"a row of the study {row['study'][:40]!r}, not {self.study!r}"
        return None

    def _repair(self) -> None:
        """Read the file through the checked loader (``io.state``): a torn last line is cut, the
        rows of incomplete cases (a kill between two cases' writes) dropped, the header of an
        existing file kept; anything else is refused before any work, the file untouched."""
        found = read_csv(self.path, self._check_header, self._check_row,
                         "move it away or give another --out (nothing there was changed)")
        if found is None:
            self.path.write_text(",".join(self.columns) + "\n")
            return
        header, rows, _ = found
        counts: dict[str, int] = {}
        for r in rows:
            counts[r.get("case", "")] = counts.get(r.get("case", ""), 0) + 1
        keep = [r for r in rows if (r.get("case_rows") or "").isdigit()
                and counts[r["case"]] == int(r["case_rows"])]
        if set(header) != set(self.columns):  # an older layout: keep its columns, add the new ones
            self.columns = header + [c for c in self.columns if c not in header]
        self._rewrite(keep)

    def _rewrite(self, rows: list[dict]) -> None:
        buf = io.StringIO()
        w = csv.DictWriter(buf, self.columns, extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(buf.getvalue())
        tmp.replace(self.path)

    def rows(self) -> list[dict]:
        with open(self.path, newline="") as f:
            return list(csv.DictReader(f))

    def done(self) -> set[str]:
        return {r["case"] for r in self.rows()}

    def append(self, case: str, rows: list[dict]) -> None:
        buf = io.StringIO()
        w = csv.DictWriter(buf, self.columns, extrasaction="ignore", lineterminator="\n")
        for r in rows:
            w.writerow({**{k: _fmt(v) for k, v in r.items()}, "case": case, "case_rows": len(rows)})
        with open(self.path, "a", newline="") as f:
            f.write(buf.getvalue())
            f.flush()
            os.fsync(f.fileno())


def _fmt(v):
    """Plain text for numpy scalars too (full precision floats, no 'np.float64(...)')."""
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, np.integer):
        return int(v)
    return v


def run_cases(study: str, cases: list[dict], fn: Callable[[dict], list[dict]], csv_path: Path,
              executor: Executor | None = None, workers: int = 1, show_progress: bool = True,
              extra_columns: Iterable[str] = ()) -> list[dict]:
    """Run the unfinished ``cases`` with ``fn`` and append their rows; returns all rows of the CSV.

    Rows get ``study`` filled in. A case that raises is recorded as one row with status
    ``error: ...`` (so it is not retried forever; delete its row to retry).
    """
    ids = [c["case"] for c in cases]
    if len(set(ids)) != len(ids):
        raise ValueError(f"case ids are not unique in {study}")
    log = CsvLog(csv_path, extra_columns, study)
    finished = log.done()
    todo = [c for c in cases if c["case"] not in finished]
    total, done = len(cases), len(cases) - len(todo)
    bar = progress.bar(study, total=total, unit="cases", interval=0.0, force=show_progress)
    interrupt.note(f"after {done} of {total} cases of {study}", resume=True)
    bar.update(done)
    if done:
        bar.set_postfix_str(f"{done} done before (resumed)")
    if not todo:
        bar.close()
        return log.rows()
    own = executor is None
    if own:
        executor = process_pool(workers, log_level=logging.getLogger("vesicle_opt").getEffectiveLevel())
    try:
        futures = {executor.submit(_timed, fn, c): c for c in todo}
        for fut in as_completed(futures):
            case = futures[fut]
            try:
                rows, wall = fut.result()
            except Exception as exc:  # noqa: BLE001 - recorded in the CSV, never silently dropped
                rows, wall = [{"scene": case.get("scene", ""), "method": case.get("method", ""),
                               "status": f"error: {type(exc).__name__}: {exc}"[:200]}], float("nan")
            log.append(case["case"], [{"study": study, **r} for r in rows])
            for r in rows:  # a failure said where it happens: on the console beside its CSV row
                if (line := failed_line(study, case["case"], r)) is not None:
                    logging.getLogger(__name__).warning("%s", line)
            done += 1
            interrupt.note(f"after {done} of {total} cases of {study}", resume=True)
            bar.set_postfix_str(f"last {case['case']} ({wall:.1f} s)")
            bar.update(1)
    except KeyboardInterrupt:  # SIGINT/SIGTERM (io.interrupt): the workers end now, not after their case
        if own:
            terminate(executor)
            own = False
        raise
    finally:
        bar.close()
        if own:
            executor.shutdown(wait=True, cancel_futures=True)
    return log.rows()


def failed_line(study: str, case: str, row: dict) -> str | None:
    """One line for a row that is not a certified result (``converged`` false with an ``outcome``,
    or a case that raised): the outcome and its reason (for a round-off floor the tol that can be
    certified, ``verify.certify``); None for a certified row or one that certifies nothing."""
    status = str(row.get("status") or "")
    if status.startswith("error: "):
        return f"{study} {case}: {status}"
    outcome, converged = row.get("outcome"), row.get("converged")
    if outcome in (None, "", "converged") or converged in (None, "", True, "True"):
        return None
    where = " ".join(f"{k}={row[k]}" for k in ("scene", "method", "n", "target") if row.get(k) not in (None, ""))
    why = f" ({row['reason']})" if row.get("reason") else ""
    if row.get("certifiable_tol") not in (None, "") and "can be certified" not in why:
        why += f"; tol >= {float(row['certifiable_tol']):.0e} can be certified"
    return f"{study} {case}{' ' + where if where else ''}: {outcome}{why}"


def run_into(name: str, case_list: list[dict], fn: Callable[[dict], list[dict]], out, executor: Executor | None = None,
             workers: int = 1, extra_columns: Iterable[str] = ()) -> tuple[Path, list[dict], list[dict]]:
    """A study's run: ``out`` made, ``run_cases`` into ``out/<name>.csv`` (resumable); returns
    (``out`` as a Path, every row, the rows of the cases that did not raise: status not ``error...``)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = run_cases(name, case_list, fn, out / f"{name}.csv", executor=executor, workers=workers,
                     extra_columns=extra_columns)
    return out, rows, [r for r in rows if not str(r.get("status", "")).startswith("error")]


def run_study(name: str, case_list: list[dict], fn: Callable[[dict], list[dict]], summary: Callable,
              out: Path, executor: Executor | None = None, workers: int = 1,
              extra_columns: Iterable[str] = ()) -> tuple[list[dict], dict]:
    """A branch study's run: ``run_cases`` into ``out/<name>.csv`` (resumable), then
    ``summary(rows, case_list)`` written to ``out/<name>.json`` (non-finite floats as null);
    returns (rows, summary)."""
    out.mkdir(parents=True, exist_ok=True)
    rows = run_cases(name, case_list, fn, out / f"{name}.csv", executor=executor, workers=workers,
                     extra_columns=extra_columns)
    info = summary(rows, case_list)
    write_json(out / f"{name}.json", json_safe(info))
    return rows, info


@contextlib.contextmanager
def dask_executor(address: str):
    """The executor of the dask scheduler at ``address`` (``distributed.Client(address).get_executor()``:
    its workers run the cases; they need this package installed), the client closed after. InputError
    (key ``scheduler``) when dask.distributed is not installed (the ``dask`` extra) or no scheduler
    answers there within ``SCHEDULER_TIMEOUT_S``, before any case runs."""
    if not isinstance(address, str) or not address.strip():
        raise InputError("scheduler", f"a dask scheduler address such as tcp://host:8786, got {address!r}")
    try:
        from distributed import Client  # the optional ``dask`` extra: loaded for --scheduler only
    except ImportError:
        raise InputError("scheduler", "needs dask.distributed: pip install 'vesicle-opt[dask]'") from None
    try:
        client = Client(address, timeout=f"{SCHEDULER_TIMEOUT_S}s")
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise InputError("scheduler", f"no dask scheduler at {address!r} ({type(exc).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else 'no answer'})") from None
    try:
        yield client.get_executor()
    finally:
        client.close()


def worker_logging(level: int) -> None:
    """A spawned worker's ``vesicle_opt`` logger at the parent's level, to stderr (a spawned process
    starts with no handler, so a case's log lines would otherwise be dropped)."""
    logger = logging.getLogger("vesicle_opt")
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(handler)
    logger.setLevel(level)


def in_fresh_process(fn: Callable, *args):
    """``fn(*args)`` in a new spawned process, so that its peak memory (ru_maxrss) is its own."""
    pool = process_pool(1)
    try:
        result = pool.submit(fn, *args).result()
    except KeyboardInterrupt:  # interrupted: the worker ends now (``terminate``)
        terminate(pool)
        raise
    pool.shutdown(wait=True)
    return result


def _timed(fn, case):
    t0 = time.perf_counter()
    rows = fn(case)
    return rows, time.perf_counter() - t0
