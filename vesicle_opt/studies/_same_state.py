"""Are two phase-field states on meridian meshes the same state? (the seedless stomatocyte against the
seeded one, ``studies._stomatocyte``).

Two solves of one scene on two interface-refined meshes (each refined about its own start, in its own
box) differ by the P1 error of each mesh, and by an axial translation: the pin (``nlp.reuse.pin_row``)
holds the inside's centre of mass at each box's mid-height. So the fields are compared after moving
that centre onto each other: ``field_distance`` is sum w |phi_a - phi_b~| / sum w (1 + phi_a) on a's
nodes (w the meridian weights 2 pi r, ``phi_b~`` the P1 interpolant of b at (r, z - z_a + z_b), -1
outside b's box), the measure of ``verify.updown.asymmetry``: about the volume between the two
interfaces relative to the inside's volume (|phi_a - phi_b| is 2 between them, 1 + phi_a is 2
inside). The same state on two meshes of the same fine spacing h differs by O(h^2) (interpolation
and discretisation); another state by far more (the seeded cup and the sickle torus at eps 0.03,
v 0.62: 0.0767, measured). ``compare`` adds f, the volume multiplier and ``verify.updown.describe``'s
form, pole gap and up-down asymmetry of each.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.mesh.band_start import axial_centre
from vesicle_opt.verify import updown


def field_distance(disc_a, phi_a, disc_b, phi_b) -> float:
    """The module docstring's distance of b from a (not symmetric in a and b: a's nodes and weights)."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation  # third-party, lazy (as verify.updown)

    phi_a, phi_b = np.asarray(phi_a, float), np.asarray(phi_b, float)
    shift = axial_centre(disc_b, phi_b) - axial_centre(disc_a, phi_a)
    tri = Triangulation(disc_b.mesh.p[0], disc_b.mesh.p[1], disc_b.mesh.t.T)
    nodes = np.asarray(disc_a.nodes, float)
    moved = np.ma.filled(LinearTriInterpolator(tri, phi_b)(nodes[:, 0], nodes[:, 1] + shift), -1.0)
    w = np.asarray(disc_a.weights, float)
    return float(w @ np.abs(phi_a - moved) / (w @ (1 + phi_a)))


def compare(a, b) -> dict:
    """Two Results on meridian meshes: f of each and their relative difference, the volume
    multipliers', the field distance both ways, and each one's ``updown.describe``."""
    fa, fb = float(a.extra["f"]), float(b.extra["f"])
    return {"f": (fa, fb), "f_rel": abs(fa - fb) / abs(fa),
            "lambda": (float(a.lambda_volume), float(b.lambda_volume)),
            "distance": (field_distance(a.disc, a.phi, b.disc, b.phi), field_distance(b.disc, b.phi, a.disc, a.phi)),
            "describe": (updown.describe(a.disc, a.phi), updown.describe(b.disc, b.phi))}
