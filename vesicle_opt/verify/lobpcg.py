"""A second-order check of a computed equilibrium without matrices (the KKT test is first order only).

At a KKT point of (6)-(8) with rigidity * grad E_h = lam_A grad A + lam_B grad B the Hessian of the
Lagrangian is H_L = rigidity H_E - lam_B H_B (A is linear). phi is a strict local minimiser when
H_L is positive definite on the tangent space {v : dA.v = 0, dB.v = 0}, apart from the exact null
modes (translations d_i phi on a periodic box). ``reduced_hessian_eigenvalues`` returns the smallest
eigenvalues of the pencil (H_L, P) on that space by LOBPCG (P the Fourier model of ``precond``,
cB = -lam_B, so the eigenvalues are dimensionless: ~1 for the stiff interface modes), optionally also
excluding the rotations (x_i d_j - x_j d_i) phi, which are soft (exact symmetries of the continuum).
Positive values with small LOBPCG residuals show a strict local minimum; this is a numerical check
(a few eigenvalues, iterative), not a proof.

On lumped P1 meshes (the Newton-Krylov backend's sparse path) P is the bending model P0 = (rigidity/
eps) S M_L^{-1} S applied exactly, with ``SparsePreconditioner``'s approximate inverse as LOBPCG's
preconditioner. On periodic tensor meshes the central-difference translations d_i phi are excluded
as in ``second_order`` (near-null, O(h^2), so the two checks decide the same question); rotations are
not: on a simplicial mesh they are genuine soft modes, and a negative one is a discrete saddle.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.linalg import LinearOperator, lobpcg

from vesicle_opt.verify.second_order import translation_modes


def reduced_hessian_eigenvalues(scene, result, setup, k: int = 3, rotations: bool = False,
                                max_iter: int = 150, tol: float = 1e-5, seed: int = 0,
                                vectors: bool = False):
    """(eigenvalues, residual norms) of H_L on the tangent space (see the module docstring), sorted
    ascending; with ``vectors`` also the eigenvectors (columns, nodal values). ``setup`` is the
    backend's (disc, PhaseField, preconditioner, translations) of ``nk.setup.prepare``."""
    disc, pf, prec, translations = setup
    fourier = getattr(disc, "fourier", None)
    phi = np.asarray(result.phi, float)
    st = pf.state(phi)
    parts = pf.hessian_parts(st)
    _, dA, dB = pf.gradients(st)
    rig, cB = scene.model.rigidity, -result.lambda_area
    N = phi.size

    def block(f):
        return lambda V: np.column_stack([f(np.ravel(V[:, j])) for j in range(V.shape[1])]) \
            if V.ndim == 2 else f(np.ravel(V))

    hv = block(lambda v: pf.hvp(st, parts, v, rig, cB))
    if fourier is not None:
        sym = prec.symbol(rig, cB)
        pv = block(lambda v: fourier.apply_symbol(v, sym))
        piv = block(lambda v: fourier.apply_symbol(v, 1.0 / sym))
    else:
        pv, piv = block(prec.model(rig)), block(prec.inverse(rig))
    H = LinearOperator((N, N), matvec=hv, matmat=hv, dtype=float)
    P = LinearOperator((N, N), matvec=pv, matmat=pv, dtype=float)
    Pinv = LinearOperator((N, N), matvec=piv, matmat=piv, dtype=float)
    cols = [dA, dB]
    if fourier is not None:
        cols += [pf.m * t for t in translations(phi).T]
    else:
        cols += [pf.m * t for t in translation_modes(disc, phi)]
    if rotations and fourier is not None:
        g = fourier.derivatives(phi)
        x = disc.nodes
        for i, j in ((1, 2), (2, 0), (0, 1)) if disc.dim == 3 else ((0, 1),):
            cols.append(pf.m * (x[:, i] * g[j] - x[:, j] * g[i]))
    Y = np.column_stack(cols)
    X = np.random.default_rng(seed).standard_normal((N, k))
    vals, vecs = lobpcg(H, X, B=P, M=Pinv, Y=Y, largest=False, tol=tol, maxiter=max_iter)
    res = [float(np.linalg.norm(hv(vecs[:, j]) - vals[j] * pv(vecs[:, j])) /
                 max(np.linalg.norm(pv(vecs[:, j])), np.finfo(float).tiny)) for j in range(k)]
    order = np.argsort(vals)
    if vectors:
        return np.asarray(vals)[order], np.asarray(res)[order], np.asarray(vecs)[:, order]
    return np.asarray(vals)[order], np.asarray(res)[order]
