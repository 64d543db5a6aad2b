"""The tree of branches of a diagram: walk, detect, locate, switch, recursively to a depth.

``grow(problem, depth, switch, deflate)``, breadth first:

1. the root (branch 0) is walked from the start (``branch.arclength``);
2. on each walked branch of level d the changes of the decided count (``branch.events.decided``) are located, and the
   turns in p with none (a fold whose critical eigenvalue only touches zero, located by the parabola
   through the three points around the turn): a row per event (``event`` = ``fold`` or ``branch point``, ``detected_at`` the accepted point after the
   change, the located parameter, energy, critical eigenvalue and its error bound, and
   ``critical_mode``: the snapshot that holds the critical eigenvector);
3. with ``switch`` and d < ``depth``, each located branch point starts two branches, sigma = +1 and
   -1 along the critical mode (``branch.switch``): a branch's first rows are the branch point
   (``corrector`` ``branch point``) and the switched point (``switch``), its ``parent`` the branch it
   left; a candidate that lies on a known branch (``switch.known``; mirror images included where
   the problem's distance takes its symmetries) is one row with ``event`` ``known: branch k`` and
   is not walked; a walked branch that comes within its step of a located branch point of another
   branch has joined it and stops there (``joined branch point at point N``);
4. with ``deflate`` = N > 0 and no branch walked by switching, up to N other certified points at
   the root's start parameter are sought by deflation (``branch.deflation``), walked as new roots
   (``parent`` empty, ``event`` ``deflation``) and expanded as the root is (steps 2-3).

Every decision is read back from the rows (a located event by its ``detected_at``, a branch by its
id, ids given out in the same order), so a resumed diagram redoes nothing and loses no row.

The ``problem`` (``branch.run`` for vesicles, a closed form in the tests) provides: ``weights``;
``walk(k, p_start, stop)`` (walk or resume branch k, its first rows already recorded for a
switched branch); ``points(k)`` (its accepted Points, ``payload`` the row); ``rows()``;
``solve(p, phi0, lam0)`` and ``free`` (or None): certified Points, not recorded; ``mode(point, m)``
(the m-th eigenvector, M-normalised); ``align(phi, ref)`` (``branch.switch``); ``record_event(k, detected_at, located,
mode)``; ``record_start(k, parent, bp, first, how, known)``; ``deflate(p, phi0, known)``; ``step``
(the first parameter step) and ``theta(k)`` (the branch's arclength scale).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vesicle_opt.branch import events as ev
from vesicle_opt.branch import switch as sw

AMPLITUDE = 0.05  # the switch's first amplitude, a fraction of max(|phi*|_w, 1) (mode M-normalised)
P_TOL = 1e-3  # a branch point is located to this fraction of the first step (or to its eigenvalue's bound)
TAU_TOL = 1e-3  # a fold, to this fraction of its bracketing chord


@dataclass
class Node:
    """One branch of the tree: its parent (None: a root), level and why it stopped."""

    id: int
    parent: int | None
    level: int
    stopped: str = ""


def locate(problem, k: int, pts: list[ev.Point], j: int) -> dict:
    """Locate the index change between pts[j - 1] and pts[j] of branch k (its bracket widened to
    decided ends, ``events.bracket``); its row (recorded once)."""
    detected = pts[j].payload["point"]
    for r in problem.rows():
        if r["branch"] == k and r.get("detected_at") == detected and r["corrector"] == "locate":
            return r
    ia, ib = ev.bracket(pts, j)  # the critical eigenvalue decided at both ends
    a, b = pts[ia], pts[ib]
    kind = ev.classify([q.p for q in pts], j, ia, ib)
    if kind == ev.BRANCH_POINT:
        loc = ev.locate_branch_point(problem.solve, a, b, P_TOL * abs(problem.step))
    elif problem.free is not None:
        loc = ev.locate_on_chord(problem.free, a, b, problem.weights, problem.theta(k), TAU_TOL)
    else:
        around = pts[max(j - 2, 0): j + 1] if j + 1 >= len(pts) else pts[j - 1: j + 2]
        loc = ev.locate_fold_parabola(around, problem.weights, problem.theta(k))
    mode = None if loc.point is None else problem.mode(loc.point, loc.critical)
    problem.record_event(k, detected, loc, mode)
    return problem.rows()[-1]


def locate_turn(problem, k: int, pts: list[ev.Point], j: int) -> dict:
    """A turning point of branch k at pts[j] where the index does not change (a symmetric turning
    point, the critical eigenvalue touching zero): the parabola's vertex (``located_by`` parabola)."""
    detected = pts[j].payload["point"]
    for r in problem.rows():
        if r["branch"] == k and r.get("detected_at") == detected and r["corrector"] == "locate":
            return r
    loc = ev.locate_fold_parabola(pts[j - 1: j + 2], problem.weights, problem.theta(k))
    problem.record_event(k, detected, loc, None)
    return problem.rows()[-1]


def _point_of(problem, row: dict) -> ev.Point | None:
    """The located point of an event row, as a Point (None where the location did not solve)."""
    return None if row.get("energy") is None or row["located_by"] in ("parabola",) or \
        str(row["located_by"]).startswith("failed") else problem.point_of_row(row)


