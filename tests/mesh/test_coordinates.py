"""The orthonormal Fourier coordinates y = sqrt(W) F v (``mesh.coordinates``): Parseval's identity
(T orthogonal) to round-off, T^{-1} T = I, Fourier multipliers diagonal in y, and the translation
rows equal to T of the spectral derivatives that ``FourierGrid.derivatives`` forms by inverse
transforms (a second implementation), on both FFT libraries and odd and even sizes."""

import importlib.util

import numpy as np
import pytest

from vesicle_opt.mesh.spectral import fft_library, fourier_grid

LIBRARIES = ["scipy", pytest.param("pyfftw", marks=pytest.mark.skipif(
    importlib.util.find_spec("pyfftw") is None, reason="pyFFTW not installed"))]
SHAPES = [(8, 10, 12), (9, 7, 5), (12, 16)]
U = np.finfo(float).eps
ROUND = 100 * U  # an FFT's relative round-off is O(u log N) (measured ~1e-15 at these sizes)


def _grid(n, kind="spectral"):
    return fourier_grid(tuple((0.0, 2.0 + d) for d in range(len(n))), n, kind).fourier


@pytest.mark.parametrize("library", LIBRARIES)
@pytest.mark.parametrize("n", SHAPES)
def test_coordinates_are_orthonormal_and_invertible(library, n, rng):
    f = _grid(n)
    T = f.coordinates
    u, v = rng.standard_normal(f.size), rng.standard_normal(f.size)
    with fft_library(library):
        Tu, Tv = T.forward(u), T.forward(v)
        back = T.backward(Tv)
        Tv_copy = Tv.copy()
        T.backward(Tv, out=f.empty_field())  # y is read, never written
    assert Tu.size == T.size == 2 * np.prod(f.half_shape)
    assert abs(Tu @ Tv - u @ v) <= ROUND * np.linalg.norm(u) * np.linalg.norm(v)  # Parseval
    assert abs(Tv @ Tv - v @ v) <= ROUND * (v @ v)
    assert np.abs(back - v).max() <= ROUND * np.abs(v).max()
    assert np.array_equal(Tv, Tv_copy)
    assert abs(Tu[0] - u.sum() / np.sqrt(f.size)) <= ROUND * np.abs(u).sum() / np.sqrt(f.size)  # T.dc's entry


@pytest.mark.parametrize("library", LIBRARIES)
@pytest.mark.parametrize("n", SHAPES)
def test_a_fourier_multiplier_is_diagonal_in_the_coordinates(library, n, rng):
    """T F^{-1} diag(s) F v = s * T v: the Laplacian's symbol (``laplacian_multiplier``) applied in
    y against ``laplacian`` in nodal values; ``forward_add`` adds T v in place."""
    f = _grid(n)
    T = f.coordinates
    v = rng.standard_normal(f.size)
    with fft_library(library):
        lap = f.laplacian(v)
        Tlap = T.forward(lap)
        in_y = f.laplacian_multiplier.ravel() * T.forward(v)
        via_back = T.backward(T.forward(v), f.laplacian_multiplier * T.unscale)
        acc = T.forward(v)
        T.forward_add(lap, acc)
    scale = np.abs(f.symbol).max() * np.linalg.norm(v)
    assert np.linalg.norm(Tlap - in_y) <= ROUND * scale
    assert np.abs(via_back - lap).max() <= ROUND * np.abs(f.symbol).max() * np.abs(v).max()
    assert np.linalg.norm(acc - (T.forward(v) + Tlap)) <= ROUND * scale


@pytest.mark.parametrize("library", LIBRARIES)
@pytest.mark.parametrize("n", SHAPES)
def test_translation_rows_are_the_coordinates_of_the_spectral_derivatives(library, n, rng):
    f = _grid(n)
    x = f.nodes()
    v = np.prod([np.sin(2 * np.pi * x[:, d] / L + d) for d, L in enumerate(f.lengths)], axis=0) \
        + 0.1 * rng.standard_normal(f.size)
    with fft_library(library):
        rows = f.coordinates.derivatives(v, 0.7)
        ref = [f.coordinates.forward(0.7 * d) for d in f.derivatives(v)]
    assert rows.shape == (f.dim, f.coordinates.size)
    kmax = max(np.abs(k).max() for k in f.k)
    for row, r in zip(rows, ref):
        assert np.linalg.norm(row - r) <= ROUND * kmax * np.linalg.norm(v)


@pytest.mark.parametrize("n", [*SHAPES, (6,)])
def test_project_is_the_orthogonal_projector_onto_the_range(n, rng):
    """``project``: T v is left alone, a random y lands in the range (T T^{-1} P y = P y), P is
    idempotent and y - P y is orthogonal to every T v; and the range has dimension N (the random
    coordinates outside it are what T^{-1} ignores)."""
    f = _grid(n)
    T = f.coordinates
    v, y = rng.standard_normal(f.size), rng.standard_normal(T.size)
    Tv = T.forward(v)
    py = T.project(y.copy())
    assert np.abs(T.project(Tv.copy()) - Tv).max() <= ROUND * np.abs(Tv).max()
    assert np.abs(T.forward(T.backward(py)) - py).max() <= ROUND * np.abs(py).max()
    assert np.array_equal(T.project(py.copy()), py)
    assert abs((y - py) @ Tv) <= ROUND * np.linalg.norm(y) * np.linalg.norm(Tv)
    assert np.linalg.norm(y - py) > 0.01 * np.linalg.norm(y) or T.size == f.size  # y had a part outside
    basis = np.array([T.project(e) for e in np.eye(T.size)])  # P itself, column by column
    # P is an orthogonal projector: its singular values are 0 or 1, so any cut between them counts the rank
    assert np.linalg.matrix_rank(basis, tol=1e-10) == f.size
