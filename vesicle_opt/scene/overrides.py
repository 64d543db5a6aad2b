"""Scene overrides: dotted keys given as a mapping ``{"mesh.n": 64}`` or as ``--set`` style
``"KEY=VALUE"`` strings (values parsed as TOML), and the rule that setting one way of giving the
constraint targets (``constraints.reduced_volume`` with ``area``, or ``alpha`` / ``beta`` /
``target``, Section 3.1) drops the scene's other way. ``schema.apply_overrides`` applies them.
"""

from __future__ import annotations

import logging
import tomllib
from typing import Any, Mapping, Sequence

from vesicle_opt.errors import InputError

log = logging.getLogger("vesicle_opt.scene")


def parse_value(text: str) -> Any:
    """Parse a ``--set`` value as TOML; a bare word that is not TOML is taken as a string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def override_items(overrides: Mapping[str, Any] | Sequence[str] | None) -> list[tuple[str, Any]]:
    """(dotted key, value) pairs of overrides given as a mapping ``{"mesh.n": 64}`` (values as they
    are) or a list of ``"KEY=VALUE"`` strings (``--set``; values parsed as TOML); InputError naming
    ``overrides`` for anything else (a bare string would be iterated character by character)."""
    if overrides is None:
        return []
    if isinstance(overrides, Mapping):
        return [(str(k).strip(), v) for k, v in overrides.items()]
    if isinstance(overrides, (str, bytes)) or not isinstance(overrides, Sequence) \
            or not all(isinstance(item, str) for item in overrides):
        raise InputError("overrides", "expected a mapping {'mesh.n': 64} or a list of 'KEY=VALUE' "
                         f"strings (['mesh.n=64']), got {overrides!r}")
    items = []
    for item in overrides:
        if "=" not in item:
            raise InputError("--set", f"expected KEY=VALUE, got {item!r}")
        key, text = item.split("=", 1)
        if not key.strip():
            raise InputError("--set", f"expected KEY=VALUE with a key, got {item!r}")
        items.append((key.strip(), parse_value(text.strip())))
    return items


# the two ways of giving the constraint targets (``schema._physical_targets``): setting one way
# completely by overrides (a complete set below) drops the other way's keys from the scene, with one
# INFO line; a partial one (alpha alone) is left to the schema's "not both" refusal
_TARGET_WAYS = (("constraints.reduced_volume", "constraints.area"),
                ("constraints.alpha", "constraints.beta", "constraints.target"))
_COMPLETE = ({"constraints.reduced_volume", "constraints.area"}, {"constraints.alpha", "constraints.beta"},
             {"constraints.target"})


def replace_targets(raw: dict, keys: set[str]) -> None:
    """Drop from ``raw`` the target keys of the other way than the one ``keys`` (overridden) give
    completely."""
    for way, other in (_TARGET_WAYS, _TARGET_WAYS[::-1]):
        if any(c <= keys and c <= set(way) for c in _COMPLETE):
            dropped = [k for k in other if k not in keys and k.split(".")[1] in raw.get("constraints", {})]
            for k in dropped:
                del raw["constraints"][k.split(".")[1]]
            if dropped:  # one line, through the CLI's logging (stderr)
                log.info(
                    "%s given: the scene's %s dropped", " and ".join(sorted(keys & set(way))), ", ".join(dropped))
