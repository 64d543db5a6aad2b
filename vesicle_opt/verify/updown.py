"""The form of an axisymmetric vesicle on the meridian half-plane: one vesicle with its two poles on
the axis and apart, or not; up-down symmetric, or not.

A transition line's "oblate" (``branch.transition``) is the up-down symmetric oblate branch only
while its field is that state. Two ways it stops being one, both seen on the line D(c0)
(Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991), Fig. 8):

* at positive c0 and low v the oblate's dimples approach each other; once the poles are within an
  interface width the phase field merges them and the vesicle is a torus (no curve reaches the
  axis): ``pole_gap`` is the distance between the two ends of the meridian curve phi = 0 on the
  axis (None where the curve does not reach the axis at two ends: a torus, several components);
* at negative c0 the warm-started "oblate" turns into an up-down asymmetric (cup-like) state:
  ``updown_asymmetry`` is the volume of the symmetric difference of the inside {phi > 0} and its
  mirror image about the inside's centroid plane z = z_c, relative to the inside's volume,
  sum w |phi - phi_m| / sum w (1 + phi) (phi_m the P1 interpolant at (r, 2 z_c - z), -1 outside the
  box), with the weight 2 pi r of the meridian mesh. It is 0 for a symmetric field on a mirrored
  mesh, O(h^2) interpolation error on a mesh that is not (an interface-refined band about an
  asymmetric start), and of the order of the relative shift of the interface for an asymmetric one.

``describe`` gives both with ``form`` (prolate, oblate, cup, or None for anything else; the phase
figure's labels). numpy and matplotlib's triangle finder (as ``mesh.refine.transfer``).
"""

from __future__ import annotations

import numpy as np

SYMMETRIC = 1e-3  # updown_asymmetry below this is "symmetric": measured 1.4e-6 .. 3.9e-6 on the certified symmetric
# prolates and oblates of the line D(c0) at eps = 0.02 (bands that are not mirrored); a unit sphere with one half
# stretched by s (its pole moved by s) gives 0.32 s (0.0016 at s = 0.005, tests/verify/test_updown.py's field)
AXIS = 1e-9  # a curve's end with r below this (relative to the box) lies on the axis


def poles(curves, r_max: float) -> tuple[float, float] | None:
    """(z_lower, z_upper) of the one meridian curve's two ends on the axis; None for anything else."""
    if not curves or len(curves) != 1:
        return None
    c = curves[0]
    if abs(c[0][0]) > AXIS * r_max or abs(c[-1][0]) > AXIS * r_max or len(c) < 3:
        return None
    a, b = float(c[0][1]), float(c[-1][1])
    return (min(a, b), max(a, b))


def asymmetry(disc, phi: np.ndarray) -> float:
    """``updown_asymmetry`` (module docstring) of a field on a meridian mesh."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation  # third-party, lazy

    phi = np.asarray(phi, float)
    w = np.asarray(disc.weights, float)
    inside = w * (1 + phi) / 2
    zc = float(inside @ disc.nodes[:, 1] / inside.sum())
    mirrored = np.column_stack([disc.nodes[:, 0], 2 * zc - disc.nodes[:, 1]])
    tri = Triangulation(disc.mesh.p[0], disc.mesh.p[1], disc.mesh.t.T)
    phi_m = np.ma.filled(LinearTriInterpolator(tri, phi)(mirrored[:, 0], mirrored[:, 1]), -1.0)  # outside: -1
    return float(w @ np.abs(phi - phi_m) / (w @ (1 + phi)))


def describe(disc, phi: np.ndarray) -> dict:
    """{form, pole_gap, updown_asymmetry, symmetric} of a field on a meridian mesh ({} elsewhere)."""
    if getattr(disc, "kind", None) != "axisymmetric" or not np.all(np.isfinite(phi)):
        return {}
    from vesicle_opt.io.meridian import meridian_curves  # scikit-fem's mesh: meridian meshes only

    curves = meridian_curves(disc, phi)
    ends = poles(curves, float(disc.box[0][1]))
    asym = asymmetry(disc, phi)
    return {"form": form(curves), "pole_gap": None if ends is None else ends[1] - ends[0],
            "updown_asymmetry": asym, "symmetric": bool(asym < SYMMETRIC)}


CUP = 0.1  # dimples differing by this fraction of the height: a cup (as the phase_diagram study's)


def form(curves) -> str | None:
    """The form of one meridian curve from the axis to the axis: "cup" when one pole's dimple (its
    depth below the curve's extreme z on its side) exceeds the other's by ``CUP`` of the height (up-
    down asymmetric: a stomatocyte-like state), else "prolate" (height > width) or "oblate"; None
    for anything else (no curve, several, a torus)."""
    if not curves or len(curves) != 1 or curves[0][0][0] > 1e-9 or curves[0][-1][0] > 1e-9:
        return None
    r, z = curves[0][:, 0], curves[0][:, 1]
    height = float(z.max() - z.min())
    lo, hi = sorted((float(z[0]), float(z[-1])))
    if abs((lo - float(z.min())) - (float(z.max()) - hi)) > CUP * height:
        return "cup"
    return "prolate" if height > 2 * float(r.max()) else "oblate"

