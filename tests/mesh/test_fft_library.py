"""The optional FFT library (``solver.fft = "pyfftw"``, ``mesh.spectral.fft_library``): FFTW's
transforms agree with scipy.fft's to round-off on the operators the solver applies (a second
implementation sharing no code), a whole solve gives the same KKT point, plans are reused, and the
key is refused in one line where pyFFTW is missing."""

import importlib.util

import numpy as np
import pytest

from vesicle_opt import scene as S
from vesicle_opt.api import solve
from vesicle_opt import extras
from vesicle_opt.errors import InputError
from vesicle_opt.mesh import fftlib, spectral
from vesicle_opt.mesh.spectral import fft_library, fourier_grid

needs_pyfftw = pytest.mark.skipif(importlib.util.find_spec("pyfftw") is None, reason="pyFFTW not installed")
BOX3 = ((-np.pi, np.pi),) * 3
ROUND = 1e-13  # two FFT implementations differ by O(eps_mach log N) relative: measured ~1e-15


@needs_pyfftw
@pytest.mark.parametrize("n", [(8, 10, 12), (9, 7, 6)])
def test_pyfftw_transforms_equal_scipy_to_roundoff(n, rng):
    f = fourier_grid(BOX3, n, "spectral").fourier
    v = rng.standard_normal(f.size)
    ref_lap, ref_d = f.laplacian(v), f.derivatives(v)
    with fft_library("pyfftw"):
        lap, d = f.laplacian(v), f.derivatives(v)
        vh = f.fft(v)
        vh2 = f.fft(2 * v)  # a second transform must not overwrite the first one's output
    scale = np.abs(f.symbol).max() * np.abs(v).max()
    assert np.abs(lap - ref_lap).max() <= ROUND * scale
    for a, b in zip(d, ref_d):
        assert np.abs(a - b).max() <= ROUND * np.sqrt(scale) * np.abs(v).max()
    np.testing.assert_allclose(vh2, 2 * vh, rtol=0, atol=ROUND * np.abs(vh).max())
    assert fftlib.FFTWPlans.of(tuple(n)) is fftlib.FFTWPlans.of(tuple(n))  # planned once, reused
    assert fftlib.in_use() == "scipy"  # the context restores the default


@needs_pyfftw
def test_pyfftw_solve_reaches_the_same_kkt_point():
    sets = ["mesh.kind='spectral'", "mesh.n=16", "solver.backend='newton-krylov'", "solver.second_order=false"]
    a = solve(S.load("torus-table1-3d", [*sets, "solver.fft='scipy'"]))
    b = solve(S.load("torus-table1-3d", [*sets, "solver.fft='pyfftw'"]))
    assert a.converged and b.converged
    assert (a.extra["fft_library"], b.extra["fft_library"]) == ("scipy", "pyfftw")  # the summary says which ran
    assert spectral.resolve_fft("auto") == "pyfftw"  # the default takes pyFFTW where it is installed
    # tol 1e-8: two KKT points of one problem within the tolerance agree in E to ~tol^2 relative;
    # the iterates differ only by FFT round-off (measured |dE|/E ~1e-14)
    assert abs(a.energy - b.energy) <= 1e-10 * abs(a.energy)


def test_fft_key_is_checked(monkeypatch):
    sets = ["mesh.kind='spectral'", "mesh.n=16"]
    with pytest.raises(InputError, match="solver.fft"):
        S.load("torus-table1-3d", [*sets, "solver.fft='mkl'"])
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pyfftw" else real(name, *a))
    monkeypatch.setattr(extras, "_outcome", {})  # the outcome of the import, found afresh
    with pytest.raises(InputError, match="solver.fft.*fftw"):
        S.load("torus-table1-3d", [*sets, "solver.fft='pyfftw'"])
    assert spectral.resolve_fft("auto") == "scipy"  # without pyFFTW the default is scipy's
    with pytest.raises(ValueError, match="mkl"):
        with fft_library("mkl"):
            pass


def _misaligned(x, alignment):
    """A copy of x whose data pointer is not a multiple of ``alignment`` bytes."""
    buf = np.zeros(x.size + 8)
    off = next(k for k in range(1, 8) if buf[k:].ctypes.data % alignment)
    out = buf[off:off + x.size]
    out[:] = x
    return out


