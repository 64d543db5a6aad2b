"""The phase-field stomatocyte reached without a seed, as the start of the ``phase_diagram`` walks.

``_stomatocyte.switched`` reaches the cup with no stomatocyte seed at eps = ``EPS`` (0.03) alone: the
oblate at v = ``V_SWITCH`` walked in c0 to its odd branch point, the branch out of it followed with
c0 free to c0 = 0, the minimiser from there walked down in v at c0 = 0 (``down_in_v``) to
``V_SEED`` = 0.62 (docs/guide/bifurcation.md, "A continuous switch"). At eps 0.04 and 0.05 the same
route lands elsewhere, and it runs on a uniform eps/h = 2 mesh, where the walks use refined eps/h = 4
meshes. So the landing is handed on as a shape: its phi = 0 meridian curve (``io.meridian``), which
``_meridian.seed`` turns into the tanh profile at any eps on the mesh refined about that curve, as it
does with a sharp shape. No hand-made shape enters: the curve is the phase field's own.

Measured (this module's curve, v = 0.62, eps/h = 4 refined, IPOPT, the study's 24-mode sharp seed for
the comparison): at eps 0.04 / 0.03 / 0.025 / 0.02 the landing's curve and the sharp seed reach the same
certified cup, f 1.9699170065 / 1.9683407758 / 1.9677507813 / 1.9672810941 (relative differences 2.6e-12
/ 2.6e-8 / 5.5e-11 / 1.2e-10), field distance (``_same_state``) 1e-7 to 2e-6; at 0.05 both reach the
same up-down symmetric torus (no cup exists there). The study's walks from either start agree point by
point to <= 1.2e-7 in f (docs/guide/bifurcation.md). The route itself: ~190 CPU s (168 s to c0 = 0,
then the walk in v).

The curve is kept in the walks' ``states`` directory (``FILE``: written whole or not at all, via a
temporary file and a rename), made once before the cases run (``prepare``, in the study's process), so
parallel cases and a resumed run read it; a file that cannot be read (damaged, truncated, not a curve
from the axis to the axis) is computed again and replaced.
"""

from __future__ import annotations

import logging
import zipfile
from pathlib import Path

import numpy as np

from vesicle_opt.io.files import save_npz
from vesicle_opt.io.meridian import meridian_curves
from vesicle_opt.studies import _stomatocyte as stoma
from vesicle_opt.verify import updown

log = logging.getLogger(__name__)

EPS = 0.03  # the level at which the continuous switch lands on the cup (module docstring)
C0S = (0.0, -0.5, -1.0, -1.25, -1.5)  # the oblate's walk in c0 at V_SWITCH to its odd branch point (as the slow test)
VS = (0.65, 0.64, 0.63, stoma.V_SEED)  # the landing walked down in v at c0 = 0 (``down_in_v``), 0.01 a step
FILE = "stomatocyte-landing.npz"


class NotReached(RuntimeError):
    """The route did not end on a certified cup at V_SEED (the message says where it stopped)."""


def prepare(case_list: list[dict]) -> list[dict]:
    """The landing made once, before the cases run in parallel (each worker would make it again):
    where a case starts from it and its ``states`` has no readable curve, ``curve`` runs the route
    here. Where the route does not land, those cases start from the seed instead and carry why
    (``missed``), so that no case runs the route again."""
    want = [c for c in case_list if c.get("start") == "landing" and c.get("states") is not None]
    if not want:
        return case_list
    try:
        curve(want[0]["states"])
    except NotReached as exc:
        missed = _missed(exc, "the stomatocyte walks")
        return [{**c, "start": "seed", "missed": missed} if c.get("start") == "landing" else c for c in case_list]
    return case_list


def start(case: dict):
    """(a ``phase_case`` start curve or None, why the landing is missing or ''): with ``case["start"]``
    = "landing" the landing's curve (``curve``, kept in ``case["states"]``); else None (the seed), with
    ``case["missed"]`` (``prepare``) as the reason."""
    if case.get("start") != "landing":
        return None, case.get("missed", "")
    try:
        return curve(case.get("states")), ""
    except NotReached as exc:
        return None, _missed(exc, str(case.get("case")))


def _missed(exc: NotReached, who: str) -> str:
    """The rows' line for a route that did not land (logged once for ``who``, which starts from the seed)."""
    log.warning(f"{who}: the seedless landing was not reached ({exc}); the seed instead")
    return f"the seedless landing was not reached: {exc}"


def curve(states=None) -> tuple[np.ndarray, np.ndarray, str]:
    """(r, z, note): the landing's phi = 0 meridian curve at (V_SEED, c0 = 0) and a line for the rows'
    ``seed`` column; read from ``states``/``FILE`` where a readable one is there, else computed
    (``compute``) and written there. NotReached where the route does not get there."""
    path = None if states is None else Path(states) / FILE
    if path is not None and path.exists():
        got = read(path)
        if got is not None:
            return got
        log.warning(f"{path.name}: unreadable, computing the landing again")
    r, z, note = compute()
    if path is not None:
        write(path, r, z, note)
    return r, z, note


def compute() -> tuple[np.ndarray, np.ndarray, str]:
    """The route (module docstring): (r, z, note), or NotReached."""
    out = stoma.switched(stoma.V_SWITCH, EPS, c0s=C0S)
    end = getattr(out.followed, "end", None)
    if end is None:
        stopped = getattr(out.followed, "stopped", "no branch point")
        raise NotReached(f"the switched branch did not reach c0 = 0 ({stopped})")
    corr = out.corrector
    v, res = stoma.down_in_v(corr, corr.scene, end.phi, VS)[-1]
    form = updown.describe(res.disc, res.phi).get("form") if res.converged else None
    if v != stoma.V_SEED or not res.converged or res.extra.get("second_order") != "minimum" or form != "cup":
        raise NotReached(f"the walk in v ended at v {v:g}: {res.outcome}, {res.extra.get('second_order')}, form {form}")
    curves = meridian_curves(res.disc, res.phi)
    if len(curves) != 1 or not _axis_to_axis(curves[0][:, 0], curves[0][:, 1]):
        raise NotReached(f"the landing's phi = 0 set is not one curve from the axis to the axis ({len(curves)} curves)")
    note = (f"no seed: the phi = 0 curve of the continuous switch's landing (eps {EPS:g}, v {stoma.V_SWITCH:g} "
            f"-> {stoma.V_SEED:g}, f {float(res.extra['f']):.10f})")
    return curves[0][:, 0].copy(), curves[0][:, 1].copy(), note


def write(path: Path, r, z, note: str) -> None:
    """``FILE`` whole or not at all (``io.files.save_npz``: a temporary file renamed over it)."""
    save_npz(path, r=np.asarray(r, float), z=np.asarray(z, float), note=np.array(note))


def read(path: Path):
    """(r, z, note) from ``FILE``, or None where it cannot be read or holds no curve from the axis to
    the axis (what ``compute`` writes)."""
    try:
        with np.load(path, allow_pickle=False) as d:
            r, z, note = np.asarray(d["r"], float), np.asarray(d["z"], float), str(d["note"])
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    return (r, z, note) if _axis_to_axis(r, z) else None


def _axis_to_axis(r: np.ndarray, z: np.ndarray) -> bool:
    """One meridian curve from the axis to the axis (a cup's: both ends at r = 0, where the mesh's axis
    edges put them exactly), finite, r >= 0."""
    return bool(r.ndim == 1 and r.shape == z.shape and r.size >= 3 and np.all(np.isfinite(r)) and
                np.all(np.isfinite(z)) and np.all(r >= 0) and r[0] == 0.0 and r[-1] == 0.0)
