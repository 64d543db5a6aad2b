"""The second-order check without matrices (``verify.verdict`` defines the quantity and the rule).

At a KKT point of (6)-(8) with rigidity * grad E_h = lam_A grad A + lam_B grad B the Hessian of the
Lagrangian is H_L = rigidity H_E - lam_B H_B (A is linear). ``reduced_hessian_eigenvalues`` returns
the smallest eigenvalues of H_L v = mu M v (M = diag(m), the lumped mass) on the tangent space
T = {v : dA.v = 0, dB.v = 0}, minus the excluded symmetry modes, in units of ``verdict.mu_ref``: the
same number as the assembled check ``verify.second_order``, by preconditioned LOBPCG,

    lobpcg(A = H_L, B = M, T = P^{-1}, Y = M^{-1} [dA, dB, M t_i, M r_ij]),

with P the Fourier model of ``nk.precond`` (cB = -lam_B; on lumped P1 meshes the bending model
(rigidity/eps) S M^{-1} S, whose approximate inverse is ``SparsePreconditioner.inverse``). scipy keeps
the iterates B-orthogonal to Y, so Y holds M^{-1} times the constraint gradients c: the iterates
satisfy c.v = 0, i.e. lie in T. (The P-metric check this replaced passed Y = c with B = P, so it
iterated on {(P c).v = 0}, not on T, and its "excluded" rotation came back: run to 330 iterations on
the 64^2 ellipse, its least eigenvalue fell from 1.45e-3 to the rotation mode's 4.5e-6.)

It runs in the variables u = M^{1/2} v on the operator Pi M^{-1/2} H_L M^{-1/2} Pi / mu_ref (Pi the
orthogonal projector onto T there), which is the same iteration (every trial vector maps one to one,
Rayleigh-Ritz on T gives the same Ritz pairs), except that LOBPCG's residual test then measures the
residual on T in the M^{-1} norm, in units of mu_ref: the error bound ``err`` of ``verdict.classify``
(Bauer-Fike). scipy's own test, unprojected, would count the multipliers' component of H v along
the constraint gradients, which is not an error and does not vanish.

Excluded modes (reported as ``excluded``): on Fourier grids the translations d_i phi and (with
``rotations``) the rotations (x_i d_j - x_j d_i) phi, exact symmetries of the continuum, soft on the
grid; on periodic tensor P1 meshes the spectral translations of ``second_order.translation_modes``,
as the assembled check; nothing on other meshes (a simplicial mesh breaks both symmetries, so a
negative rotation there is a genuine discrete saddle). Their Rayleigh quotients on T are reported and
enter the verdict too. This is a numerical check (a few eigenvalues, iterative), not a proof.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.sparse.linalg import LinearOperator, lobpcg

from vesicle_opt.model.problem import constraint_data
from vesicle_opt.verify import verdict as V
from vesicle_opt.verify.second_order import translation_modes
from vesicle_opt.verify.verdict import SecondOrder

K = 3  # block size: the least pair is often degenerate (saddles of the 2D ellipse elongate either way)
MAX_ITER = 150  # the least eigenvalue is within 1e-6 (relative) of its converged value after 47 (FD 64^2
# ellipse), 61 (its circle-start saddle), 114 (P1 41^2), 59 (P1 32^2 saddle), 94 (torus 16^3), 123 (torus
# 32^3) iterations; the P-metric iteration it replaced needed 66, 98, 64, 77, 140 on the last five
TOL = 1e-4  # stop when every pair's error bound (mu_ref units) is below; the cap usually comes first,
# the least pair then at <= 3.1e-4 (P1 41^2) and 1.9e-3 (torus 32^3), against |mu_min| >= 0.14 there


def _symmetry_modes(disc, translations, phi, rotations: bool):
    """(label, columns) of the excluded modes (module docstring)."""
    fourier = getattr(disc, "fourier", None)
    if fourier is None:
        modes = translation_modes(disc, phi)
        return (V.TRANSLATIONS if modes else V.NONE), modes
    modes = list(translations(phi).T)
    if not rotations:
        return V.TRANSLATIONS, modes
    g, x = fourier.derivatives(phi), disc.nodes
    for i, j in ((1, 2), (2, 0), (0, 1)) if disc.dim == 3 else ((0, 1),):
        modes.append(x[:, i] * g[j] - x[:, j] * g[i])
    return V.TRANSLATIONS_ROTATIONS, modes


def _orthonormal(C):
    q, r = np.linalg.qr(C)
    keep = np.abs(np.diag(r)) > 1e-12 * np.abs(np.diag(r)).max()
    return q[:, keep]


def spectrum(scene, result, setup, k: int = K, rotations: bool = False, max_iter: int = MAX_ITER,
             tol: float = TOL, seed: int = 0) -> dict:
    """Everything the check computes: eigenvalues mu/mu_ref (ascending), their error bounds, the
    M-normalised eigenvectors (columns), the excluded modes' label and Rayleigh quotients on T
    (mu_ref units), mu_ref and LOBPCG's iteration count."""
    disc, pf, prec, translations = setup
    fourier = getattr(disc, "fourier", None)
    phi = np.asarray(result.phi, float)
    st = pf.state(phi)
    parts = pf.hessian_parts(st)
    _, dA, dB = pf.gradients(st)
    rig, cB = scene.model.rigidity, -result.lambda_area
    ref = V.mu_ref(rig, scene.model.epsilon, constraint_data(scene, disc)[1], disc.dim)
    m = np.broadcast_to(np.asarray(pf.m, float), phi.shape)
    s = np.sqrt(m)
    N = phi.size
    if fourier is not None:
        inv = 1.0 / prec.symbol(rig, cB)
        pinv = lambda r: fourier.apply_symbol(r, inv)  # noqa: E731
    else:
        pinv = prec.inverse(rig)
    excluded, modes = _symmetry_modes(disc, translations, phi, rotations)
    # the constraint gradients c (dA, dB, M t) in the u variables: c / sqrt(m)
    Q = _orthonormal(np.column_stack([dA / s, dB / s]))
    Qall = _orthonormal(np.column_stack([Q, *(s * t for t in modes)]))

    def proj(U, basis):
        return U - basis @ (basis.T @ U)

    def h_u(u):  # M^{-1/2} H_L M^{-1/2} u / mu_ref
        return pf.hvp(st, parts, u / s, rig, cB) / s / ref

    def columns(f):
        return lambda U: np.column_stack([f(U[:, j]) for j in range(U.shape[1])]) \
            if U.ndim == 2 else f(np.ravel(U))

    a_u = columns(lambda u: proj(h_u(proj(u, Qall)), Qall))
    calls = [0]

    def t_u(R):  # applied once per iteration, to the block of unconverged residuals
        calls[0] += 1
        return columns(lambda r: ref * s * pinv(s * r))(R)
    A = LinearOperator((N, N), matvec=a_u, matmat=a_u, dtype=float)
    T = LinearOperator((N, N), matvec=t_u, matmat=t_u, dtype=float)
    X = np.random.default_rng(seed).standard_normal((N, k))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # lobpcg warns when the unwanted eigenvalues lag behind
        vals, U = lobpcg(A, X, M=T, Y=Qall, largest=False, tol=tol, maxiter=max_iter)
    U = np.asarray(U) / np.linalg.norm(U, axis=0)
    AU = a_u(U)
    vals = np.einsum("ij,ij->j", U, AU)  # the Rayleigh quotients (LOBPCG's Ritz values to round-off)
    order = np.argsort(vals)
    vals, U, AU = vals[order], U[:, order], AU[:, order]
    err = np.linalg.norm(AU - U * vals, axis=0)
    rayleigh = []
    for t in modes:  # each excluded mode, M-orthogonally onto T = {dA.v = dB.v = 0}
        u = proj(s * t, Q)
        rayleigh.append(float(u @ proj(h_u(u), Q) / (u @ u)))
    return {"eigenvalues": vals, "errors": err, "vectors": U / s[:, None], "excluded": excluded,
            "excluded_rayleigh": tuple(rayleigh), "mu_ref": ref, "iterations": calls[0]}


