"""Shared pieces of the theorem studies: scenes by name, CSV rows from results, fitted rates."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from vesicle_opt import scene as scene_mod
from vesicle_opt.verify.metrics import field_errors
from vesicle_opt.nlp import build_nlp
from vesicle_opt.result import Result

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
           "converged": get("converged")}
    if ref is not None:
        out["error_energy"] = abs(get("energy") - ref.energy) / abs(ref.energy)
        phi = get("phi")
        if phi is not None and disc is not None:
            out.update(field_errors(disc, phi, ref.phi))
    out.update(extra)
    return out


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
    import matplotlib.pyplot as plt
    plt.close(fig)


def plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as pyplot
    return pyplot
