"""The symmetry images of a field on a periodic grid, for recognising a known branch.

The continuum problem (6)-(8) on a periodic box is invariant under translations, and the grid keeps
the reflections x_i -> -x_i and the exchange of axes of equal size and length (on a square 2D grid:
the square's group D4, rotations by 90 degrees and reflections). Two points that are images of each
other under these are one branch of the diagram (``branch.switch.known``). ``align(phi, ref)``
returns the image of phi nearest ref: for each of the point group's 2^d d! (at most) transforms,
the translation that maximises the periodic cross-correlation with ref (one FFT pair; grid
translations, exact symmetries of the discrete problem).
"""

from __future__ import annotations

import itertools

import numpy as np


def transforms(shape, box) -> list:
    """The point group's maps of grid arrays (flips per axis, exchanges of equal axes)."""
    d = len(shape)
    lengths = [float(b[1] - b[0]) for b in np.asarray(box, float)]
    perms = [q for q in itertools.permutations(range(d))
             if all(shape[q[i]] == shape[i] and np.isclose(lengths[q[i]], lengths[i]) for i in range(d))]
    out = []
    for perm in perms:
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
