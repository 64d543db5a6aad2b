"""The band check of interface-refined meshes (``mesh.refine = "interface"``, ``mesh.refine``).

The mesh is fine only within ``mesh.band`` x eps of the start's interface. A solution whose phi = 0
curve moved towards the coarse cells is computed with the coarse cells' error (measured: 3.6e-4
relative in E_h at 3 eps from them, 2.4e-3 at 2 eps, against 2e-5 at 4 eps; ``scene.ranges.BAND_MIN``).
So a converged result whose margin (``mesh.refine.band_margin``: the distance from its phi = 0 curve
to the nearest vertex of a coarser element, in units of eps) is below ``BAND_MIN`` is not converged:
outcome ``not_certified``, its reason naming ``mesh.band``. The summary carries ``band_margin`` and
``h_fine`` on every refined mesh.
"""

from __future__ import annotations

import dataclasses

from vesicle_opt.result import Result, Status
from vesicle_opt.scene.ranges import BAND_MIN


def apply(result: Result) -> Result:
    """``result`` with ``band_margin`` and ``h_fine`` in ``extra`` (a refined mesh only); a converged
    result whose margin is below ``BAND_MIN`` is not converged (module docstring)."""
    disc = result.disc
    if disc is None or getattr(disc, "band", None) is None or "epsilon" not in result.extra:
        return result
    from vesicle_opt.mesh.refine import band_margin  # scikit-fem: only refined meshes load it

    margin = band_margin(disc.mesh, result.phi, disc.h_fine, result.extra["epsilon"])
    extra = {**result.extra, "band_margin": margin, "h_fine": disc.h_fine}
    if margin >= BAND_MIN or not result.converged:
        return dataclasses.replace(result, extra=extra)
    line = (f"the interface left the refined band: its phi = 0 curve is {margin:.3g} eps from the coarse "
            f"cells (needs >= {BAND_MIN:g}; mesh.band = {disc.band:g} about the start's interface): solve again "
            f"with x0 = this result (re-meshed about its interface) or widen mesh.band")
    return dataclasses.replace(result, converged=False, outcome=Status.NOT_CERTIFIED,
                               extra={**extra, "reason": line})
