"""The symmetry images of a field on a periodic or mirror grid, for recognising a known branch.

The continuum problem (6)-(8) on a periodic box is invariant under translations, and the grid keeps
the reflections x_i -> -x_i and the exchange of axes of equal size and length (on a square 2D grid:
the square's group D4, rotations by 90 degrees and reflections). Two points that are images of each
other under these are one branch of the diagram (``branch.switch.known``). ``align(phi, ref)``
returns the image of phi nearest ref: for each of the point group's 2^d d! (at most) transforms,
the translation that maximises the periodic cross-correlation with ref (one FFT pair; grid
translations, exact symmetries of the discrete problem).

On a mirror grid (``mesh.cosine``: the box holds one 2^d-th of a vesicle centred at its corner,
natural boundaries) there are no translations and the reflections x_i -> -x_i map every field of the
class to itself; what is left is the exchange of axes with equal extent and spacing (the octant's
x <-> y on a square-based box: a prolate along x and one along y are one branch). ``align_mirror``
returns the image under those exchanges nearest ref (no FFT: the nodes map onto nodes one to one).
"""

from __future__ import annotations

import itertools

import numpy as np


def exchanges(shape, box) -> list:
    """The permutations of axes that map the grid onto itself (equal node count and length: equal
    extent and spacing)."""
    d = len(shape)
    lengths = [float(b[1] - b[0]) for b in np.asarray(box, float)]
    return [q for q in itertools.permutations(range(d))
            if all(shape[q[i]] == shape[i] and np.isclose(lengths[q[i]], lengths[i]) for i in range(d))]


def transforms(shape, box) -> list:
    """The point group's maps of grid arrays (flips per axis, exchanges of equal axes)."""
    d = len(shape)
    out = []
    for perm in exchanges(shape, box):
        for flips in itertools.product((False, True), repeat=d):
            axes = tuple(i for i in range(d) if flips[i])
            out.append(lambda a, perm=perm, axes=axes: np.flip(np.transpose(a, perm), axes) if axes else np.transpose(a, perm))
    return out


def align(phi: np.ndarray, ref: np.ndarray, shape, box) -> np.ndarray:
    """The image of phi under the grid's symmetries nearest ref in the l2 (uniform-weight) norm."""
    shape = tuple(int(n) for n in shape)
    A, R = np.asarray(phi, float).reshape(shape), np.asarray(ref, float).reshape(shape)
    FR = np.fft.rfftn(R)
    best, best_d = A, np.inf
    for T in transforms(shape, box):
        B = np.ascontiguousarray(T(A))
        corr = np.fft.irfftn(FR * np.conj(np.fft.rfftn(B)), s=shape, axes=tuple(range(len(shape))))
        shift = np.unravel_index(int(np.argmax(corr)), shape)
        C = np.roll(B, shift, axis=tuple(range(len(shape))))
        d = float(np.sum((C - R) ** 2))
        if d < best_d:
            best, best_d = C, d
    return best.ravel()


def align_mirror(phi: np.ndarray, ref: np.ndarray, shape, box) -> np.ndarray:
    """The image of phi under the mirror grid's exchanges of equal axes nearest ref (l2 norm)."""
    shape = tuple(int(n) for n in shape)
    A, R = np.asarray(phi, float).reshape(shape), np.asarray(ref, float).reshape(shape)
    images = [np.transpose(A, q) for q in exchanges(shape, box)]
    return min(images, key=lambda B: float(np.sum((B - R) ** 2))).ravel()
