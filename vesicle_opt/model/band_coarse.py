"""A two-level preconditioner on mirror grids: the bulk model plus a coarse space on the interface band.

The bending Hessian's Gauss-Newton part is (cE/eps) m L^2, L = eps Delta_h + diag(g'(phi)) the
linearised chemical potential (``model.lumped.PhaseField.hvp_operator``; grids of one weight m). The
bulk model of ``nk.precond`` takes g' = -2/eps everywhere. In the band, J's near-null shape modes
psi(x) phi_0'(d/eps) (psi smooth along the interface; for the tanh profile phi_0' is proportional to
1 - phi^2) have L ~ eps phi_0' Delta_s psi, while the bulk model sees ~3/eps there: P_bulk^{-1} H has
one small eigenvalue per shape mode with eps |k_s| below ~1, (R/eps)^2 of them, and the Krylov counts
grow as eps falls with h ~ eps (``docs/guide/large-3d.md``).

The coarse space holds them: Z = diag(1 - phi^2) B, B the tensor-product quadratic B-splines (C^1:
the shape modes' energy is fourth order along the interface; hats, C^0, took 147-3000 GMRES
iterations against 49 on the 205 k-node octant) on a lattice of spacing H = ``SPACING`` eps anchored
at the box's lower corner, each column even about that corner's mirror planes (the spline at J = -1
is read as J = 1's image, ``bspline_1d``), the columns whose norm is at least ``KEEP`` of the largest
(the band's). Its Galerkin matrix is that of the Gauss-Newton model

    P_GN = (cE/eps) m L^2 + max(cB, 0) S + GN_DELTA (cE/eps) m (eps Delta_h - 2/eps)^2,
    S = m (2/eps - eps Delta_h) = -m (eps Delta_h - 2/eps),

as in ``nk.precond.SparsePreconditioner.gauss_newton`` (2D sparse meshes factor P_GN whole; here only
its coarse block on the band: (area / H^2) x a few layers, 145 / 941 columns at 31 k / 205 k nodes).
All of it follows from D = eps Delta_h Z (L Z = D + g' Z, the bulk factor D - (2/eps) Z), and D is
probed: the columns of one colour (lattice indices equal mod ``STRIDE`` on every axis) are summed, one
Laplacian of the sum (two transforms) is taken, and each node is read as the colour's column whose
cell (the nearest lattice point of that colour, 3H wide) holds it. The cells hold the splines'
supports (1.5 H either side); what is lost is the spectral Laplacian's tail beyond them (it only
preconditions; with cells 5H wide, 250 transforms instead of 54, the counts were the same to 10 %).
The same sum read on a cell is that column of Z exactly (one colour's supports are disjoint), so Z is
formed on D's pattern and every factor of the Galerkin products is an array of values there: L Z,
Z's nonzeros, the diagonals' rows; no sparse sums or COO conversions (``_split``; a build at 525 k
nodes, synthetic prolate, k = 1997: 1.76-1.92 -> 1.34-1.46 CPU s, the same matrix to 7e-16).

The preconditioner is the additive two-level one, P^{-1} r = P_bulk^{-1} r + Z Hc^{-1} Z^T r, symmetric
positive definite; Hc by a sparse LU, Z and Z^T applied in their tensor form (``restrict``,
``extend``).

Where the solve need not be symmetric positive definite (GMRES on the bordered systems of
``branch.nk_free``), Hc is the Galerkin matrix of the Hessian itself, Z^T H Z with
H = cE H_E + cB H_B (``hessian``: the diagonals of ``PhaseField.hessian_parts``; the same probed D,
the tension cB taken as it is, not floored, and the r g'' term of H_E kept; no GN_DELTA share unless the
LU finds it exactly singular). P_GN's Galerkin matrix misses those terms on the very modes the coarse
space is for: on the 31 k-node octant prolate the generalised eigenvalues of (Z^T H Z, Hc) span
0.09-7.9 for P_GN's and 0.39-1.4 for the Hessian's (``tests/model/test_band_coarse.py``), and a
bordered Newton system of the 205 k-node walk took 15 / 21 / 27 GMRES iterations to 1e-2 / 1e-4 / 1e-6
against 7 / 13 / 18. What is left is the probing's error (4 % of Hc in norm with 3 colours an axis,
4e-4 with 4: 3 / 6 / 10 iterations, the count of Z^T H Z from k products, but a build 3x dearer, as
the sparse products grow as the square of the columns a node is read into: ``STRIDE`` stays 3). With 4
colours and each column read only on its support and 0.2 H beyond (where nearly all the tail lies: 4 /
7 / 12 iterations, 205 k nodes, the count of the exact matrix), a build cost 1.7-1.8x this one and the
walk gained only at 525 k nodes (points 2-5: 45.0 against 48.5 CPU s; points 2-7 at 31 k and 205 k:
11 % and 6 % slower): left out.

Hc is affine in cB, so a new tension re-factors it on the same space (``with_tension``); ``Lagged`` is
the reuse policy of the p-free corrector (``branch.nk_free``) and of the Newton-CG solve
(``nk.solve``). Measured (the bordered tangent system of ``branch.nk_free`` at the octant prolate
v = 0.71, eps / h = 2.5, GMRES to 1e-8): 39 / 81 / 133 iterations with the bulk model at 31 k / 98 k /
205 k nodes (eps 0.14 / 0.07 / 0.05), 29 / - / 32 with the coarse space; a random right-hand side
72 / 182 / 934 against 29 / - / 44.
"""

