"""The scene checks of ``mesh.kind = "axisymmetric"`` (``mesh.axisymmetric``), before any work: the box
is the meridian half-plane [[0, R], [z0, z1]] with natural boundaries, and the scene's shapes are 3D
shapes symmetric about the z axis. Each violation is one line (:class:`~vesicle_opt.errors.InputError`
naming the key): a box that does not start at r = 0 or has 3 pairs, periodic boundaries, a 2D scene
(2D shapes), a shape off the axis, an ellipsoid whose x and y semi-axes differ."""

from __future__ import annotations

from vesicle_opt.errors import InputError
from vesicle_opt.scene.shape_spec import Shape, parse_shape


def check_box(val: dict, box) -> None:
    """mesh.kind 'axisymmetric' (``mesh.axisymmetric``): the box is the meridian half-plane
    [[0, R], [z0, z1]] (r from the axis, then z) with natural boundaries; checked before any work."""
    if val["mesh.kind"] != "axisymmetric":
        return
    if len(box) != 2:
        raise InputError("domain.box", f"mesh.kind 'axisymmetric' takes the meridian half-plane [[0, R], "
                         f"[z0, z1]] (2 pairs: r, then z), got {len(box)} pairs")
    if box[0][0] != 0.0:
        raise InputError("domain.box", f"an axisymmetric box must start at r = 0 (the axis): [[0, R], "
                         f"[z0, z1]], got r from {box[0][0]!r}")
    if val["domain.boundary"] != "natural":
        raise InputError("domain.boundary", "mesh.kind 'axisymmetric' needs 'natural' (the axis and the "
                         f"cylinder's walls are natural boundaries), got {val['domain.boundary']!r}")


def parse_axisymmetric_shape(key: str, spec, dim: int, axisym: bool) -> Shape:
    """``parse_shape``; on the meridian half-plane the shape is 3D and symmetric about the z axis
    (its centre on the axis, an ellipsoid's x and y semi-axes equal): a 2D shape or one off the
    axis is refused in one line."""
    if not axisym:
        return parse_shape(key, spec, dim)
    if isinstance(spec, dict):
        for k in ("center", "semi_axes"):
            if isinstance(spec.get(k), (list, tuple)) and len(spec[k]) == 2:
                raise InputError(f"{key}.{k}", f"an axisymmetric scene is 3D (the vesicle revolved about "
                                 f"the z axis; the box is its meridian): give {k} as 3 numbers, got "
                                 f"{list(spec[k])} (a 2D scene)")
    shape = parse_shape(key, spec, 3)
    if shape.center is not None and (shape.center[0] != 0.0 or shape.center[1] != 0.0):
        raise InputError(f"{key}.center", f"must lie on the axis of an axisymmetric scene, [0, 0, z], "
                         f"got {list(shape.center)}")
    if shape.semi_axes is not None and shape.semi_axes[0] != shape.semi_axes[1]:
        raise InputError(f"{key}.semi_axes", f"must be symmetric about the z axis (x and y semi-axes "
                         f"equal) in an axisymmetric scene, got {list(shape.semi_axes)}")
    return shape
