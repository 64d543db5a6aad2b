"""Orthonormal real coordinates of the fields of a periodic Fourier grid (``mesh.spectral``).

For a real field v on N nodes, its real FFT v^ (rfft layout: the last axis halved) holds every
Fourier coefficient once up to conjugation, and Parseval's identity reads

    u . v = sum_k W_k Re(u^_k conj(v^_k)),   W_k = 2/N on the interior columns of the last axis,
                                              W_k = 1/N on its k = 0 column and (n even) Nyquist column,

each interior coefficient standing for itself and its conjugate partner. The coordinates

    y = T v = sqrt(W) * v^   (as the spectrum's float64 view: real and imaginary parts in turn)

are therefore orthonormal: T u . T v = u . v, and T^{-1} y = F^{-1}(y / sqrt(W)). An operator that
is diagonal in Fourier space, F^{-1} diag(s) F, is diag(s) in these coordinates, so a Krylov method
run in them (``nk.system.FourierSystem``) applies the Fourier preconditioner of ``nk.precond``
without a transform, and its dot products are plain BLAS dots. Scaling convention: y has
``2 * (N / n_last) * (n_last // 2 + 1)`` entries; the few that no real field reaches (the imaginary
parts of self-conjugate coefficients, the antisymmetric part of the k = 0 and Nyquist columns) are
zero for every T v up to round-off and are ignored by T^{-1}; ``project`` removes them from a
vector that is not a T v (a random one, or one a diagonal scaling has left off the range's
round-off), so that no operator T A T^{-1} shows their zero eigenvalues.
"""

from __future__ import annotations

import numpy as np


class FourierCoordinates:
    """y = sqrt(W) v^ of a ``FourierGrid`` (module docstring): ``forward`` (T), ``backward`` (T^{-1},
    with a Fourier symbol applied on the way), ``derivatives`` (T of the spectral d_i v) and
    ``project`` (onto T's range). sqrt(W) is ``scale`` = sqrt(2/N) on every column but the
    self-paired ones (``FourierGrid.edge_columns``), which take a further 1/sqrt(2): a scalar and
    a factor on a few percent of the entries, so no weight array is held; a symbol applied on the
    way is passed with the scalar folded in (``symbol * scale``, ``symbol * unscale``)."""

    def __init__(self, grid):
        self.grid = grid
        self.scale = float(np.sqrt(2.0 / grid.size))  # sqrt(W) off the edge columns
        self.unscale = 1.0 / self.scale
        self.size = 2 * int(np.prod(grid.half_shape))  # the number of coordinates
        self.dc = float(np.sqrt(1.0 / grid.size))  # sqrt(W) of the k = 0 coefficient: y[0] = sum(v) / sqrt(N)
        self._pairs = (*grid.half_shape, 2)
        # the index of -k (each axis i -> -i mod n) over the leading axes, C order: ``project``
        lead = np.arange(int(np.prod(grid.half_shape[:-1]))).reshape(grid.half_shape[:-1])
        axes = tuple(range(grid.dim - 1))
        self._mirror = np.roll(np.flip(lead, axes), 1, axes).ravel() if axes else lead.ravel()

    def forward(self, v: np.ndarray, mult=None) -> np.ndarray:
        """T v (``mult``: a paired symbol times ``scale``: T of the symbol's operator applied to v)."""
        return self.grid.forward_times(v, self.scale if mult is None else mult, EDGE).ravel()

    def forward_add(self, v: np.ndarray, out: np.ndarray, mult=None) -> np.ndarray:
        """out += T v (``mult`` as in ``forward``), in place; returns out."""
        return self.grid.forward_add(v, self.scale if mult is None else mult, out, EDGE)

    def backward(self, y: np.ndarray, mult=None, out: np.ndarray | None = None) -> np.ndarray:
        """T^{-1} y (``mult``: a paired symbol times ``unscale``: the symbol's operator applied on the
        way back); y is not written; ``out``: a work array to write into where the FFT library can
        (``FourierGrid.backward_times``)."""
        return self.grid.backward_times(y, self.unscale if mult is None else mult, out, 1.0 / EDGE)

    def project(self, y: np.ndarray) -> np.ndarray:
        """y projected, in place, orthogonally onto the range of T (the coordinates of real fields):
        on the self-paired columns every coefficient c_k is replaced by (c_k + conj(c_{-k})) / 2,
        which zeroes the imaginary part of a self-conjugate one; a few percent of the entries, no
        transform. T v is in the range up to round-off; a random start block or a preconditioned
        residual is kept there with this (outside it the products vanish: T^{-1} ignores those
        entries). Returns y."""
        view = self.grid.edge_view(y)
        for c in self.grid.edge_columns:
            column = view[:, c]  # the coefficients (k_1, ..., k_{d-1}, c), C order
            mirrored = column[self._mirror]  # c_{-k}
            np.conjugate(mirrored, out=mirrored)
            column += mirrored
            column *= 0.5
        return y

    def derivatives(self, v: np.ndarray, factor: float = 1.0) -> np.ndarray:
        """The rows T(factor d_i v), (dim, size), from one transform: the spectral derivative is
        the multiplier i k_i (the Nyquist mode zeroed, as ``FourierGrid.derivatives``), so no
        inverse transform is needed."""
        vh = self.grid.fft(v)
        rows = np.empty((len(self.grid.ik), self.size))
        for row, ik in zip(rows, self.grid.ik):
            spec = row.view(np.complex128).reshape(vh.shape)
            np.multiply(vh, (factor * self.scale) * ik, out=spec)
            self.grid.edges(row.reshape(self._pairs[:-2] + (-1,)), EDGE)
        return rows


EDGE = float(np.sqrt(0.5))  # sqrt(W) on the self-paired columns relative to the others
