"""Periodic grids whose Laplacian is diagonal in Fourier space: pseudo-spectral and FD-by-FFT.

Nodes x_j = lo + j h per direction (C order, as ``fd.grid``), weights m = prod(h) (nodal
quadrature: the grid sum, the trapezoid rule, spectrally accurate for periodic integrands).
The discrete Laplacian Delta_h = F^{-1} diag(sigma) F is applied by real FFTs, O(N log N):

* ``spectral`` (the paper's Section 5): sigma(k) = -|k|^2, k the integer wavenumbers times 2 pi / L;
* ``fd``: sigma(k) = -sum_i (4 / h_i^2) sin^2(k_i h_i / 2), the symbol of the (2d+1)-point stencil,
  so this equals ``fd.grid``'s sparse Laplacian to round-off (a test checks it).

The real FFTs are scipy.fft's or FFTW's through pyFFTW (``mesh.fftlib``: ``solver.fft``, plans
reused, ``fft_library``). Both compute the unnormalised forward and the 1/N-normalised inverse transform.
scipy.fft is imported where it is first used, so a run on pyFFTW never loads it (with the
scipy.special it imports, ~0.07 s of every CLI start-up, measured); ``resample`` (nested
iteration's coarse-to-fine step) uses numpy.fft, so a nested pyFFTW solve does not either.

Both Laplacians are symmetric, so in the lumped framework of Definition 2.2 K = -m Delta_h (m constant) and
Delta_h^T = Delta_h. :func:`grid` wraps a :class:`FourierGrid` into a
:class:`~vesicle_opt.discretization.Discretization` whose K is a ``LinearOperator`` (never a dense
matrix), so ``functionals.evaluate``/``gradients`` and ``kkt.kkt_residual`` work unchanged on it.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass

import numpy as np

from vesicle_opt.mesh import cosine
from vesicle_opt.mesh.base import TransformDiscretization, grid_points
from vesicle_opt.mesh.coordinates import FourierCoordinates
from vesicle_opt.mesh.fftlib import (FFT_LIBRARIES, WORKERS, FFTWPlans, fft_available, fft_library,  # noqa: F401
                                     import_pyfftw, in_use, resolve_fft, scratch_spectrum)

class FourierGrid:
    """FFT machinery of one periodic grid: Laplacian symbol, spectral derivatives."""

    def __init__(self, box, n, kind: str = "spectral"):
        if kind not in ("spectral", "fd"):
            raise ValueError(f"unknown Fourier grid kind {kind!r}")
        self.kind = kind
        self.box = tuple(tuple(map(float, b)) for b in box)
        self.shape = tuple(int(k) for k in n)
        self.dim = len(self.shape)
        self.lengths = np.array([b - a for a, b in self.box])
        self.h = self.lengths / np.array(self.shape)
        self.cell = float(np.prod(self.h))
        self.size = int(np.prod(self.shape))
        ks = []
        for d, (nd, Ld) in enumerate(zip(self.shape, self.lengths)):
            f = np.fft.rfftfreq(nd, 1.0 / nd) if d == self.dim - 1 else np.fft.fftfreq(nd, 1.0 / nd)
            ks.append(2 * np.pi / Ld * f)
        self.k = [k.reshape([-1 if i == d else 1 for i in range(self.dim)]) for d, k in enumerate(ks)]
        sym = 0.0
        for d, k in enumerate(self.k):
            if kind == "spectral":
                sym = sym - k**2
            else:
                sym = sym - (4 / self.h[d] ** 2) * np.sin(k * self.h[d] / 2) ** 2
        self.symbol = np.asarray(sym, float)  # Delta_h in Fourier space (rfft layout), <= 0
        self.half_shape = (*self.shape[:-1], self.shape[-1] // 2 + 1)  # the rfft layout
        self._pairs_shape = (*self.half_shape[:-1], 2 * self.half_shape[-1])  # a ``multiplier``'s shape
        # the last axis's self-paired columns (k = 0 and, n even, Nyquist): each coefficient there is
        # its own term of the full spectrum, each other column's stands for two (Parseval)
        self.edge_columns = (0, self.shape[-1] // 2) if self.shape[-1] % 2 == 0 else (0,)
        self.laplacian_multiplier = self.multiplier(self.symbol)  # Delta_h's, as ``apply_symbol`` takes it
        # spectral first derivatives (Nyquist mode zeroed so they stay real and skew)
        self.ik = []  # i k_d per axis (rfft layout, broadcast shapes), the Nyquist mode zeroed
        for d, k in enumerate(self.k):
            kk = k.copy()
            nd = self.shape[d]
            if nd % 2 == 0 and d != self.dim - 1:
                kk[tuple(nd // 2 if i == d else 0 for i in range(self.dim))] = 0.0
            if nd % 2 == 0 and d == self.dim - 1:
                kk[..., -1] = 0.0
            self.ik.append(1j * kk)

    # --- transforms -----------------------------------------------------------------------
    transforms = 0  # real FFTs done by all grids in this process (benchmarks: the FFT count)
    transform_seconds = 0.0  # and their wall time (benchmarks: the FFT floor, timed where it is spent)

    def fft(self, v: np.ndarray) -> np.ndarray:
        t0 = time.perf_counter()
        if in_use() == "pyfftw":
            out = FFTWPlans.of(self.shape).rfftn(v.reshape(self.shape))
        else:
            import scipy.fft as sfft  # with its first use (module docstring)
            out = sfft.rfftn(v.reshape(self.shape), workers=WORKERS)
        FourierGrid.transforms += 1
        FourierGrid.transform_seconds += time.perf_counter() - t0
        return out

    def ifft(self, vh: np.ndarray) -> np.ndarray:
        """The real field of the half spectrum vh; vh may be overwritten (every caller passes a
        spectrum of its own: scipy's c2r transform then needs no copy of it)."""
        t0 = time.perf_counter()
        if in_use() == "pyfftw":
            out = FFTWPlans.of(self.shape).irfftn(vh).ravel()
        else:
            import scipy.fft as sfft
            out = sfft.irfftn(vh, s=self.shape, workers=WORKERS, overwrite_x=True).ravel()
        FourierGrid.transforms += 1
        FourierGrid.transform_seconds += time.perf_counter() - t0
        return out

    def multiplier(self, sym: np.ndarray) -> np.ndarray:
        """A real symbol (rfft layout) as ``apply_symbol`` multiplies it fastest: each value twice,
        for the real and the imaginary part of its coefficient (the spectrum's float64 view), so
        the product is a float64 multiply with no complex-by-real cast (64^3: 0.07 against 0.13
        ms a product, measured). For a symbol applied many times (a Newton step's products and
        preconditioner): formed once, one pass."""
        return np.repeat(np.asarray(sym, float).reshape(self.half_shape), 2, axis=-1)

    def _paired(self, sym: np.ndarray) -> bool:
        return sym.shape == self._pairs_shape

    def apply_symbol(self, v: np.ndarray, sym: np.ndarray, constant: float = 0.0, with_sum: bool = False):
        """F^{-1} diag(sym) F v (+ ``constant``, added to every node through the k = 0 coefficient:
        no pass over the field) for a real, even symbol: in the rfft layout, or as ``multiplier``
        made it. The product is formed in place: in the transform's own spectrum (scipy) or from
        FFTW's output buffer straight into its input buffer (pyFFTW), so the spectrum is neither
        copied out nor back; only the two transforms are timed (``transform_seconds``), as ``fft``
        and ``ifft`` time them. ``with_sum``: returns (result, sum of v), the sum read off the
        transform's k = 0 coefficient (no pass over v)."""
        paired = self._paired(sym)
        if in_use() != "pyfftw":
            vh = self.fft(v)
            total = float(vh.flat[0].real)
            if paired:
                re_im = vh.view(np.float64)
                np.multiply(re_im, sym, out=re_im)
            else:
                vh *= sym
            if constant:
                vh.flat[0] += constant * self.size  # the unnormalised DC of a constant field
            out = self.ifft(vh)
            return (out, total) if with_sum else out
        plans = FFTWPlans.of(self.shape)
        t0 = time.perf_counter()
        plans.forward_into(v, plans.spec_out)
        t1 = time.perf_counter()
        total = float(plans.spec_out.flat[0].real)
        if paired:
            np.multiply(plans.spec_out_pairs, sym, out=plans.spec_in_pairs)
        else:
            np.multiply(plans.spec_out, sym, out=plans.spec_in)
        if constant:
            plans.spec_in.flat[0] += constant * self.size
        t2 = time.perf_counter()
        out = plans.backward_from_buffer().ravel()
        FourierGrid.transforms += 2
        FourierGrid.transform_seconds += (t1 - t0) + (time.perf_counter() - t2)
        return (out, total) if with_sum else out

    def edge_view(self, re_im: np.ndarray) -> np.ndarray:
        """A spectrum's real view (``multiplier``'s layout, any shape of it) as complex rows, one a
        column of the last axis: ``[:, c]`` is column c as one strided vector (one ufunc loop;
        slicing the real view's two numbers per row looped 4096 times over pairs at 64^3, 10x slower)."""
        return re_im.reshape(-1, self._pairs_shape[-1]).view(np.complex128)

    def edges(self, re_im: np.ndarray, edge: float) -> None:
        """The last axis's k = 0 and (n even) Nyquist columns of a spectrum's real view times edge."""
        if edge != 1.0:
            view = self.edge_view(re_im)
            for c in self.edge_columns:
                view[:, c] *= edge

    def forward_times(self, v: np.ndarray, mult, edge: float = 1.0) -> np.ndarray:
        """mult * F v as a new float64 array of ``multiplier``'s shape (the spectrum's real view);
        mult a paired multiplier or a scalar, ``edge`` a further factor on the k_last = 0 and
        Nyquist columns (``edge_columns``): one transform and one multiply out of its output."""
        re_im = self.fft(v).view(np.float64)  # pyFFTW: written straight into a new array (``fft``)
        np.multiply(re_im, mult, out=re_im)  # in place: the spectrum is still in cache
        self.edges(re_im, edge)
        return re_im

    def forward_add(self, v: np.ndarray, mult, out: np.ndarray, edge: float = 1.0) -> np.ndarray:
        """out += mult * F v (``forward_times``' layout and factors; out flat or shaped): the product
        formed in the transform's own output (pyFFTW: its buffer), so no new array is written."""
        if in_use() != "pyfftw":
            re_im = self.fft(v).view(np.float64)
        else:
            plans = FFTWPlans.of(self.shape)
            t0 = time.perf_counter()
            plans.forward_into(v, plans.spec_out)
            FourierGrid.transforms += 1
            FourierGrid.transform_seconds += time.perf_counter() - t0
            re_im = plans.spec_out_pairs
        re_im *= mult
        self.edges(re_im, edge)
        out_pairs = out.reshape(self._pairs_shape)
        out_pairs += re_im
        return out

    def backward_times(self, pairs: np.ndarray, mult, out: np.ndarray | None = None, edge: float = 1.0) -> np.ndarray:
        """F^{-1} (mult * pairs) for a spectrum given as its real view (``multiplier``'s shape, read
        only), mult a paired multiplier or a scalar and ``edge`` as in ``forward_times``: the
        multiply written straight into the transform's input. ``out``: a work array
        (``empty_field``) the result is written into where the library can (pyFFTW); the result is
        returned either way."""
        pairs = pairs.reshape(self._pairs_shape)
        if in_use() != "pyfftw":  # into this thread's scratch spectrum (the c2r may overwrite it)
            scratch = scratch_spectrum(self.half_shape).view(np.float64)
            np.multiply(pairs, mult, out=scratch)
            self.edges(scratch, edge)
            return self.ifft(scratch.view(np.complex128))
        plans = FFTWPlans.of(self.shape)
        np.multiply(pairs, mult, out=plans.spec_in_pairs)
        self.edges(plans.spec_in_pairs, edge)
        t0 = time.perf_counter()
        out = plans.backward_from_buffer(out).ravel()
        FourierGrid.transforms += 1
        FourierGrid.transform_seconds += time.perf_counter() - t0
        return out

    def empty_field(self) -> np.ndarray | None:
        """An uninitialised field (N,) for ``backward_times`` to write into where the library in use
        can (pyFFTW: aligned as its plans want); None where it cannot (scipy's c2r returns its own)."""
        if in_use() == "pyfftw":
            return import_pyfftw().empty_aligned(self.size, dtype="float64")
        return None

    @functools.cached_property
    def coordinates(self) -> FourierCoordinates:
        """The orthonormal real coordinates of this grid's fields (``mesh.coordinates``)."""
        return FourierCoordinates(self)

    def laplacian(self, v: np.ndarray) -> np.ndarray:
        """Delta_h v (symmetric)."""
        return self.apply_symbol(v, self.laplacian_multiplier)

    def derivatives(self, v: np.ndarray, scale: float = 1.0) -> list[np.ndarray]:
        """Spectral partial derivatives d_i v (the translation modes of a field v), times ``scale``
        (folded into the wavenumbers: no pass over the fields)."""
        vh = self.fft(v)
        return [self.ifft((scale * ik if scale != 1.0 else ik) * vh) for ik in self.ik]

    def nodes(self) -> np.ndarray:
        axes = [a + h * np.arange(k) for (a, _), h, k in zip(self.box, self.h, self.shape)]
        return grid_points(axes)


@dataclass(frozen=True, eq=False)
class FourierDiscretization(TransformDiscretization):
    """A lumped discretisation on a periodic grid with Delta_h applied by FFT (see module doc)."""

    fourier: FourierGrid | None = None


def even_fft_size(x: float) -> int:
    """The least even integer >= x whose prime factors are 2, 3, 5 (a fast FFT length that a
    nested iteration can halve); 2 for x <= 2."""
    k = max(2, 2 * int(np.ceil(x / 2)))
    while True:
        r = k
        for p in (2, 3, 5):
            while r % p == 0:
                r //= p
        if r == 1:
            return k
        k += 2


def resample(phi: np.ndarray, shape_from, shape_to, kind: str = "spectral") -> np.ndarray:
    """The trigonometric interpolant of a periodic grid field on another grid of the same box
    (C-ordered nodes): per axis, the rfft truncated or zero-padded, the unpaired Nyquist bin of an
    even length split (up) or united (down), as ``scipy.signal.resample`` does, without importing
    scipy.signal (0.3 s of start-up). ``kind`` = the discretisation's kind: ``"cosine"`` (mirror
    grids) takes the cosine-series interpolant (``mesh.cosine.resample``)."""
    if kind == cosine.KIND:
        return cosine.resample(phi, shape_from, shape_to)
    v = np.asarray(phi, float).reshape(shape_from)
    for axis, num in enumerate(shape_to):
        n_x = v.shape[axis]
        if num == n_x:
            continue
        m = min(num, n_x)
        X = np.fft.rfft(v, axis=axis)  # numpy's pocketfft: a solve on pyFFTW then never imports scipy.fft
        X = X[(slice(None),) * axis + (slice(0, m // 2 + 1),)]
        if m % 2 == 0:
            X[(slice(None),) * axis + (m // 2,)] *= 2.0 if num < n_x else 0.5
        v = np.fft.irfft(X * (num / n_x), n=num, axis=axis)
    return np.ascontiguousarray(v).ravel()


def fourier_grid(box, n, kind: str = "spectral"):
    """The ``spectral`` (or FFT-applied ``fd``) discretisation of a periodic box; ``kind = "cosine"``:
    the mirror-symmetric grid of ``mesh.cosine`` (natural boundaries), so that a coarse level of any
    of them is ``fourier_grid(disc.box, shape, disc.kind)``."""
    if kind == cosine.KIND:
        return cosine.grid(box, n)
    fg = FourierGrid(box, n, kind)
    return FourierDiscretization.of_grid(fg, kind, float(np.prod(fg.lengths)))


def grid(box, n) -> FourierDiscretization:
    """``mesh.kind = 'spectral'``: the Fourier pseudo-spectral discretisation of a periodic box."""
    return fourier_grid(box, n, "spectral")
