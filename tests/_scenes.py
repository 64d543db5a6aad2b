"""Small scenes for tests, built from the bundled ones with overrides."""

from pathlib import Path

from vesicle_opt import scene

PROBLEMS = Path(__file__).resolve().parent.parent / "problems"


def bundled(name: str, *overrides: str) -> scene.Scene:
    return scene.load(PROBLEMS / f"{name}.toml", list(overrides))
