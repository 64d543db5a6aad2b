"""The scenes shipped inside the package (``vesicle_opt/problems/*.toml``), found by name.

They are package data, read through ``importlib.resources``, so ``load_scene("ellipse-2d")`` and
``vesicle-opt solve ellipse-2d`` work from any directory and from a non-editable install.
"""

from __future__ import annotations

from importlib import resources
import os
from pathlib import Path

from vesicle_opt.errors import InputError


def _folder():
    return resources.files("vesicle_opt") / "problems"


def names() -> list[str]:
    """The bundled scene names (file stems), sorted."""
    return sorted(p.name[:-5] for p in _folder().iterdir() if p.name.endswith(".toml"))


def text(name: str) -> str:
    """The TOML text of a bundled scene (``ellipse-2d`` or ``ellipse-2d.toml``)."""
    stem = name[:-5] if name.endswith(".toml") else name
    entry = _folder() / f"{stem}.toml"
    if not entry.is_file():
        raise InputError("scene", f"no bundled scene {name!r} (bundled scenes: {', '.join(names())})")
    return entry.read_text()


def resolve(arg: str | Path) -> tuple[str, str]:
    """(name, TOML text) of a scene given as a path or as the name of a bundled scene."""
    if not isinstance(arg, (str, os.PathLike)):
        raise InputError("scene", f"expected a scene TOML path or a bundled scene name, got "
                         f"{type(arg).__name__} ({', '.join(names())})")
    p = Path(arg)
    try:
        if p.is_dir():
            raise InputError("scene", f"{arg} is a directory; give a scene TOML file or a bundled name "
                             f"({', '.join(names())})")
        if p.is_file():
            return p.stem, p.read_text()
    except UnicodeDecodeError as exc:
        raise InputError("scene", f"{arg} is not valid TOML: {exc}") from None
    except OSError as exc:  # a name too long, permission denied, an I/O error: one line, before any work
        raise InputError("scene", f"cannot read {str(arg)!r} ({exc.strerror or exc})") from None
    stem = p.name[:-5] if p.name.endswith(".toml") else p.name
    if str(arg) in (stem, f"{stem}.toml") and stem in names():
        return stem, text(stem)
    raise InputError("scene", f"file not found: {arg} (bundled scenes: {', '.join(names())})")


def describe() -> list[str]:
    """One line per bundled scene: its name and the first sentence of the file's opening comment."""
    width = max(map(len, names()))
    lines = []
    for name in names():
        head = []
        for ln in text(name).splitlines():
            if not ln.startswith("#"):
                break
            head.append(ln.lstrip("# ").strip())
        first = " ".join(head).split(". ")[0].rstrip(".")
        lines.append(f"{name:<{width}}  {first}")
    return lines
