"""Shared pieces of the studies: scenes by name, CSV rows from results, fitted rates, the torus
check of the Section-5 studies, and pyplot on the Agg backend (``pyplot``; figures are files)."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import matplotlib
import numpy as np

from vesicle_opt import scene as scene_mod
from vesicle_opt.nlp import build_nlp
from vesicle_opt.result import Result
from vesicle_opt.verify import topology
from vesicle_opt.verify.failure import tol_to_certify
from vesicle_opt.verify.metrics import field_errors

matplotlib.use("Agg")  # before pyplot: the studies write figure files, never open windows
import matplotlib.pyplot as pyplot  # noqa: E402

# Table 1 of the paper (the torus of Section 5, penalty M = 1e4): rigidity * E_h per grid n^3
TABLE1 = {16: 409.22535, 32: 423.20807, 48: 423.20086, 64: 423.20087}
TABLE1_M = 1e4

EXTRA = ["error_lap", "error_h1_raw", "shift", "penalized_energy", "kkt_residual", "converged", "tol",
         "setting"]


def load(name: str, overrides: list[str] | tuple = ()) -> scene_mod.Scene:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # near-bound warnings are the scenes' documented state
        return scene_mod.load(name, list(overrides))


def nlp_for(name: str, overrides=()):
    sc = load(name, overrides)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return build_nlp(sc)


def row(result: Result | dict, scene: str, method: str, n, h, ref: Result | None = None, disc=None,
        **extra) -> dict:
    """One CSV row; errors against ``ref`` (same discretisation) when given."""
    get = (lambda k: result.get(k)) if isinstance(result, dict) else (lambda k: getattr(result, k))
    out = {"scene": scene, "method": method, "n": n, "h": h, "M": get("M"), "energy": get("energy"),
           "volume_residual": get("volume_residual"), "area_residual": get("area_residual"),
           "lambda_volume": get("lambda_volume"), "lambda_area": get("lambda_area"),
           "iterations": get("iterations"), "wall_time_s": get("wall_time_s"), "status": get("status"),
           "penalized_energy": get("penalized_energy"), "kkt_residual": get("kkt_residual"),
           "converged": get("converged"),
           # how and why a row failed (studies.runner.failed_line), a floor's certifiable tol
           "outcome": str(get("outcome") or ""), "reason": get("reason"),
           "certifiable_tol": tol_to_certify(result) if isinstance(result, Result) else result.get("certifiable_tol")}
    if ref is not None:
        out["error_energy"] = abs(get("energy") - ref.energy) / abs(ref.energy)
        phi = get("phi")
        if phi is not None and disc is not None:
            out.update(field_errors(disc, phi, ref.phi))
    out.update(extra)
    return out


def human(value) -> str:
    """A study's summary value as a short line for people: a dict as ``key value, ...`` (nested
    ones in parentheses), floats to 6 significant digits, lists comma-separated; not a repr."""
    if isinstance(value, dict):
        return ", ".join(f"{k} ({human(v)})" if isinstance(v, dict) else f"{k} {human(v)}" for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return ", ".join(human(v) for v in value)
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.6g}"
    return "none" if value is None else str(value)


def num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def column(rows: list[dict], key: str, **match) -> np.ndarray:
    sel = [r for r in rows if all(str(r.get(k)) == str(v) for k, v in match.items())]
    return np.array([num(r.get(key)) for r in sel])


def select(rows: list[dict], **match) -> list[dict]:
    return [r for r in rows if all(str(r.get(k)) == str(v) for k, v in match.items())]


def savefig(fig, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    pyplot.close(fig)


def plt():
    """pyplot on the Agg backend (the module's ``pyplot``)."""
    return pyplot


def torus_check(disc, phi: np.ndarray, topo: dict | None = None) -> dict:
    """Is {phi > 0} a solid torus around the z axis? The topology columns of ``table1`` and
    ``torus_section5`` (one rule for both):

    * ``components``, ``euler_characteristic``, ``wraps`` from ``verify.topology`` (periodic,
      corner contacts connect): ``topo`` is a ``topology.report`` dict (a front-door result's
      ``extra``), computed from ``disc`` and ``phi`` when not given; ``wraps`` is written as the
      axis letters, ``"none"`` when the body does not join its periodic image (None, and chi
      None, off grids: not a torus then);
    * ``axis_negative``: phi < 0 at every node of the centre axis x = y = 0 (the grid column
      nearest to it): the hole of the torus, not a sphere or a disk;
    * ``torus_ok``: one component, chi = 0, no wrap, and the axis outside.
    """
    topo = topology.report(disc, phi) if topo is None else topo
    if "components" not in topo:  # report() of a non-finite phi is empty
        return {"components": None, "euler_characteristic": None, "wraps": None, "axis_negative": False,
                "torus_ok": False}
    rho = np.hypot(disc.nodes[:, 0], disc.nodes[:, 1])
    axis = rho <= rho.min() + 1e-9 * disc.h  # the column nearest to x = y = 0 (on it for even n)
    wraps = None if topo["wraps"] is None else "".join("xyz"[a] for a in topo["wraps"]) or "none"
    axis_negative = bool(np.all(np.asarray(phi)[axis] < 0))
    ok = topo["components"] == 1 and topo["euler_characteristic"] == 0 and wraps == "none" and axis_negative
    return {"components": topo["components"], "euler_characteristic": topo["euler_characteristic"],
            "wraps": wraps, "axis_negative": axis_negative, "torus_ok": bool(ok)}
