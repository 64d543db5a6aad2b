"""One level of the matrix-free second-order check (``verify.lobpcg``): its operators in the
variables u = M^{1/2} v (nodal, or on one-weight periodic Fourier grids in their orthonormal Fourier
coordinates T u, ``mesh.coordinates``), the excluded symmetry modes, and the start blocks (interface
modulations p(x) (1 - phi^2), Rayleigh-Ritz selection, random mixing). ``verify.lobpcg`` describes
the check and its scaling conventions; this module builds what it iterates on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vesicle_opt.mesh.cosine import KIND as COSINE
from vesicle_opt.model.band_coarse import BandCoarse
from vesicle_opt.model.lumped import State
from vesicle_opt.verify import block_eig
from vesicle_opt.verify import verdict as V
from vesicle_opt.verify.second_order import translation_modes

POLY_DEGREE = 2  # interface modulations of degree <= 2: translations, the ellipsoidal shape modes
TRANSPORT_FLOOR = 1e-3  # ``transported``'s floor on 1 - phi^2 (|phi| <= 0.9995, 5.8 eps from the interface).
# Measured (octant prolate, the same warm checks replayed, the carried rows alone as the start): 525 k nodes
# 1e-2 / 3e-3 / 1e-3: coarse iterations 27-28 / 21-28 / 21-28 (against 35-38 from the previous rows), the
# start's Rayleigh quotient 0.17 / 0.053 / 0.043 (mu_min 0.032-0.036); 205 k 1e-2 / 1e-3 / 1e-4: 16-19 /
# 14-16 / 16-19 (20-35)


@dataclass
class Level:
    """The check's operators on one grid, in the variables u = M^{1/2} v (``verify.lobpcg``'s
    docstring); on periodic Fourier grids in their orthonormal Fourier coordinates T u
    (``mesh.coordinates``: T is orthogonal, so the iteration is the same; the preconditioner is a
    diagonal there and a product takes four transforms, not six with the preconditioner's)."""

    disc: object
    a_u: object  # u -> Pi M^{-1/2} H_L M^{-1/2} Pi u / mu_ref (blocks of columns)
    t_u: object  # r -> mu_ref M^{1/2} P^{-1} M^{1/2} r (blocks)
    s: np.ndarray | float  # sqrt(m) per node (a scalar where all weights are equal)
    Q: np.ndarray  # orthonormal rows (u variables): dA, dB
    Qall: np.ndarray  # and the excluded modes
    modes: list
    excluded: str
    h_u: object  # single vectors, unprojected
    coords: object = None  # the Fourier coordinates the u variables are taken in, or None (nodal)

    def to_u(self, v: np.ndarray) -> np.ndarray:
        """The u variables of nodal values v (one vector)."""
        return self.s * v if self.coords is None else self.coords.forward(self.s * v)

    def rows_to_u(self, X: np.ndarray, owned: bool = False) -> np.ndarray:
        """The u variables of nodal rows X (``owned``: X may be scaled in place, nodal variables)."""
        if self.coords is None:
            if owned:
                X *= self.s
                return X
            return self.s * X
        out = np.empty((len(X), self.coords.size))
        for row, x in zip(out, X):
            row[...] = self.to_u(x)
        return out

    def rows_to_nodal(self, U: np.ndarray) -> np.ndarray:
        """Nodal rows of u rows U (the eigenvectors, M-normalised)."""
        if self.coords is None:
            return U / self.s
        return np.stack([self.coords.backward(u) for u in U]) / self.s


def symmetry_modes(disc, translations, phi, rotations: bool):
    """(label, rows) of the excluded modes (``verify.lobpcg``'s docstring: "Excluded modes")."""
    fourier = getattr(disc, "fourier", None)
    if fourier is None:
        modes = translation_modes(disc, phi)
        extra = None if modes or translations is None else translations(phi)
        if extra is not None:  # a caller's near-null modes (the branch's axial slide on a meridian mesh)
            modes = [np.ascontiguousarray(c) for c in np.asarray(extra, float).T]
        return V.excluded_label(disc, modes), modes
    g = fourier.derivatives(phi)  # the translations d_i phi (what ``translations`` gives, as rows)
    if not g:  # a mirror grid (``mesh.cosine``): only mirror-symmetric perturbations exist at all
        return V.MIRROR_CLASS, []
    if not rotations:
        return V.TRANSLATIONS, g
    x = disc.nodes
    rot = [x[:, i] * g[j] - x[:, j] * g[i] for i, j in (((1, 2), (2, 0), (0, 1)) if disc.dim == 3 else ((0, 1),))]
    return V.TRANSLATIONS_ROTATIONS, [*g, *rot]


def orthonormal_rows(rows) -> tuple[np.ndarray, list[bool]]:
    """Orthonormal rows spanning ``rows`` (a sequence of vectors), in their order (modified
    Gram-Schmidt, twice; a row left with less than 1e-12 of its norm is dependent and dropped), and
    which rows were kept: an (m, N) array and nothing larger is allocated."""
    out = np.empty((len(rows), np.size(rows[0])))
    kept, flags = 0, []
    for r in rows:
        q = out[kept]
        q[...] = r
        norm0 = float(np.linalg.norm(q))
        for _ in range(2):
            for j in range(kept):
                q -= (out[j] @ q) * out[j]
        norm = float(np.linalg.norm(q))
        flags.append(norm > 1e-12 * norm0)
        if flags[-1]:
            q /= norm
            kept += 1
    return out[:kept], flags


def build(disc, pf, pinv, translations, phi, rig, cB, ref, rotations, inv_symbol=None) -> Level:
    """The level of grid ``disc`` at the KKT point phi (``rig`` the rigidity, cB = -lam_B, ``ref``
    mu_ref; ``pinv`` the preconditioner's inverse on nodal values). ``inv_symbol``: on a one-weight
    Fourier grid mu_ref m / p of the preconditioner (paired): the level is then taken in Fourier
    coordinates (``Level``), ``pinv`` unused."""
    st = pf.state(phi)
    parts = pf.hessian_parts(st)
    dA, dB = pf.gradients(st)[1:]
    st = State(st.phi, None, None, st.s, st.E, st.A, st.B)  # hvp needs phi and g'(phi) only
    m = np.asarray(pf.m, float)
    # sqrt(m) per node; a scalar where the weights are equal (Fourier grids): one vector less
    s = float(np.sqrt(m.flat[0])) if np.all(m == m.flat[0]) else np.sqrt(np.broadcast_to(m, phi.shape))
    excluded, modes = symmetry_modes(disc, translations, phi, rotations)
    # Qall: dA, dB, then the excluded modes (u variables), orthonormal; Q = its first rows (T's normals)
    coords = None if inv_symbol is None or np.ndim(s) else disc.fourier.coordinates
    rows = [dA / s, dB / s, *(s * t for t in modes)]
    if coords is not None:  # T is orthogonal: orthonormal rows stay orthonormal
        rows = [coords.forward(r) for r in rows]
    Qall, kept = orthonormal_rows(rows)
    del dA, dB, rows
    Q = Qall[:sum(kept[:2])]

    if coords is not None:
        product = pf.hvp_coordinates(st, parts, rig, cB)
    else:
        product = pf.hvp_operator(st, parts, rig, cB)  # its coefficients formed once for every product

    if np.ndim(s) == 0:  # one weight: the scalings of the linear product folded into one pass
        scale = 1.0 / (s * s * ref)

        def h_u(u):  # M^{-1/2} H_L M^{-1/2} u / mu_ref
            out = product(u)
            out *= scale
            return out
    else:
        def h_u(u):  # M^{-1/2} H_L M^{-1/2} u / mu_ref
            return product(u / s) / s / ref

    def rows_of(f):  # blocks are rows (``block_eig``), filled in place
        def apply(U):
            out = np.empty_like(U)
            for i, u in enumerate(U):
                out[i] = f(u)
            return out
        return apply

    a_u = rows_of(h_u)  # block_eig projects what it needs onto T
    if coords is not None:  # the preconditioner is a diagonal in Fourier coordinates
        diag = inv_symbol.ravel()  # mu_ref m / p (``setup``)

        def t_u(R):  # kept in T's range (``FourierCoordinates.project``): no spurious null modes
            out = np.multiply(R, diag)
            for row in out:
                coords.project(row)
            return out
    else:
        t_u = rows_of(lambda r: (ref * s * s) * pinv(r)) if np.ndim(s) == 0 else \
            rows_of(lambda r: ref * s * pinv(s * r))
    return Level(disc, a_u, t_u, s, Q, Qall, modes, excluded, h_u, coords)


def setup(disc, pf, prec, translations, scene, phi, cB, ref, rotations, band: bool = False) -> Level:
    """The level of ``disc`` with the Newton solve's preconditioner ``prec`` (``nk.precond``): in
    Fourier coordinates on one-weight Fourier grids, on nodal values elsewhere. ``band``: on mirror
    grids plus the interface band's coarse space (``model.band_coarse``; ``verify.lobpcg`` asks for it
    on the coarse levels, whose vectors only start the next level: the fine level, which decides the
    verdict, keeps the bulk model)."""
    rig = scene.model.rigidity
    fourier = getattr(disc, "fourier", None)
    if fourier is not None:
        if hasattr(fourier, "coordinates") and np.all(pf.m == pf.m[0]):  # the level in Fourier coordinates
            # mu_ref M^{1/2} P^{-1} M^{1/2} = diag(mu_ref m / p) there: the scalars in the one array
            inv = fourier.multiplier((ref * float(pf.m[0])) / prec.symbol(rig, cB))
            return build(disc, pf, None, translations, phi, rig, cB, ref, rotations, inv)
        inv = fourier.multiplier(1.0 / prec.symbol(rig, cB))
        pinv = lambda r: fourier.apply_symbol(r, inv)  # noqa: E731
        if band and getattr(fourier, "kind", None) == COSINE:
            coarse = BandCoarse(fourier, float(pf.m[0]), scene.model.epsilon, phi, pf.state(phi).s, rig, cB)
            pinv = coarse.additive(pinv)
    else:
        pinv = prec.inverse(rig)
    return build(disc, pf, pinv, translations, phi, rig, cB, ref, rotations)


def interface_block(lev: Level, phi, rotations_kept: bool = False) -> np.ndarray:
    """Rows p(x) (1 - phi^2), p the monomials of degree <= POLY_DEGREE in coordinates centred on
    the interface (``verify.lobpcg``'s docstring); on Fourier grids where the rotations are not
    excluded, also the rotation modes (x_i d_j - x_j d_i) phi: soft there (the least eigenvalue of
    the torus on the P1 box, 0.0039 mu_ref at 48^3), and no polynomial modulation is one. In the level's u
    variables: each row formed in place (nodal variables) or in one nodal temporary and taken to
    Fourier coordinates at once, so no nodal block is held beside the u block."""
    disc = lev.disc
    x = np.asarray(disc.nodes, float)
    d = x.shape[1]
    fourier = getattr(disc, "fourier", None)
    # the rotation rows (x_i d_j - x_j d_i) phi, each formed in the row's temporary from the d
    # derivative fields (not all d(d-1)/2 rotation fields at once: the start's peak)
    g = fourier.derivatives(phi) if rotations_kept and fourier is not None else []
    rot = (((1, 2), (2, 0), (0, 1)) if d == 3 else ((0, 1),)) if g else ()
    n_rows = 1 + d + (d * (d + 1) // 2 if POLY_DEGREE >= 2 else 0) + len(rot)
    nodal = lev.coords is None
    out = np.empty((n_rows, phi.size if nodal else lev.coords.size))
    tmp = out[0] if nodal else np.empty(phi.size)  # where a row's nodal values are formed

    def put(row: int, values: np.ndarray) -> None:
        out[row] = lev.to_u(values)  # nodal: in place (values is out[row])

    w = np.multiply(phi, phi)
    np.subtract(1.0, w, out=w)
    np.clip(w, 0.0, None, out=w)
    c = (w @ x) / max(w.sum(), np.finfo(float).tiny)
    y = x - c  # N x d (the one temporary beside the rows)
    y /= max(float(np.sqrt(np.einsum("i,ij,ij->", w, y, y) / max(w.sum(), 1e-300))), 1e-300)
    rows = [lambda t: np.copyto(t, w)] + [lambda t, i=i: np.multiply(y[:, i], w, out=t) for i in range(d)]
    if POLY_DEGREE >= 2:
        rows += [lambda t, i=i, j=j: np.multiply(np.multiply(y[:, i], y[:, j], out=t), w, out=t)
                 for i in range(d) for j in range(i, d)]
    rows += [lambda t, i=i, j=j: np.subtract(np.multiply(x[:, i], g[j], out=t), x[:, j] * g[i], out=t)
             for i, j in rot]
    for row, fill in enumerate(rows):
        target = out[row] if nodal else tmp
        fill(target)
        put(row, target)
    return out


def rayleigh_on_t(lev: Level, modes) -> tuple[float, ...]:
    """Rayleigh quotients (mu_ref units) of nodal directions ``modes``, each M-orthogonally onto
    T = {dA.v = dB.v = 0}; nan for a direction that vanishes there (below 1e-8 of its nodal norm
    times sqrt(N): the rotation about an axis of symmetry)."""
    out = []
    for t in modes:
        u = lev.to_u(t)
        u = u - (lev.Q @ u) @ lev.Q
        scale = float(np.linalg.norm(lev.to_u(np.full(np.shape(t), np.abs(t).max()))))
        if not np.linalg.norm(u) > 1e-8 * scale:
            out.append(float("nan"))
            continue
        hu = lev.h_u(u)
        out.append(float(u @ (hu - (lev.Q @ hu) @ lev.Q) / (u @ u)))
    return tuple(out)


def excluded_rayleigh(lev: Level) -> tuple[float, ...]:
    """The excluded modes' Rayleigh quotients on T (``rayleigh_on_t``)."""
    return rayleigh_on_t(lev, lev.modes)


def rotation_rayleigh(lev: Level, phi) -> tuple[float, ...]:
    """The rotation generators' (x_i d_j - x_j d_i) phi Rayleigh quotients on T (a report: they stay
    in the check, ``verdict``'s docstring); () where the grid has no Fourier derivatives."""
    if getattr(lev.disc, "fourier", None) is None:
        return ()
    return rayleigh_on_t(lev, symmetry_modes(lev.disc, None, phi, True)[1][lev.disc.dim:])


def transported(rows: np.ndarray, phi_then: np.ndarray, phi_now: np.ndarray, floor: float = TRANSPORT_FLOOR) -> np.ndarray:
    """Nodal rows found at phi_then carried to phi_now: each times (1 - phi_now^2) / max(1 - phi_then^2,
    ``floor``). A least mode of the reduced Hessian is a modulation of the interface, ~ a(x) (1 - phi^2)
    with a smooth across the band (the tanh profile's derivative: a normal displacement), so the
    quotient recovers a where the band was and the product puts the mode on the band now (where the
    interface moved by less than the band's width). The floor bounds the quotient where the band was
    not (far from the interface, where the rows are round-off and other modes)."""
    w_then = np.maximum(1.0 - np.square(phi_then), floor)
    return rows * ((1.0 - np.square(phi_now)) / w_then)


def start_block(lev: Level, U: np.ndarray, k: int, seed: int | None = None) -> np.ndarray:
    """The start block: u rows U (the caller's to give away: updated in place) reduced to its k
    lowest Ritz vectors where larger, and with ``seed`` each column mixed with a random one of equal
    norm: a Rayleigh-Ritz selection keeps only the smooth modulations' symmetry classes, and a block
    without the least eigenvector's class converges to a higher pair (measured: 1.326 instead of
    1.277 on the FD 64^2 ellipse)."""
    if U.shape[0] > k:
        U = block_eig.rayleigh_ritz(lev.a_u, U, lev.Qall, k, overwrite=True)
    if seed is not None:
        R = np.random.default_rng(seed).standard_normal(U.shape)
        if lev.coords is not None:  # random coordinates: onto T's range (real fields) first
            for row in R:
                lev.coords.project(row)
        U /= np.linalg.norm(U, axis=1)[:, None]
        R /= np.linalg.norm(R, axis=1)[:, None]
        U += R
    return U
