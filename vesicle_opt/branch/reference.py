"""The sharp-interface reference of a branch's ``sharp_reduced_energy`` column (``branch(...,
reference=)``, the CLI's ``--sharp``): the eps -> 0 reduced energy at each point's reduced volume,
computed by ``vesicle_opt.sharp`` (no code shared with the phase-field path).

* ``elastica``: the 2D closed elastica (its 2-fold minimum), ``sharp.elastica``;
* ``prolate`` / ``oblate``: the 3D axisymmetric vesicle of the spontaneous-curvature model at
  c0 = 0, ``sharp.axisymmetric`` (a few seconds to tens of seconds a point);
* ``auto`` (``guess``): elastica in 2D; in 3D prolate or oblate from the start ellipsoid's semi-axes
  (one long and two equal short: prolate; one short and two equal long: oblate); none otherwise.

The references hold at c0 = 0 and in the reduced volume only; anything else is refused (InputError
naming ``--sharp``) before any solve.
"""

from __future__ import annotations

from typing import Callable

from vesicle_opt.errors import InputError

KINDS = ("auto", "elastica", "prolate", "oblate")


def guess(scene) -> str | None:
    """The reference that covers ``scene`` (module docstring), or None."""
    if scene.dim == 2:
        return "elastica"
    axes = getattr(scene.initial, "semi_axes", None)
    if scene.initial.shape != "ellipsoid" or axes is None:
        return None
    a = sorted(axes)
    if a[0] < a[1] and abs(a[1] - a[2]) <= 1e-12 * a[2]:
        return "oblate"
    if a[1] < a[2] and abs(a[0] - a[1]) <= 1e-12 * a[1]:
        return "prolate"
    return None


def reference(kind: str, scene, param: str) -> Callable[[str, float, int], float | None]:
    """f(param, value, dim) -> the sharp reduced energy at reduced volume ``value`` (None where the
    reference's own solve does not converge); InputError (``--sharp``) when it cannot apply."""
    if kind not in KINDS:
        raise InputError("--sharp", f"must be one of {', '.join(KINDS)}, got {kind!r}")
    which = guess(scene) if kind == "auto" else kind
    if which is None:
        raise InputError("--sharp", "no reference covers this scene (3D: start from an axisymmetric "
                         "ellipsoid, or name prolate / oblate)")
    if param != "reduced_volume":
        raise InputError("--sharp", f"the references are in the reduced volume, not {param!r}")
    if scene.model.c0 != 0:
        raise InputError("--sharp", f"the references hold at c0 = 0, the scene has c0 = {scene.model.c0!r}")
    if (which == "elastica") != (scene.dim == 2):
        raise InputError("--sharp", f"{which!r} is a {'2D' if which == 'elastica' else '3D'} reference, "
                         f"the scene is {scene.dim}D")
    from vesicle_opt.sharp import axisymmetric, elastica  # scipy's solvers: only with a reference asked for

    def f(p: str, value: float, dim: int) -> float | None:
        if not 0 < value < 1:
            return None
        sol = elastica.solve(value) if which == "elastica" else axisymmetric.solve(value, which)
        return float(sol.reduced_energy) if sol.converged else None
    return f
