"""The front doors' check of a scene argument: a ``Scene`` (``vesicle_opt.load_scene``), or an
InputError naming the argument before any work (never an AttributeError from inside)."""

from __future__ import annotations

from vesicle_opt.errors import InputError
from vesicle_opt.scene.schema import Scene


def require_scene(obj, key: str = "scene") -> Scene:
    if not isinstance(obj, Scene):
        raise InputError(key, f"expected a Scene (vesicle_opt.load_scene(path or name)), got {type(obj).__name__}")
    return obj