def grow(problem, depth: int = 1, switch: bool = True, deflate: int = 0) -> dict[int, Node]:
    """The tree (module docstring): {branch id: Node}."""
    nodes = {0: Node(0, None, 0)}
    nodes[0].stopped = problem.walk(0, None, _stop(problem, nodes, 0))
    next_id = _expand(problem, nodes, [0], 1, depth, switch)
    switched = any(n.parent is not None and not n.stopped.startswith(("known", "none found")) for n in nodes.values())
    if deflate and not switched:  # the fallback: other points at the start, each a root, expanded alike
        queue: list[int] = []
        next_id = _deflate(problem, nodes, deflate, next_id, queue)
        _expand(problem, nodes, queue, next_id, depth, switch)
    return nodes


def _expand(problem, nodes, queue, next_id, depth, switch) -> int:
    """Locate the events of the queued branches and walk the branches they switch to, breadth first."""
    while queue:
        k = queue.pop(0)
        node = nodes[k]
        pts = [q for q in problem.points(k) if q.payload["corrector"] != "branch point"]  # its start: singular
        found = ev.crossings(pts)
        located = [locate(problem, k, pts, j) for j in found]  # all, before any switch
        for j in ev.turns(pts):  # a turn in p with no change of index near it: a fold all the same
            if all(abs(j - c) > 2 for c in found):
                locate_turn(problem, k, pts, j)
        for row in located:
            if not (switch and node.level < depth and row["event"] == ev.BRANCH_POINT):
                continue
            bp = _point_of(problem, row)
            for sigma in (1, -1):
                cid, next_id = next_id, next_id + 1
                nodes[cid] = Node(cid, k, node.level + 1)
                mine = [r for r in problem.rows() if r["branch"] == cid]
                if not mine or (len(mine) == 1 and mine[0]["corrector"] == "branch point"):  # (a kill between the two)
                    if bp is None:
                        problem.record_start(cid, k, row, None, "no located point", None)
                    else:
                        _switch(problem, nodes, cid, k, bp, row, sigma)
                    mine = [r for r in problem.rows() if r["branch"] == cid]
                first = mine[-1] if len(mine) < 2 else mine[1]
                if not first["accepted"]:
                    nodes[cid].stopped = first["event"] or "switch failed"
                    continue
                nodes[cid].stopped = problem.walk(cid, None, _stop(problem, nodes, cid))
                queue.append(cid)
    return next_id


def _switch(problem, nodes, cid, k, bp, row, sigma) -> None:
    mode = problem.load_mode(row)
    if mode is None:
        problem.record_start(cid, k, row, None, "no critical mode stored", None)
        return
    amp = AMPLITUDE * max(math.sqrt(float(np.dot(problem.weights, bp.phi * bp.phi))), 1.0)
    parent = problem.points(k)
    theta = problem.theta(k)
    pt, how, _ = sw.first_point(bp, mode, sigma, amp, parent, problem.align, problem.weights, theta,
                                free=problem.free, solve=problem.solve, dp=abs(problem.step) / 2,
                                max_dp=4 * abs(problem.step))
    others = {j: polyline(problem, j, n) for j, n in nodes.items() if j != cid and n.stopped and
              not n.stopped.startswith("known")}
    same = None if pt is None else sw.known(pt, parent, others, problem.align, problem.weights, theta)
    problem.record_start(cid, k, row, pt, f"sigma {sigma:+d}, {how}", same)


def polyline(problem, j: int, node: Node) -> list[ev.Point]:
    """Branch j's accepted points, ended by the branch point it joined (``_stop``) if it did."""
    pts = problem.points(j)
    if node.stopped.startswith(JOINED):
        row = problem.rows()[int(node.stopped[len(JOINED):].split()[0])]
        bp = _point_of(problem, row)
        pts = pts + ([bp] if bp is not None else [])
    return pts


JOINED = "joined branch point at point "


def _stop(problem, nodes, cid):
    """The walk's stop rule of branch cid: joined a located branch point of another branch."""
    def stop(track):
        p, phi = track.points[-1]
        if track.accepted < 3 or track.theta is None or track.ds is None:
            return None
        for r in problem.rows():
            if r["corrector"] != "locate" or r["event"] != ev.BRANCH_POINT or r["branch"] == cid or \
                    r["point"] == _origin(problem, cid):
                continue
            bp = _point_of(problem, r)
            if bp is None:
                continue
            e = problem.align(phi, bp.phi) - bp.phi
            d = math.hypot(track.theta * math.sqrt(float(np.dot(problem.weights, e * e))), p - bp.p)
            if d <= track.ds:
                return f"{JOINED}{r['point']} (branch {r['branch']})"
        return None
    return stop


def _origin(problem, cid) -> int | None:
    first = next((r for r in problem.rows() if r["branch"] == cid), None)
    return None if first is None else first.get("detected_at")


def _deflate(problem, nodes, n, next_id, queue) -> int:
    root = problem.points(0)
    if not root:
        return next_id
    start = root[0]
    known = [start.phi]
    for _ in range(n):
        cid, next_id = next_id, next_id + 1
        nodes[cid] = Node(cid, None, 0)
        mine = [r for r in problem.rows() if r["branch"] == cid]
        if not mine:
            pt = problem.deflate(start.p, start.phi, known)
            problem.record_start(cid, None, None, pt, "deflation", None)
            mine = [r for r in problem.rows() if r["branch"] == cid]
        if not mine[0]["accepted"]:
            nodes[cid].stopped = mine[0]["event"] or "deflation found nothing"
            break
        known.append(problem.phi(mine[0]["point"]))
        nodes[cid].stopped = problem.walk(cid, None, _stop(problem, nodes, cid))
        queue.append(cid)
    return next_id
