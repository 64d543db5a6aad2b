"""Uniform periodic grids with the standard finite-difference Laplacian.

Nodes x_j = lo + j h (j = 0..n-1 per direction, C order), weights prod(h), and the (2d+1)-point
Laplacian as a sum of Kronecker products of the 1D circulant (1, -2, 1)/h^2. In the framework of
Definition 2.2 this is the lumped scheme with K = -(prod h) Delta_FD; on a periodic box it coincides
with P1 + mass lumping on the tensor triangulation (a test checks this to round-off).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from vesicle_opt.mesh.base import Discretization, grid_points


def second_difference(n: int, h: float) -> sp.csr_matrix:
    """1D periodic second difference (1, -2, 1)/h^2 on n points."""
    e = np.ones(n)
    D = sp.diags([e[:-1], -2 * e, e[:-1]], [-1, 0, 1], shape=(n, n), format="lil")
    D[0, n - 1] = 1.0
    D[n - 1, 0] = 1.0
    return sp.csr_matrix(D) / h**2


def grid(box, n) -> Discretization:
    dim = len(box)
    hs = [(b - a) / k for (a, b), k in zip(box, n)]
    axes = [a + h * np.arange(k) for (a, _), h, k in zip(box, hs, n)]
    nodes = grid_points(axes)
    lap = sp.csr_matrix((nodes.shape[0],) * 2)
    for d in range(dim):
        factors = [sp.identity(k, format="csr") for k in n]
        factors[d] = second_difference(n[d], hs[d])
        term = factors[0]
        for f in factors[1:]:
            term = sp.kron(term, f, format="csr")
        lap = lap + term
    cell = float(np.prod(hs))
    weights = np.full(nodes.shape[0], cell)
    K = sp.csr_matrix(-cell * lap)
    return Discretization(kind="fd", dim=dim, nodes=nodes, weights=weights, K=K,
                          M=sp.diags(weights, format="csr"), mass="lumped", h=max(hs),
                          volume=float(np.prod([b - a for a, b in box])), box=tuple(box),
                          grid_shape=tuple(n))
