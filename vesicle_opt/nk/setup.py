"""Setting up the matrix-free backend on a discretisation: operators, preconditioner, symmetries,
and the grids of nested iteration.

``prepare`` gives (disc, PhaseField, preconditioner, translations); FD grids are moved to FFT
(``mesh.spectral.fourier_grid``, equal to the sparse FD operator to round-off), and so is lumped P1
on a periodic tensor box (``fft_equivalent``): there the lumped P1 operator *is* the FD stencil
(K and the lumped weights equal to round-off, ``tests/mesh/test_fd.py``), so the scene is never
assembled; ``tensor_fft=False`` keeps it on the sparse path (``nk.precond.SparsePreconditioner``,
Chebyshev in 3D), as every unstructured mesh is. ``discretization_path`` names the path taken
(the summary's ``discretization_path``). Translations d_i phi
are null modes only where the discrete problem is translation invariant (grid shifts of Fourier
grids). ``coarse_levels`` and ``resample`` serve nested iteration on Fourier grids.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.mesh import discretize
from vesicle_opt.mesh.spectral import fourier_grid
from vesicle_opt.mesh.spectral import resample as fourier_resample
from vesicle_opt.model.lumped import LumpedOperators, PhaseField
from vesicle_opt.nk.precond import FourierPreconditioner, SparsePreconditioner


def on_fourier_grid(disc):
    """The discretisation with Delta_h applied by FFT where it is a periodic grid (FD -> FFT-FD)."""
    if disc.kind == "fd" and getattr(disc, "fourier", None) is None:
        return fourier_grid(disc.box, disc.grid_shape, "fd")  # equal to the sparse FD to round-off
    return disc


def fft_equivalent(scene) -> bool:
    """Lumped P1 with nodal quadrature on a periodic tensor box (no mesh file): the FD stencil."""
    return (scene.mesh.kind == "fem-p1" and scene.domain.boundary == "periodic" and not scene.mesh.file
            and scene.mesh.mass == "lumped" and scene.mesh.quadrature == "nodal")


def nk_discretization(scene, tensor_fft: bool = True):
    """The discretisation the matrix-free backend runs a scene on (module docstring)."""
    if tensor_fft and fft_equivalent(scene):
        return fourier_grid(scene.domain.box, scene.mesh.n, "fd")
    return on_fourier_grid(discretize(scene))


def discretization_path(scene, disc, prec) -> str:
    """'fft' (Fourier grids: spectral, FD), 'fft (lumped P1 on a periodic tensor box = FD stencil)',
    or 'sparse (<S^-1 kind>)' for meshes on the sparse path."""
    if getattr(disc, "fourier", None) is None:
        return f"sparse ({getattr(prec, 'kind', 'model')})"
    if scene.mesh.kind == "fem-p1":
        return "fft (lumped P1 on a periodic tensor box = FD stencil)"
    return "fft"


def prepare(scene, disc=None, tensor_fft: bool = True):
    """(disc, PhaseField, preconditioner, translations) for a scene; FD grids (and lumped P1 on a
    periodic tensor box, unless ``tensor_fft`` is False) go to FFT."""
    disc = on_fourier_grid(disc) if disc is not None else nk_discretization(scene, tensor_fft)
    ops = LumpedOperators(disc)
    pf = PhaseField(ops, scene.model.epsilon, scene.model.C)
    fourier = getattr(disc, "fourier", None)
    if fourier is not None:
        prec = FourierPreconditioner(fourier, disc.weights[0], scene.model.epsilon)
    else:
        prec = SparsePreconditioner(disc.K, disc.weights, scene.model.epsilon, disc.mesh_dim)
    # translations are null modes only where the discrete problem is translation invariant: the
    # spectral grid (trigonometric interpolation commutes with every shift, up to aliasing). A
    # tetrahedral mesh breaks the symmetry, so its gradient has parts along d_i phi that a
    # projection would freeze (measured: a stall at kkt_dual 3e-6), and so does the FD stencil,
    # invariant under whole-cell shifts only (measured: the 24^2 ellipse from a 32^2 solution
    # stalled at dual 2e-6 with the projection, converges to kkt 6e-12 without it)
    deriv = fourier if getattr(fourier, "kind", None) != "fd" else None

    def translations(phi, scale: float = 1.0, coordinates: bool = False):
        """scale * d_i phi as the columns of an (N, k) view of contiguous rows; None: none.
        ``coordinates``: their orthonormal Fourier coordinates instead (``mesh.coordinates``), as
        (k, size) rows (``nk.system.FourierSystem``)."""
        if coordinates:
            return None if deriv is None or not hasattr(deriv, "coordinates") else \
                deriv.coordinates.derivatives(phi, scale)
        rows = None if deriv is None else deriv.derivatives(phi, scale)
        if not rows:  # a mesh, or a mirror grid (``mesh.cosine``: no translation modes)
            return None
        return np.stack(rows).T  # (N, k) view of contiguous rows (what the CG projection reads)

    return disc, pf, prec, translations


def coarse_levels(disc, epsilon: float, min_n: int = 16) -> list[tuple[int, ...]]:
    """Grid shapes of the nested-iteration start, coarse to fine, excluding disc's own.

    Halve n while every side stays even and >= min_n and the coarse spacing still resolves
    the interface (h <= eps); only on Fourier grids (spectral or FD), where the Fourier interpolant
    carries a coarse solution to the fine grid.
    """
    if getattr(disc, "fourier", None) is None:
        return []
    shapes, n = [], tuple(disc.grid_shape)
    lengths = disc.fourier.lengths
    while all(k % 2 == 0 and k // 2 >= min_n for k in n) and max(lengths / (np.array(n) // 2)) <= epsilon:
        n = tuple(k // 2 for k in n)
        shapes.append(n)
    return shapes[::-1]


def resample(phi: np.ndarray, shape_from, shape_to, kind: str = "spectral") -> np.ndarray:
    """The trigonometric interpolant of a periodic grid field on another grid (same box):
    ``mesh.spectral.resample`` (the cosine series on the mirror grids, ``kind = "cosine"``)."""
    return fourier_resample(phi, shape_from, shape_to, kind)