def reduced_hessian_eigenvalues(scene, result, setup, k: int = K, rotations: bool = False,
                                max_iter: int = MAX_ITER, tol: float = TOL, seed: int = 0,
                                vectors: bool = False):
    """(eigenvalues mu/mu_ref, error bounds in mu_ref units), ascending (module docstring); with
    ``vectors`` also the M-normalised eigenvectors (columns, nodal values). ``setup`` is the
    backend's (disc, PhaseField, preconditioner, translations) of ``nk.setup.prepare``."""
    sp = spectrum(scene, result, setup, k, rotations, max_iter, tol, seed)
    if vectors:
        return sp["eigenvalues"], sp["errors"], sp["vectors"]
    return sp["eigenvalues"], sp["errors"]


def check(scene, result, setup, rotations: bool = True, **kw) -> SecondOrder:
    """The verdict of ``verify.verdict.classify`` on the matrix-free spectrum; on Fourier grids the
    rotations are excluded by default (the translations always), as the front door does."""
    try:
        sp = spectrum(scene, result, setup, rotations=rotations, **kw)
    except (np.linalg.LinAlgError, ValueError) as e:  # lobpcg's breakdowns (dependent blocks)
        nan = float("nan")
        return SecondOrder("not checked", nan, nan, (nan,), (), nan, f"lobpcg: {e}", errors=(nan,))
    mu, err = float(sp["eigenvalues"][0]), float(sp["errors"][0])
    verdict, reason = V.classify(mu, err, sp["excluded_rayleigh"])
    return SecondOrder(verdict, mu * sp["mu_ref"], mu, tuple(float(x) for x in sp["eigenvalues"]),
                       sp["excluded_rayleigh"], float(max(sp["errors"])), reason,
                       sp["vectors"][:, 0], excluded=sp["excluded"], errors=tuple(float(e) for e in sp["errors"]),
                       iterations=sp["iterations"])
