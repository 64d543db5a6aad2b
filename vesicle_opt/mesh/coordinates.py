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
zero for every T v up to round-off and are ignored by T^{-1}.
"""

from __future__ import annotations

import numpy as np


class FourierCoordinates:
    """y = sqrt(W) v^ of a ``FourierGrid`` (module docstring): ``forward`` (T), ``backward`` (T^{-1},
    with a Fourier symbol applied on the way), ``derivatives`` (T of the spectral d_i v), and the
    paired weights ``scale`` = sqrt(W), ``unscale`` = 1/sqrt(W) that symbols are multiplied by."""

    def __init__(self, grid):
        self.grid = grid
        n_last = grid.shape[-1]
        w = np.full(n_last // 2 + 1, 2.0 / grid.size)
        w[0] = 1.0 / grid.size
        if n_last % 2 == 0:
            w[-1] = 1.0 / grid.size
        root = np.sqrt(w)
        self.scale = grid.multiplier(np.broadcast_to(root, grid.half_shape))  # sqrt(W), paired
        self.unscale = grid.multiplier(np.broadcast_to(1.0 / root, grid.half_shape))
        self.size = self.scale.size  # the number of coordinates
        self.dc = float(root[0])  # sqrt(W) of the k = 0 coefficient: y[0] = sum(v) / sqrt(N)

    def forward(self, v: np.ndarray, mult: np.ndarray | None = None) -> np.ndarray:
        """T v (``mult``: a paired multiplier that already holds sqrt(W), e.g. ``symbol * scale``)."""
        return self.grid.forward_times(v, self.scale if mult is None else mult).ravel()

    def forward_add(self, v: np.ndarray, out: np.ndarray, mult: np.ndarray | None = None) -> np.ndarray:
        """out += T v (``mult`` as in ``forward``), in place; returns out."""
        return self.grid.forward_add(v, self.scale if mult is None else mult, out)

    def backward(self, y: np.ndarray, mult: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
        """T^{-1} y (``mult``: a paired multiplier that already holds 1/sqrt(W)); y is not written;
        ``out``: a work array to write into where the FFT library can (``FourierGrid.backward_times``)."""
        return self.grid.backward_times(y, self.unscale if mult is None else mult, out)

    def derivatives(self, v: np.ndarray, factor: float = 1.0) -> np.ndarray:
        """The rows T(factor d_i v), (dim, size), from one transform: the spectral derivative is
        the multiplier i k_i (the Nyquist mode zeroed, as ``FourierGrid.derivatives``), so no
        inverse transform is needed."""
        vh = self.grid.fft(v)
        rows = np.empty((len(self.grid.ik), self.size))
        for row, ik in zip(rows, self.grid.ik):
            spec = row.view(np.complex128).reshape(vh.shape)
            np.multiply(vh, factor * ik, out=spec)
            row *= self.scale.ravel()
        return rows
