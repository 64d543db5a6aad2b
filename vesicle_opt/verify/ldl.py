"""Sparse LDL^T of the shift-invert matrix K = H - s M (M diagonal: lumped mass) with the symbolic
analysis kept per sparsity pattern, for ``verify.shift_invert``.

Along a walk on one mesh (``nlp.reuse``) every point's Hessian of the Lagrangian has the same
pattern (IPOPT's ``nlp_hess_l`` on a fixed graph), so the fill-reducing ordering (AMD) and the
elimination tree need computing once: QDLDL (the optional extra ``ldl``) keeps them in its solver
object and refactorises numerically on new values (``update``). Measured on the refined meridian
mesh at eps/R0 = 0.02 (20.3 k nodes, CPU, one thread): 0.066 s against 0.095 s for a first
factorisation and 0.17-0.21 s for SuperLU's LU with its minimum-degree ordering (fill 1.4 M in L
against 3.0 M in L + U; one solve 4.2 ms against 4.6 ms).

QDLDL does not pivot: on an indefinite K a pivot can be tiny and the factors inaccurate (a zero one
is refused, non-finite values are returned as they come). The caller (``shift_invert.factorise``)
therefore tests every factorisation by the residual of a bordered solve and falls back to SuperLU's
pivoted LU. The update path runs the same numeric code on the same permuted values as a first
factorisation, so a reused analysis gives bitwise the same factors as a fresh one.

Patterns whose factor is larger than ``KEEP_FILL`` are not kept. A ``Factor`` refers to its
pattern's one solver: factorising again on that pattern (the next point,
or the check's next shift) makes the earlier ``Factor`` stale, and its ``solve`` raises rather than
answer for another matrix.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from vesicle_opt import extras

PATTERNS = 2  # patterns kept (LRU): one mesh's along a walk, and the mesh a re-mesh moves to (~16 MB each at 20 k nodes)
KEEP_FILL = 20_000_000  # a pattern whose L has more nonzeros (~240 MB) is not kept: its factors die with the check
_CACHE: list = []  # [_Pattern], most recently used last


@dataclasses.dataclass(eq=False)
class _Pattern:
    """H's CSC pattern (the key) and where its upper triangle and the diagonal go in K's."""

    shape: tuple
    indptr: np.ndarray
    indices: np.ndarray
    up_indptr: np.ndarray  # K's upper triangle (H's upper entries and the whole diagonal), CSC
    up_indices: np.ndarray
    source: np.ndarray  # positions of H's upper entries in H.data
    target: np.ndarray  # their positions in K's upper data
    diagonal: np.ndarray  # positions of K's diagonal in its upper data
    solver: object = None  # the QDLDL solver: its ordering and elimination tree, then the latest numeric factors
    generation: int = 0  # numeric factorisations done on it


@dataclasses.dataclass(eq=False)
class Factor:
    """K^{-1} by the LDL^T of the latest factorisation on a pattern (stale after the next one)."""

    pattern: _Pattern
    generation: int
    shift: float

    def _solver(self):
        if self.pattern.generation != self.generation:
            raise RuntimeError("ldl.Factor: the pattern was factorised again since (a stale factorisation)")
        return self.pattern.solver

    def solve(self, b: np.ndarray) -> np.ndarray:
        """K^{-1} b (b: n or n x k)."""
        solver, b = self._solver(), np.asarray(b, float)
        if b.ndim == 1:
            return solver.solve(np.ascontiguousarray(b))
        return np.column_stack([solver.solve(np.ascontiguousarray(c)) for c in b.T]).reshape(b.shape)

    def negative_pivots(self) -> int:
        """Negative entries of D: K's count of negative eigenvalues (Sylvester) where the factors are accurate."""
        return int(np.count_nonzero(self._solver().factors()[1] < 0))


def available() -> bool:
    """QDLDL loads (the optional extra ``ldl``; a broken install warns once, ``extras.usable``)."""
    return extras.usable("qdldl", "the second-order check's factorisation", "SuperLU's LU")


def _canonical(H) -> sp.csc_matrix:
    H = sp.csc_matrix(H)
    if not H.has_canonical_format:
        H = H.copy()
        H.sum_duplicates()  # sorts the indices too
    return H


def _analyse(H: sp.csc_matrix) -> _Pattern:
    """K's upper pattern (H's upper entries and the diagonal) and the scatter of H's values into it."""
    n = H.shape[0]
    cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(H.indptr))
    rows = H.indices.astype(np.int64)
    source = np.flatnonzero(rows <= cols)
    keys_h = cols[source] * n + rows[source]  # CSC order: column-major, rows ascending
    keys = np.union1d(keys_h, np.arange(n, dtype=np.int64) * (n + 1))  # sorted: K's upper pattern in CSC order
    up_indptr = np.searchsorted(keys, np.arange(n + 1, dtype=np.int64) * n)
    return _Pattern(H.shape, H.indptr.copy(), H.indices.copy(), up_indptr.astype(np.int32),
                    (keys % n).astype(np.int32), source, np.searchsorted(keys, keys_h),
                    np.searchsorted(keys, np.arange(n, dtype=np.int64) * (n + 1)))


def _pattern_of(H: sp.csc_matrix) -> _Pattern:
    for i, pat in enumerate(_CACHE):
        if pat.shape == H.shape and pat.indices.size == H.indices.size and np.array_equal(pat.indptr, H.indptr) \
                and np.array_equal(pat.indices, H.indices):
            _CACHE.append(_CACHE.pop(i))
            return pat
    _CACHE.append(_analyse(H))
    del _CACHE[:-PATTERNS]
    return _CACHE[-1]


def factor(H, m: np.ndarray, shift: float) -> Factor | None:
    """LDL^T of K = H - shift diag(m) (H symmetric; both triangles stored, the upper one read), the
    analysis reused where H's pattern was seen before (module docstring); None where QDLDL is not
    usable or refuses K (a zero pivot, an empty column of the pattern)."""
    if not available():
        return None
    import qdldl  # optional extra (``ldl``), lazy: only lumped meshes' second-order checks use it

    H = _canonical(H)
    pat = _pattern_of(H)
    data = np.zeros(pat.up_indices.size)
    data[pat.target] = H.data[pat.source]
    data[pat.diagonal] -= shift * np.asarray(m, float)
    K = sp.csc_matrix((data, pat.up_indices, pat.up_indptr), shape=pat.shape)
    try:
        if pat.solver is None:
            pat.solver = qdldl.Solver(K, upper=True)
            if pat.solver.factors()[0].nnz > KEEP_FILL and pat in _CACHE:
                _CACHE.remove(pat)  # too large to hold between checks (the Factor keeps it while in use)
        else:
            pat.solver.update(K, upper=True)
    except (RuntimeError, ValueError):
        pat.solver = None
        pat.generation += 1
        return None
    pat.generation += 1
    return Factor(pat, pat.generation, float(shift))


def clear() -> None:
    """Forget every kept analysis (tests: a fresh factorisation against a reused one)."""
    _CACHE.clear()
