"""The real FFT libraries of the Fourier grids (``mesh.spectral``): scipy.fft, or FFTW through pyFFTW
(``solver.fft = "pyfftw"``, optional extra ``fftw``; the default "auto" takes it where installed),
planned once per grid shape and thread with FFTW_ESTIMATE (no planning time, and the same plan,
hence the same bits, in every run) and reused. ``fft_library`` selects one for a block of code
(``in_use`` says which); ``FFTWPlans`` holds a shape's plans and their aligned buffers;
``scratch_spectrum`` a thread's spectrum for scipy's c2r input.
"""

from __future__ import annotations

import contextlib
import threading

import numpy as np

from vesicle_opt import extras

WORKERS = 1  # FFT threads; the solver's timings in the README are measured with 1
FFT_LIBRARIES = ("scipy", "pyfftw")  # solver.fft: scipy.fft or FFTW through pyFFTW ("auto": the latter
# where installed; measured on the 64^3 torus solve, interleaved: pyFFTW / scipy 0.84)
_library = ["scipy"]  # the one in use in this process (``fft_library``, ``in_use``)


def fft_available(name: str) -> bool:
    """Whether the FFT library ``name`` can be used here (pyFFTW is an optional extra: installed
    *and* loading, ``extras.load_error``)."""
    return name in ("scipy", "auto") or (name == "pyfftw" and extras.load_error("pyfftw") is None)


def resolve_fft(name: str) -> str:
    """The library ``name`` stands for: "auto" is pyFFTW where it loads, else scipy (one warning
    line when it is installed but does not load, ``extras.usable``); "pyfftw" is refused with one
    line when it does not load (``extras.require``)."""
    if name == "auto":
        return "pyfftw" if extras.usable("pyfftw", "solver.fft", "scipy.fft") else "scipy"
    if name == "pyfftw":
        extras.require("pyfftw", "solver.fft", name)
    return name


@contextlib.contextmanager
def fft_library(name: str):
    """Run the block with the real FFTs of ``name`` (one of ``FFT_LIBRARIES`` or "auto"), then restore."""
    name = resolve_fft(name)
    if name not in FFT_LIBRARIES:
        raise ValueError(f"unknown FFT library {name!r}: one of {', '.join(FFT_LIBRARIES)} or auto")
    old, _library[0] = _library[0], name
    try:
        yield
    finally:
        _library[0] = old


PYFFTW_UNUSED = extras.PYFFTW_UNUSED
import_pyfftw = extras.import_pyfftw  # pyFFTW's import lives in ``extras`` (whether it loads)


class FFTWPlans:
    """FFTW plans of one grid shape (real to complex and back, one thread), with their aligned
    buffers: a transform copies its input into the plan's buffer, executes, and returns a copy of
    the output (so no caller ever holds a buffer the next transform overwrites). Plans are kept per
    thread (a buffer is never shared by two threads)."""

    _local = threading.local()

    def __init__(self, shape):
        pyfftw = self._pyfftw = import_pyfftw()
        half = (*shape[:-1], shape[-1] // 2 + 1)
        axes = tuple(range(len(shape)))
        self.real_in = pyfftw.empty_aligned(shape, dtype="float64")
        self.spec_out = pyfftw.empty_aligned(half, dtype="complex128")
        self.spec_in = pyfftw.empty_aligned(half, dtype="complex128")
        # the float64 views of the two spectrum buffers (what a paired symbol multiplies)
        self.spec_out_pairs, self.spec_in_pairs = self.spec_out.view(np.float64), self.spec_in.view(np.float64)
        self.real_out = pyfftw.empty_aligned(shape, dtype="float64")
        self.forward = pyfftw.FFTW(self.real_in, self.spec_out, axes=axes, direction="FFTW_FORWARD",
                                   flags=("FFTW_ESTIMATE",), threads=WORKERS)
        # a multi-dimensional complex-to-real transform always overwrites its input (FFTW)
        self.backward = pyfftw.FFTW(self.spec_in, self.real_out, axes=axes, direction="FFTW_BACKWARD",
                                    flags=("FFTW_ESTIMATE", "FFTW_DESTROY_INPUT"), threads=WORKERS)

    @classmethod
    def of(cls, shape) -> "FFTWPlans":
        """This thread's plans of ``shape`` (made with the first call)."""
        by_shape = getattr(cls._local, "by_shape", None)
        if by_shape is None:
            by_shape = cls._local.by_shape = {}
        plans = by_shape.get(shape)
        if plans is None:
            plans = by_shape[shape] = cls(shape)
        return plans

    def forward_into(self, v: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The r2c transform of v (preserved: an out-of-place r2c keeps its input) into ``out``. v is
        handed to the plan: pyFFTW reads an aligned v in place and copies a misaligned one into the
        plan's input buffer (64^3 torus solve 1.19 s against 1.34 s with the copy into ``real_in``
        done here first). An aligned v becomes the plan's input, so the input is reset to
        ``real_in`` after such a call: the next misaligned input is then copied there, never into
        a caller's array (a test holds this)."""
        self.forward(input_array=v.reshape(self.real_in.shape), output_array=out)
        if self.forward.input_array is not self.real_in:
            self.forward.update_arrays(self.real_in, out)
        return out

    def rfftn(self, v: np.ndarray) -> np.ndarray:
        """The r2c transform of v into a new aligned array the caller owns (as ``backward_from_buffer``)."""
        return self.forward_into(v, self._pyfftw.empty_aligned(self.spec_out.shape, dtype="complex128"))

    def irfftn(self, vh: np.ndarray) -> np.ndarray:
        self.spec_in[...] = vh
        return self.backward_from_buffer()

    def backward_from_buffer(self, out: np.ndarray | None = None) -> np.ndarray:
        """The c2r transform of ``spec_in`` (normalised by 1/N, as scipy's irfftn), written straight
        into a new aligned array that the caller owns (the plan's output is moved to it: no copy of
        the result out of a buffer, the pass that cost the pyFFTW path ~0.2 ms a transform at 64^3),
        or into ``out`` where given and aligned (a caller's reused work array)."""
        if out is None or out.size != self.real_out.size or \
                not self._pyfftw.is_byte_aligned(out, self._pyfftw.simd_alignment):
            out = self._pyfftw.empty_aligned(self.real_out.shape, dtype="float64")
        self.backward(output_array=out.reshape(self.real_out.shape))
        return out


def in_use() -> str:
    """The FFT library of this process's transforms now: "scipy" or "pyfftw" (``fft_library``)."""
    return _library[0]


_SCRATCH = threading.local()


def scratch_spectrum(half_shape) -> np.ndarray:
    """This thread's complex spectrum of ``half_shape`` for scipy's c2r input (which the transform
    may overwrite: ``FourierGrid.backward_times``), made with the first call."""
    scratch = _SCRATCH.__dict__.get(half_shape)
    if scratch is None:
        scratch = _SCRATCH.__dict__[half_shape] = np.empty(half_shape, np.complex128)
    return scratch
