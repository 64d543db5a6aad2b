"""A validated scene written back as TOML (``scene.resolved.toml`` beside every ``summary.json``).

Every key is written with the value the run used, defaults included, so loading the file
(``vesicle-opt solve DIR/scene.resolved.toml``) repeats the run exactly: ``from_dict`` of the
written table gives back an equal ``Scene`` (a test checks it for every bundled scene). Paths
(``mesh.file``, ``initial.file``) are written absolute, so the file works from any directory.
``constraints``: the physical targets (``reduced_volume`` with ``area``) are written instead of the
(alpha, beta) they set, since the schema accepts one or the other. TOML has no null, so unset
optional keys are left out. The writer is tomli-w (tomllib reads TOML but cannot write it).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import tomli_w

_PATH_KEYS = {"file"}


def _plain(value):
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def _table(section, drop: tuple[str, ...] = ()) -> dict:
    out = {}
    for f in dataclasses.fields(section):
        value = getattr(section, f.name)
        if value is None or f.name in drop:
            continue
        if dataclasses.is_dataclass(value):
            out[f.name] = _table(value)
        elif f.name in _PATH_KEYS:
            out[f.name] = str(Path(value).resolve())
        else:
            out[f.name] = _plain(value)
    return out


def as_dict(scene) -> dict:
    """The scene as a raw TOML table (the inverse of ``schema.from_dict``)."""
    c = scene.constraints
    physical = c.reduced_volume is not None
    return {"domain": _table(scene.domain, drop=("mirror_cells", "axisymmetric")),  # derived from mesh.kind and boundary
            "mesh": _table(scene.mesh), "model": _table(scene.model),
            "constraints": _table(c, drop=("alpha", "beta") if physical else ()),
            "initial": _table(scene.initial), "solver": _table(scene.solver), "flow": _table(scene.flow)}


def dumps(scene) -> str:
    """TOML text of the resolved scene, with a header naming it."""
    return f"# resolved scene {scene.name!r}: every key as the run used it\n" + tomli_w.dumps(as_dict(scene))


def write(path: Path, scene) -> None:
    """``dumps(scene)`` into ``path`` (written to a temporary name, then renamed: never half a file)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(dumps(scene))
    tmp.replace(path)