@needs_pyfftw
def test_pyfftw_results_are_the_callers_own(rng):
    """Each pyFFTW transform writes into a new array (the plan's output is moved to it), and an
    aligned input, which the plan reads in place, is never written by a later transform (pyFFTW
    copies a misaligned input into the plan's input buffer): a result or an input held by a
    caller is never overwritten."""
    import pyfftw
    f = fourier_grid(((-1.0, 1.0),) * 3, (8, 6, 10), "spectral").fourier
    u = _misaligned(rng.standard_normal(f.size), pyfftw.simd_alignment)
    v = _misaligned(rng.standard_normal(f.size), pyfftw.simd_alignment)
    aligned = pyfftw.empty_aligned(f.size)
    aligned[:] = u
    u0, v0 = u.copy(), v.copy()
    with fft_library("pyfftw"):
        f.fft(aligned)
        f.fft(v)
        f.apply_symbol(aligned, f.symbol)
        f.apply_symbol(v, f.symbol)
        uh = f.fft(u)
        uh_copy, back = uh.copy(), f.ifft(f.fft(u))
        back_copy = back.copy()
        f.apply_symbol(v, f.symbol)
        f.ifft(f.fft(v))
    assert np.array_equal(uh, uh_copy) and np.array_equal(back, back_copy)
    assert np.array_equal(aligned, u0) and np.array_equal(u, u0) and np.array_equal(v, v0)


LIBRARIES = ["scipy", pytest.param("pyfftw", marks=needs_pyfftw)]


@pytest.mark.parametrize("library", LIBRARIES)
@pytest.mark.parametrize("n", [(8, 10, 12), (9, 7, 6)])
def test_a_paired_symbol_is_the_same_product(library, n, rng):
    """``multiplier(sym)`` (each value twice: one float64 multiply over the spectrum's real view)
    gives what the complex-by-real product of ``sym`` gives, constant term included, and the sum of
    v read off the transform's k = 0 coefficient (``with_sum``) is the sum of v."""
    import math
    f = fourier_grid(BOX3, n, "spectral").fourier
    v = rng.standard_normal(f.size) + 3.0  # a mean, so the k = 0 coefficient is not small
    sym = -rng.random(f.symbol.shape) * 10.0
    with fft_library(library):
        ref = f.apply_symbol(v, sym, 0.25)
        out, total = f.apply_symbol(v, f.multiplier(sym), 0.25, with_sum=True)
        lap = f.laplacian(v)
        lap_ref = f.apply_symbol(v, f.symbol)
    scale = np.abs(sym).max() * np.abs(v).max()
    # the same products and the same transforms: equal to a few units of round-off (measured 0)
    assert np.abs(out - ref).max() <= 4 * np.finfo(float).eps * scale
    assert np.abs(lap - lap_ref).max() <= 4 * np.finfo(float).eps * np.abs(f.symbol).max() * np.abs(v).max()
    # the DC coefficient is the sum formed by the transform's additions: within log2(N) u sum|v|
    bound = math.ceil(math.log2(f.size)) * np.finfo(float).eps * np.abs(v).sum()
    assert abs(total - math.fsum(v)) <= bound, (total, math.fsum(v), bound)


def test_the_mirror_grid_takes_the_same_calls(rng):
    """The cosine grid (``mesh.cosine``) has the same ``multiplier`` (the symbol itself: its spectrum
    is real) and ``with_sum`` (the DC coefficient of the orthonormal DCT is sum / sqrt(N))."""
    import math
    from vesicle_opt.mesh import cosine
    f = cosine.grid(((0.0, 1.0), (0.0, 2.0), (0.0, 1.5)), (6, 8, 5)).fourier
    v = rng.standard_normal(f.size) + 2.0
    assert f.multiplier(f.symbol) is f.symbol and f.laplacian_multiplier is f.symbol
    out, total = f.apply_symbol(v, f.symbol, 0.5, with_sum=True)
    assert np.array_equal(out, f.apply_symbol(v, f.symbol, 0.5))
    # an orthonormal DCT's DC coefficient times sqrt(N): within log2(N) u sum|v| plus the scaling's u
    bound = (math.ceil(math.log2(f.size)) + 2) * np.finfo(float).eps * np.abs(v).sum()
    assert abs(total - math.fsum(v)) <= bound
