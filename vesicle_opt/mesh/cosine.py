"""Mirror-symmetric grids: the cosine-series spectral discretisation of a box with natural boundaries.

``mesh.kind = "spectral"`` with ``domain.boundary = "natural"``. The box [lo, hi] (per axis, length
L) carries cell-centred nodes x_j = lo + (j + 1/2) h, h = L / n, and the Laplacian is diagonal in the
cosine basis cos(pi k (x - lo) / L), k = 0 .. n - 1:

    Delta_h = C^{-1} diag(sigma) C,   sigma(k) = -sum_i (pi k_i / L_i)^2,

with C the orthonormal DCT-II (``scipy.fft.dctn(type=2, norm="ortho")``; C^{-1} = C^T its
inverse). Each cosine is even about both faces of its axis, so a grid field is the restriction of
an even field on the doubled periodic box [2 lo - hi, hi] (period 2 L), whose nodes lo + h/2 + j h,
j = -n .. n - 1 are the mirror images of these: this Delta_h *is* the Fourier pseudo-spectral
Laplacian (the paper's Section 5, ``mesh.spectral``) of the doubled box applied to the even
extension (the DCT-II is the DFT of the even extension). A test checks it to round-off. The
discrete Neumann problem is the paper's natural-boundary case: grad phi . n = 0 on every face holds
for the even extension.

Scaling convention (what the scene's targets and every reported quantity mean): the weights are
m = 2^d prod(h) (each node stands for itself and its 2^d - 1 mirror images) and |Omega| is the
doubled box's 2^d prod(L) (``scene.Domain.volume``), so A = int phi, B, E_h, the volume, the area
and the energy are those of the full mirror-symmetric field on the doubled box, 2^d times the
box's own; the multipliers lambda_A = dE*/dalpha, lambda_B = dE*/dbeta are the same for both
(numerator and denominator scale alike). A vesicle centred at the corner ``lo`` (``initial.center``,
``constraints.target.center`` = lo) is one full vesicle of which the box holds one 2^d-th; the
box's far faces are mirror planes too, so the free space to the image across a far face is twice the
distance from the shape to that face.

What the mirror class cannot see: only mirror-symmetric fields are represented, so the second-order
check (``verify.lobpcg``) sees only mirror-symmetric perturbations; a "minimum" there is a minimum
within that class, not more (``verify.verdict.MIRROR_CLASS``, the summary's
``second_order_excluded``). The class has no translation or rotation modes (they are odd about a
mirror plane), so :meth:`CosineGrid.derivatives` returns none and nothing is excluded besides.

Topology: ``unfold`` reflects a grid field into the doubled box, where ``verify.topology`` counts.

The DCTs are scipy.fft's (one worker, ``WORKERS``) whatever ``solver.fft`` says (pyFFTW's planned
real-to-complex transforms are for the periodic grids only).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from vesicle_opt.mesh.base import TransformDiscretization, grid_points

KIND = "cosine"  # Discretization.kind of these grids (the summary's mesh_kind); the scene says "spectral"
WORKERS = 1  # DCT threads, as ``mesh.fftlib.WORKERS``


class CosineGrid:
    """DCT machinery of one mirror-symmetric grid (module docstring): the same interface as
    ``mesh.spectral.FourierGrid`` (fft / ifft / apply_symbol / symbol / laplacian / derivatives /
    nodes), with the spectrum in the DCT-II layout (a real array of the grid's shape)."""

    kind = KIND
    transforms = 0  # DCTs done by all mirror grids in this process (benchmarks: the transform count)
    transform_seconds = 0.0

    def __init__(self, box, n):
        self.box = tuple(tuple(map(float, b)) for b in box)
        self.shape = tuple(int(k) for k in n)
        self.dim = len(self.shape)
        self.lengths = np.array([b - a for a, b in self.box])
        self.h = self.lengths / np.array(self.shape)
        self.mirror_cells = 2**self.dim  # images of the box in the doubled periodic box
        self.cell = float(self.mirror_cells * np.prod(self.h))  # the weight m of a node (module doc)
        self.size = int(np.prod(self.shape))
        self.k = [(np.pi / L * np.arange(nd)).reshape([-1 if i == d else 1 for i in range(self.dim)])
                  for d, (nd, L) in enumerate(zip(self.shape, self.lengths))]
        sym = 0.0
        for k in self.k:
            sym = sym - k**2
        self.symbol = np.asarray(sym, float)  # Delta_h in the cosine basis (grid shape), <= 0
        self.laplacian_multiplier = self.symbol  # as ``apply_symbol`` takes it (``multiplier``)

    def fft(self, v: np.ndarray) -> np.ndarray:
        """The orthonormal DCT-II of a grid field (the spectrum ``apply_symbol`` multiplies)."""
        import scipy.fft as sfft  # with its first use (as in ``mesh.spectral``)

        t0 = time.perf_counter()
        out = sfft.dctn(np.reshape(v, self.shape), type=2, norm="ortho", workers=WORKERS)
        CosineGrid.transforms += 1
        CosineGrid.transform_seconds += time.perf_counter() - t0
        return out

    def ifft(self, vh: np.ndarray) -> np.ndarray:
        """The grid field of a DCT-II spectrum (its inverse, the DCT-III); vh may be overwritten."""
        import scipy.fft as sfft

        t0 = time.perf_counter()
        out = sfft.idctn(vh, type=2, norm="ortho", workers=WORKERS, overwrite_x=True).ravel()
        CosineGrid.transforms += 1
        CosineGrid.transform_seconds += time.perf_counter() - t0
        return out

    def multiplier(self, sym: np.ndarray) -> np.ndarray:
        """The symbol as ``apply_symbol`` multiplies it (a real spectrum: the symbol itself; the
        Fourier grid's pairs its values, ``mesh.spectral.FourierGrid.multiplier``)."""
        return sym

    def apply_symbol(self, v: np.ndarray, sym: np.ndarray, constant: float = 0.0, with_sum: bool = False):
        """C^{-1} diag(sym) C v (sym in the DCT layout: a real array of the grid's shape), plus
        ``constant`` at every node through the DC coefficient (sqrt(N) c for the orthonormal DCT).
        ``with_sum``: returns (result, sum of v), the sum read off the DC coefficient (sum / sqrt(N))."""
        vh = self.fft(v)
        total = float(vh.flat[0]) * np.sqrt(self.size)
        vh *= sym
        if constant:
            vh.flat[0] += constant * np.sqrt(self.size)
        out = self.ifft(vh)
        return (out, total) if with_sum else out

    def laplacian(self, v: np.ndarray) -> np.ndarray:
        """Delta_h v (symmetric: C is orthogonal)."""
        return self.apply_symbol(v, self.symbol)

    def quadratic_form(self, v: np.ndarray, sym: np.ndarray) -> float:
        """v^T C^{-1} diag(sym) C v = sum sym |C v|^2 (Parseval for the orthonormal DCT)."""
        vh = self.fft(v).ravel()
        return float(np.einsum("i,i,i->", vh, vh, np.ravel(sym)))  # one pass, no product array

    def derivatives(self, v: np.ndarray, scale: float = 1.0) -> list[np.ndarray]:
        """No translation modes: a shift of an even field is not even (module docstring)."""
        return []

    def nodes(self) -> np.ndarray:
        axes = [a + h * (np.arange(k) + 0.5) for (a, _), h, k in zip(self.box, self.h, self.shape)]
        return grid_points(axes)


@dataclass(frozen=True, eq=False)
class CosineDiscretization(TransformDiscretization):
    """A lumped discretisation on a mirror-symmetric grid, Delta_h applied by DCT (module docstring).
    ``fourier`` holds the :class:`CosineGrid` (the attribute the matrix-free code looks for)."""

    fourier: CosineGrid | None = None


def grid(box, n) -> CosineDiscretization:
    """``mesh.kind = 'spectral'`` with natural boundaries: the cosine-series grid of ``box``."""
    cg = CosineGrid(box, n)
    return CosineDiscretization.of_grid(cg, KIND, float(cg.mirror_cells * np.prod(cg.lengths)))


def resample(phi: np.ndarray, shape_from, shape_to) -> np.ndarray:
    """The cosine-series interpolant of a grid field on another cell-centred grid of the same box:
    per axis the orthonormal DCT-II truncated or zero-padded, times sqrt(n_to / n_from) (the
    orthonormal basis' amplitude), then the inverse on n_to points."""
    import scipy.fft as sfft  # with its first use

    v = np.asarray(phi, float).reshape(shape_from)
    for axis, num in enumerate(shape_to):
        n_x = v.shape[axis]
        if num == n_x:
            continue
        X = sfft.dct(v, type=2, norm="ortho", axis=axis, workers=WORKERS)
        m = min(num, n_x)
        X = X[(slice(None),) * axis + (slice(0, m),)]
        if num > n_x:
            pad = [(0, 0)] * v.ndim
            pad[axis] = (0, num - n_x)
            X = np.pad(X, pad)
        v = sfft.idct(X * np.sqrt(num / n_x), type=2, norm="ortho", axis=axis, workers=WORKERS)
    return np.ascontiguousarray(v).ravel()


def unfold(values: np.ndarray, shape) -> np.ndarray:
    """A grid field reflected into the doubled periodic box (module docstring): per axis the mirror
    image about the face ``lo`` put before it, shape 2 n; the doubled box's nodes, in C order, are
    lo + h/2 + j h, j = -n .. n - 1."""
    X = np.asarray(values).reshape(shape)
    for axis in range(X.ndim):
        X = np.concatenate([np.flip(X, axis=axis), X], axis=axis)
    return X
