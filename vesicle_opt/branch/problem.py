"""The rows side of a tree of branches (``branch.tree``): walks, points and event rows on a Store.

``TreeProblem`` holds what every problem of a diagram shares: the store (``branch.store``), the
walk of one branch (``branch.arclength``, resumed from its rows), the accepted points as
``events.Point`` (the fields from the snapshots, the least few eigenvalues from the row), and the
rows of a located event and of a switched branch's start. A subclass gives the numerics:
``correct(k)`` and ``free_attempt(k)`` (the walk's correctors, ``arclength.Attempt`` with the
solver's result as payload), optionally ``tangent(k)`` (the start's dphi/dp: a tangent first
step), ``row(k, step)`` -> (row, result), ``solve``, ``free``, ``mode``, ``align`` and ``deflate``
(``branch.tree`` module docstring), and ``point_row(k, point, corrector)``:
the row of a certified Point.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace
from typing import Callable

import numpy as np

from vesicle_opt.branch import arclength as arc
from vesicle_opt.branch.events import Located, Point, index


def joined(values) -> str | None:
    return None if values is None else ";".join(repr(float(x)) for x in values)


def split(text) -> tuple[float, ...]:
    return () if text in (None, "") else tuple(float(x) for x in str(text).split(";"))


class TreeProblem:
    """Rows, walks and points of a diagram (module docstring). Set ``store``, ``s`` (the root's
    ``arclength.Settings``), ``weights``, ``start`` (the root's start value) and ``progress``."""

    store = s = weights = start = progress = disc = param = None

    @property
    def step(self) -> float:
        return self.s.step

    def rows(self) -> list[dict]:
        return self.store.rows()

    def phi(self, point: int) -> np.ndarray:
        return self.store.phi(point)

    def point_of_row(self, r: dict) -> Point:
        lam = None if r.get("lambda_volume") is None else (r["lambda_volume"], r["lambda_area"])
        eig = split(r.get("second_order_eigenvalues"))
        if not eig and r.get("second_order_min_eigenvalue") is not None:
            eig = (r["second_order_min_eigenvalue"],)
        return Point(r["target"], self.phi(r["point"]), r["energy"], eig, split(r.get("second_order_errors")),
                     lam, r)

    def points(self, k: int) -> list[Point]:
        return [self.point_of_row(r) for r in self.rows() if r["branch"] == k and r["accepted"]]

    def theta(self, k: int) -> float:
        th = [r["arc_theta"] for r in self.rows() if r["branch"] == k and r.get("arc_theta")]
        return th[-1] if th else 1.0

    def load_mode(self, row: dict) -> np.ndarray | None:
        return self.store.mode(row["point"])

    def settings(self, k: int) -> tuple[arc.Settings, float]:
        """(settings, p_start) of branch k: the root's; a switched branch's towards the end of the
        diagram's range its first step points to (from its branch point)."""
        mine = [r for r in self.rows() if r["branch"] == k]
        if k == 0 or not mine or mine[0]["corrector"] != "branch point":
            return self.s, (self.start if not mine else mine[0]["target"])
        p0 = mine[0]["target"]
        p1 = mine[1]["target"] if len(mine) > 1 else p0
        lo, hi = sorted((self.start, self.s.to))
        to = hi if p1 > p0 else lo if p1 < p0 else self.s.to
        if to == p0:
            to = lo if to == hi else hi
        return dataclasses.replace(self.s, to=to, step=math.copysign(abs(self.s.step), to - p0)), p0

    def walk(self, k: int, p_start: float | None, stop: Callable | None = None) -> str:
        """Walk (or resume) branch k; why it stopped."""
        s, p0 = self.settings(k)
        mine = [r for r in self.rows() if r["branch"] == k and r["corrector"] != "locate"]
        recs = [{"p": r["target"], "phi": self.phi(r["point"]) if r["accepted"] else None,
                 "accepted": r["accepted"], "arc_step": r["arc_step"], "theta": r["arc_theta"]} for r in mine]
        track = arc.replay(s.step, recs) if recs else None
        _, why = arc.walk(s, p0 if p_start is None else p_start, self.correct(k), self.weights, track,
                          self.record(k), free=self.free_attempt(k), stop=stop, tangent=self.tangent(k))
        return why

    def tangent(self, k: int) -> Callable | None:
        """dphi/dp at branch k's start, ``(p, phi) -> array or None`` (``arclength.advance``: the first
        step along it, p free), or None: the first step a natural one. None here; a subclass with a
        p-free corrector may give it."""
        return None

    def record(self, k: int) -> Callable:
        def rec(st: arc.Step):
            row, res = self.row(k, st)
            self.append({**row, "parent": self.parent_of(k)}, res)
        return rec

    def append(self, row: dict, res=None, mode=None) -> None:
        row = {**row, "point": len(self.rows())}
        if res is not None and "second_order_eigenvalues" not in row:
            ex = getattr(res, "extra", {}) or {}
            row["second_order_eigenvalues"] = joined(ex.get("second_order_eigenvalues"))
            row["second_order_errors"] = joined(ex.get("second_order_errors"))
            if ex.get("second_order_eigenvalues") is not None:
                row["index"] = index(ex["second_order_eigenvalues"], ex.get("second_order_errors") or ())
        self.store.append(row, res, mode)
        if self.progress is not None:
            self.progress(self.rows()[-1])

    def record_event(self, k: int, detected: int, loc: Located, mode) -> None:
        if loc.point is not None:
            row, res = self.point_row(k, loc.point, "locate")
        else:  # no solve (the parabola's vertex): the reduced energy in the detected point's unit
            at = self.rows()[detected]
            unit = at["reduced_energy"] / at["energy"] if at.get("reduced_energy") and at.get("energy") else None
            row, res = {"branch": k, "param": self.param, "target": loc.p, "energy": loc.energy,
                        "reduced_energy": None if unit is None else loc.energy * unit,
                        "converged": False, "accepted": False, "corrector": "locate"}, None
        row.update({"accepted": False, "event": loc.kind, "detected_at": detected, "critical": loc.critical,
                    "critical_eigenvalue": loc.eigenvalue, "critical_error": loc.error, "solves": loc.solves,
                    "located_by": loc.located_by, "bracket": loc.bracket, "parent": self.parent_of(k),
                    "critical_mode": None if mode is None else f"point-{len(self.rows()):04d}.npz:mode"})
        self.append(row, res, mode)

    def parent_of(self, k: int):
        first = next((r for r in self.rows() if r["branch"] == k), None)
        return None if first is None else first.get("parent")

    def record_start(self, cid: int, parent: int | None, event: dict | None, pt: Point | None, how: str,
                     same: int | None) -> None:
        """The first rows of branch cid: its branch point (a copy of the event's located point, when
        there is one) and the switched (or deflated) point, or a row saying why there is none."""
        done = any(r["branch"] == cid for r in self.rows())  # its branch point row, before a kill
        if event is not None and str(event.get("located_by")) in ("illinois", "chord") and not done:
            row = {k: v for k, v in event.items() if k not in ("critical_mode", "located_by", "bracket", "critical",
                                                                "critical_eigenvalue", "critical_error")}
            row.update({"branch": cid, "corrector": "branch point", "accepted": same is None and pt is not None,
                        "parent": parent, "detected_at": event["point"], "arc_step": abs(self.s.step),
                        "arc_theta": None, "solves": 0, "iterations": 0, "wall_time_s": 0.0,
                        "event": f"from branch point at point {event['point']}"})
            self.append(row, SimpleNamespace(phi=self.phi(event["point"]), disc=self.disc, history={}))
        base = {"branch": cid, "param": self.param, "parent": parent, "corrector": "switch" if event else "deflation",
                "accepted": False, "converged": False}
        if pt is None:
            self.append({**base, "target": event["target"] if event else self.start, "event": f"none found: {how}"})
            return
        row, res = self.point_row(cid, pt, base["corrector"])
        if event is None:
            row["arc_step"] = abs(self.s.step)
        row.update({"parent": parent, "status": how, "accepted": same is None,
                    "event": f"known: branch {same}" if same is not None else ("deflation" if event is None else how)})
        if event is not None and same is None:  # the secant from the branch point: the walk's start
            th = self.theta(parent)
            dphi = pt.phi - self.phi(event["point"])
            row["arc_theta"] = th
            row["arc_step"] = min(math.hypot(th * math.sqrt(float(np.dot(self.weights, dphi * dphi))),
                                             pt.p - event["target"]), math.sqrt(2.0) * abs(self.s.step))
        self.append(row, res)
