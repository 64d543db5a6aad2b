"""Shape tables of a scene (``initial`` and ``constraints.target``): the schema and its parser.

A shape is given by ``shape`` and its parameters; ``shapes.py`` turns it into a phase field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from vesicle_opt.errors import InputError

SHAPES = ("circle", "sphere", "ellipse", "ellipsoid", "disk", "torus", "biconcave", "file",
          "constant", "noise")
SHAPE_KEYS = ("shape", "center", "radius", "semi_axes", "radii", "thickness", "file", "value", "seed")


@dataclass(frozen=True)
class Shape:
    """An initial or target shape; phi = tanh(-d/(sqrt(2) eps)), +1 inside (see ``shapes``)."""

    shape: str
    center: tuple[float, ...] | None = None
    radius: float | None = None
    semi_axes: tuple[float, ...] | None = None
    radii: tuple[float, float] | None = None  # torus: (major R, minor r)
    thickness: float | None = None  # disk: full thickness of the rounded flat disk
    file: str | None = None  # shape "file": a phi.npz written by an earlier solve (warm start)
    value: float | None = None  # shape "constant": phi = value everywhere, -1 <= value <= 1
    seed: int | None = None  # shape "noise": phi uniform in (-1, 1), seeded


def number(key: str, v: Any, integer: bool = False) -> float | int:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(key, f"expected a {'integer' if integer else 'number'}, got {v!r}")
    if integer and not isinstance(v, int):
        raise InputError(key, f"expected an integer, got {v!r}")
    if not math.isfinite(v):
        raise InputError(key, f"must be finite, got {v!r}")
    return v


def numbers(key: str, v: Any, length: int | None = None) -> tuple[float, ...]:
    if not isinstance(v, (list, tuple)) or (length is not None and len(v) != length):
        raise InputError(key, f"expected a list of {length or 'some'} numbers, got {v!r}")
    return tuple(float(number(key, x)) for x in v)


def parse_shape(key: str, spec: Any, dim: int) -> Shape:
    """Validate a shape table (``initial`` or ``constraints.target``)."""
    if not isinstance(spec, dict):
        raise InputError(key, f"expected a table with 'shape' in {SHAPES}, got {spec!r}")
    unknown = set(spec) - set(SHAPE_KEYS)
    if unknown:
        raise InputError(f"{key}.{sorted(unknown)[0]}", f"unknown key (allowed: {', '.join(SHAPE_KEYS)})")
    shape = spec.get("shape")
    if shape not in SHAPES:
        raise InputError(f"{key}.shape", f"must be one of {', '.join(SHAPES)}, got {shape!r}")
    need = {"circle": ("radius",), "sphere": ("radius",), "ellipse": ("semi_axes",),
            "ellipsoid": ("semi_axes",), "disk": ("radius", "thickness"), "torus": ("radii",),
            "biconcave": ("radius",), "file": ("file",), "constant": ("value",), "noise": ("seed",)}[shape]
    for k in need:
        if k not in spec:
            raise InputError(f"{key}.{k}", f"required for shape '{shape}'")
    if shape in ("torus", "biconcave", "disk") and dim != 3:
        raise InputError(f"{key}.shape", f"'{shape}' needs a 3D domain, this one is {dim}D")
    center = numbers(f"{key}.center", spec["center"], dim) if "center" in spec else None
    radius = spec.get("radius")
    if radius is not None and number(f"{key}.radius", radius) <= 0:
        raise InputError(f"{key}.radius", f"must be > 0, got {radius!r}")
    semi = numbers(f"{key}.semi_axes", spec["semi_axes"], dim) if "semi_axes" in spec else None
    if semi is not None and min(semi) <= 0:
        raise InputError(f"{key}.semi_axes", f"must all be > 0, got {list(semi)}")
    radii = numbers(f"{key}.radii", spec["radii"], 2) if "radii" in spec else None
    if radii is not None and not (0 < radii[1] < radii[0]):
        raise InputError(f"{key}.radii", f"need 0 < minor < major, got {list(radii)}")
    thick = spec.get("thickness")
    if thick is not None and number(f"{key}.thickness", thick) <= 0:
        raise InputError(f"{key}.thickness", f"must be > 0, got {thick!r}")
    file = spec.get("file")
    if file is not None and not isinstance(file, str):
        raise InputError(f"{key}.file", f"expected a path string, got {file!r}")
    if shape in ("file", "constant", "noise") and key != "initial":
        raise InputError(f"{key}.shape", f"'{shape}' is allowed only for the initial shape")
    value = spec.get("value")
    if value is not None and not -1 <= number(f"{key}.value", value) <= 1:
        raise InputError(f"{key}.value", f"must lie in [-1, 1], got {value!r}")
    seed = spec.get("seed")
    if seed is not None:
        seed = number(f"{key}.seed", seed, integer=True)
    return Shape(shape, center, None if radius is None else float(radius), semi, radii,
                 None if thick is None else float(thick), file,
                 None if value is None else float(value), seed)
