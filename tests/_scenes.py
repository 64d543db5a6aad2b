"""Small scenes for tests, built from the bundled ones (loaded by name, from any directory)."""

from vesicle_opt import scene


def bundled(name: str, *overrides: str) -> scene.Scene:
    return scene.load(name, list(overrides))