from __future__ import annotations

import copy

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

SPACING = 2.0  # H / eps: the shape modes the bulk model misses have eps |k_s| below ~1 (module docstring)
STRIDE = 3  # colours per axis: the cells (3H) hold the splines' supports (1.5 H either side)
KEEP = 1e-2  # columns with a norm below this share of the largest are dropped: they lie in the band's far
# tails, where the shape modes have no weight, and would only add near-zero rows to Hc
W_MIN = 1e-6  # 1 - phi^2 below this is the bulk: left out of Z's rows
GN_DELTA = 1e-3  # the bulk model's share in P_GN (here and in ``nk.precond``): keeps it nonsingular where J
# has a null vector (a translation of the interface, the meridian's axial slide: J d_z phi ~ 0), 1e-3 of the bulk scale


def bspline_1d(x: np.ndarray, lo: float, H: float, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The quadratic B-splines centred at lo + J H, J = 0 .. count - 1, at the points x: (cols, vals),
    each (len(x), 3), the splines that can be nonzero at each point (0 where out of range). The spline
    at J = -1 is the mirror image of J = 1 about lo (the grids' mirror plane), so it is read as column 1:
    the columns are even about lo, and they sum to 1 on [lo, lo + (count - 1.5) H] (COO assembly adds
    the repeated column)."""
    t = (x - lo) / H
    centre = np.rint(t).astype(int)
    cols = centre[:, None] + np.array([-1, 0, 1])[None, :]
    d = np.abs(t[:, None] - cols)
    vals = np.where(d < 0.5, 0.75 - d**2, np.where(d < 1.5, 0.5 * (1.5 - d) ** 2, 0.0))
    cols = np.abs(cols)  # J = -1 -> 1 (the mirror image)
    ok = cols < count
    return np.where(ok, cols, 0), np.where(ok, vals, 0.0)


class BandCoarse:
    """The coarse space of one state (module docstring): ``Z`` (N x k sparse), ``factor`` (Hc's LU),
    both formed on the first ``correction`` (a Newton step's trial points whose system is never solved
    cost nothing)."""

    def __init__(self, grid, m: float, eps: float, phi: np.ndarray, g_prime: np.ndarray, cE: float, cB: float,
                 hessian: tuple | None = None):
        self.grid, self.m, self.eps = grid, float(m), float(eps)
        self.hessian = hessian  # (dE_diag, dB_diag) of ``PhaseField.hessian_parts``: Hc = Z^T H Z (``_split``)
        self.g_prime, self.cE, self.cB = np.asarray(g_prime, float), float(cE), self._tension(cB)
        self._weight = 1.0 - np.asarray(phi, float) ** 2
        self.Z = self.factor = self._parts = None

    def _tension(self, cB: float) -> float:
        """P_GN floors cB at 0 (positive definite); the Hessian's own Galerkin matrix takes it as it is."""
        return float(cB) if self.hessian is not None else max(float(cB), 0.0)

    def build(self) -> "BandCoarse":
        if self.factor is None:
            Hc = self._galerkin()
            try:
                self.factor = spla.splu(sp.csc_matrix(Hc))
            except RuntimeError:  # Z^T H Z exactly singular (H indefinite: a zero eigenvalue on the space);
                # P_GN's bulk share (GN_DELTA) makes it regular, as P_GN is
                share = self._bulk_share(self._laplacians().tocsr() - (2.0 / self.eps) * self.Z)
                self.factor = spla.splu(sp.csc_matrix(Hc + 0.5 * (share + share.T)))
        return self

    def with_tension(self, cB: float) -> "BandCoarse":
        """The same space and g' with another cB: Hc is affine in cB (``_galerkin``), so only its LU is
        redone (the space, the probed Laplacians and the products are shared)."""
        self._split()
        other = copy.copy(self)
        other.cB, other.factor = self._tension(cB), None
        return other

    def _axes(self) -> list[np.ndarray]:
        """The nodes' coordinates along each axis in lattice units, (x - lo) / H (cell-centred nodes)."""
        g = self.grid
        return [h * (np.arange(n) + 0.5) / (SPACING * self.eps) for h, n in zip(g.h, g.shape)]

    def _space(self, w: np.ndarray) -> np.ndarray:
        """The lattice indices (k, d) of the kept columns on the band w > W_MIN, and Z's tensor form: per
        axis the dense (n_a x count_a) spline matrix (mirror images summed), ``restrict``/``extend``. The
        columns' norms are one such contraction of w^2 with the squared splines (Z itself is formed on
        the probing's cells: ``_probe``)."""
        g = self.grid
        counts = [int(np.ceil(L / (SPACING * self.eps))) + 2 for L in g.lengths]
        self._factors = []
        for t, count in zip(self._axes(), counts):
            c, v = bspline_1d(t, 0.0, 1.0, count)
            dense = np.zeros((t.size, count))
            np.add.at(dense, (np.repeat(np.arange(t.size), 3), c.ravel()), v.ravel())
            self._factors.append(dense)
        self._band_weight = np.where(w > W_MIN, w, 0.0).reshape(g.shape)
        u = self._band_weight**2
        for B in self._factors:
            u = np.tensordot(u, B * B, axes=(0, 0))
        norms = np.sqrt(u.ravel())
        keep = np.flatnonzero(norms >= KEEP * norms.max())
        self.counts, self._keep = tuple(counts), keep
        return np.stack(np.unravel_index(keep, counts), axis=1)

    def gauss_newton(self, v: np.ndarray) -> np.ndarray:
        """P_GN v (module docstring), matrix-free: three Laplacians, six transforms (the definition the
        probed Galerkin matrix is tested against; the preconditioner does not call it)."""
        g, eps, m, gp = self.grid, self.eps, self.m, self.g_prime
        lap_v = g.laplacian(v)
        Lv = eps * lap_v + gp * v
        out = (self.cE / eps) * m * (eps * g.laplacian(Lv) + gp * Lv)
        bulk = eps * lap_v - (2.0 / eps) * v  # -S v / m
        if self.cB:
            out -= self.cB * m * bulk
        out += GN_DELTA * (self.cE / eps) * m * (eps * g.laplacian(bulk) - (2.0 / eps) * bulk)
        return out

    def _cells(self) -> tuple[np.ndarray, np.ndarray]:
        """Each kept column's cell, (first, end) node per axis, each (k, d): the nodes whose nearest
        lattice point of the column's colour is the column's. One colour's cells are disjoint."""
        ends = []
        for t, count in zip(self._axes(), self.counts):
            J = np.arange(count)
            r = J % STRIDE
            near = np.rint((t[:, None] - np.arange(STRIDE)) / STRIDE).astype(int) * STRIDE + np.arange(STRIDE)
            ends.append((np.array([np.searchsorted(near[:, ri], j, "left") for j, ri in zip(J, r)]),
                         np.array([np.searchsorted(near[:, ri], j, "right") for j, ri in zip(J, r)])))
        d = self.lattice.shape[1]
        lo = np.stack([ends[a][0][self.lattice[:, a]] for a in range(d)], axis=1)
        hi = np.stack([ends[a][1][self.lattice[:, a]] for a in range(d)], axis=1)
        return lo, hi

    def _probe(self) -> tuple[sp.csc_matrix, np.ndarray]:
        """D = eps Delta_h Z, probed, and Z's values on D's pattern: one Laplacian per colour (lattice
        indices equal mod ``STRIDE``) of the sum of its columns, each column read on its cell
        (``_cells``). A colour's cells are disjoint and each holds its column's support, so the sum read
        on a cell is that column of Z exactly; D's read is its column up to the Laplacian's tails (its
        own beyond the cell, the colour's other columns' within it). Assembled column by column (CSC)."""
        g, eps = self.grid, self.eps
        k, d = self.lattice.shape
        code = np.ravel_multi_index((self.lattice % STRIDE).T, (STRIDE,) * d)
        lo, hi = self._cells()
        indptr = np.concatenate([[0], np.cumsum(np.prod(hi - lo, axis=1))])
        data, zdata = np.empty(indptr[-1]), np.empty(indptr[-1])
        indices = np.empty(indptr[-1], np.int32 if g.size < 2**31 else np.int64)
        flat = np.arange(g.size).reshape(g.shape)
        for c in range(STRIDE**d):
            members = np.flatnonzero(code == c)
            if members.size == 0:
                continue
            y = np.zeros(k)
            y[members] = 1.0
            z = self.extend(y)
            y = (eps * g.laplacian(z)).reshape(g.shape)
            z = z.reshape(g.shape)
            for j in members:
                box = tuple(slice(a, b) for a, b in zip(lo[j], hi[j]))
                data[indptr[j]:indptr[j + 1]] = y[box].ravel()
                zdata[indptr[j]:indptr[j + 1]] = z[box].ravel()
                indices[indptr[j]:indptr[j + 1]] = flat[box].ravel()
        return sp.csc_matrix((data, indices, indptr), shape=(g.size, k)), zdata

    def _laplacians(self) -> sp.csc_matrix:
        """D = eps Delta_h Z, probed (``_probe``)."""
        return self._probe()[0]

    def _split(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """Hc's two parts, Z^T ((cE/eps) m L^2 + GN_DELTA ...) Z and Z^T S Z (symmetrised), from
        D = eps Delta_h Z (``_probe``): L Z = D + g' Z, S Z = -m (D - (2/eps) Z). Formed once.
        With ``hessian`` = (dE_diag, dB_diag) they are the Hessian's own, H = cE H_E + cB H_B
        (``PhaseField.hvp_operator``): Z^T ((cE/eps) m L^2 + cE diag(dE_diag)) Z and
        Z^T (-eps m Delta_h + diag(dB_diag)) Z = -m Z^T D + Z^T diag(dB_diag) Z.

        Every factor lives on D's pattern (CSC), so each is its values there: L Z, Z's own values (the
        CSC of its nonzeros: zero beyond its support and the band), the diagonals' rows scaled; A^T is
        then CSR as stored, and each product converts only its right factor."""
        if self._parts is None:
            self.lattice = self._space(self._weight)  # Z is formed here, with the parts
            eps, m = self.eps, self.m
            D, zdata = self._probe()
            rows = D.indices  # each stored entry's node

            def on_d(values, nonzero=False):  # a matrix on D's pattern (CSC) from its values
                pattern = (D.indices.copy(), D.indptr.copy()) if nonzero else (D.indices, D.indptr)
                out = sp.csc_matrix((values, *pattern), shape=D.shape)
                if nonzero:
                    out.eliminate_zeros()  # in place: on its own copies of the shared pattern
                return out
            self.Z = Z = on_d(zdata.copy(), nonzero=True)
            a = (self.cE / eps) * m
            LZ = on_d(D.data + self.g_prime[rows] * zdata)
            E = a * (LZ.T @ LZ)
            if self.hessian is None:
                bulk = on_d(D.data - (2.0 / eps) * zdata)
                E = E + self._bulk_share(bulk)
                S = -m * (Z.T @ bulk)
            else:
                dE, dB = (np.broadcast_to(np.asarray(x, float), (D.shape[0],)) for x in self.hessian)
                E = E + Z.T @ on_d(self.cE * dE[rows] * zdata, nonzero=True)
                S = Z.T @ on_d(dB[rows] * zdata - m * D.data)
            self._parts = (0.5 * (E + E.T), 0.5 * (S + S.T))
        return self._parts

    def _bulk_share(self, bulk) -> sp.csr_matrix:
        """GN_DELTA Z^T (cE/eps) m (eps Delta_h - 2/eps)^2 Z from bulk = D - (2/eps) Z: P_GN's bulk share
        (in ``_split``; in ``build`` the regulariser of an exactly singular Z^T H Z), not symmetrised."""
        return (GN_DELTA * ((self.cE / self.eps) * self.m)) * (bulk.T @ bulk)

    def _galerkin(self) -> sp.csr_matrix:
        """Hc = Z^T P_GN Z (or Z^T H Z: ``hessian``) = (``_split``'s first part) + cB (its second)."""
        E, S = self._split()
        return E + self.cB * S if self.cB else E

    def correction(self, r: np.ndarray) -> np.ndarray:
        """Z Hc^{-1} Z^T r, Z applied in its tensor form (``restrict``, ``extend``)."""
        self.build()
        return self.extend(self.factor.solve(self.restrict(r)))

    def restrict(self, r: np.ndarray) -> np.ndarray:
        """Z^T r as d one-axis contractions with the spline matrices (Z = diag(w) (B_0 x B_1 x ...) on the
        kept columns): a few passes over the grid instead of a sparse product with ~3^d entries a band
        node (525 k nodes: 2.8 against 4.7 ms)."""
        u = self._band_weight * np.reshape(r, self.grid.shape)
        for B in self._factors:  # contracts the leading grid axis, appends its lattice axis
            u = np.tensordot(u, B, axes=(0, 0))
        return u.ravel()[self._keep]

    def extend(self, y: np.ndarray) -> np.ndarray:
        """Z y, the transpose of ``restrict`` (525 k nodes: 2.3 against 5.2 ms)."""
        u = np.zeros(int(np.prod(self.counts)))
        u[self._keep] = y
        u = u.reshape(self.counts)
        for B in self._factors:
            u = np.tensordot(u, B, axes=(0, 1))
        return (self._band_weight * u).ravel()

    def additive(self, bulk_inv):
        """r -> P_bulk^{-1} r + Z Hc^{-1} Z^T r."""
        return lambda r: bulk_inv(r) + self.correction(r)


class Lagged:
    """One factorization of a preconditioner, reused while the state moves little (it only
    preconditions: the Krylov solve is of the true system either way). ``get`` makes a new one where
    eps |g' - g'_held| > ``lag_g`` anywhere; where only cB = -lambda_B moved by more than ``lag_cb``
    (relative) it re-tensions the held one if it can (``BandCoarse.with_tension``), else makes a new
    one. ``held``: (g', cB, the factorization)."""

    def __init__(self, eps: float, lag_g: float, lag_cb: float):
        self.eps, self.lag_g, self.lag_cb = float(eps), float(lag_g), float(lag_cb)
        self.held = None
        self.made = 0  # factorizations made (benchmarks and tests)

    def band_coarse(self, grid, phi: np.ndarray, g_prime: np.ndarray, cE: float, cB: float,
                    hessian: tuple | None = None) -> BandCoarse:
        """The mirror grid's coarse space at one state (``BandCoarse``, node weight ``grid.cell``; with
        ``hessian``, the Hessian's own Galerkin matrix) under these rules, re-tensioned where only cB moved."""
        return self.get(g_prime, cB, lambda: BandCoarse(grid, grid.cell, self.eps, phi, g_prime, cE, cB, hessian),
                        BandCoarse.with_tension)

    def get(self, g_prime: np.ndarray, cB: float, make, retension=None):
        """The held factorization, or ``make()``'s, or ``retension(held, cB)``'s (rules above)."""
        held, cB = self.held, float(cB)
        moved_g = held is None or self.eps * float(np.max(np.abs(g_prime - held[0]))) > self.lag_g
        moved_c = held is not None and abs(cB - held[1]) > self.lag_cb * abs(held[1])
        if moved_g or (moved_c and retension is None):
            self.held = (np.array(g_prime, float), cB, make())
            self.made += 1
        elif moved_c:
            self.held = (held[0], cB, retension(held[2], cB))
        return self.held[2]
