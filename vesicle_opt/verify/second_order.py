"""The assembled second-order check of a KKT point (IPOPT backend): minimum or saddle?

At a KKT point of (6)-(8) the Hessian of the Lagrangian
    H = rigidity * D^2 E_h - lambda_A D^2 A - lambda_B D^2 B
must be positive semi-definite on the tangent space T = {v : dA.v = 0, dB.v = 0} for a local
minimiser. ``check`` computes the quantity of ``verify.verdict`` (the smallest eigenvalues of
H v = mu M v on T, over mu_ref) by shift-invert Lanczos on a bordered sparse system (consistent
mass: the Hessian reduced to phi with w = Delta_h phi through the NLP's own linear rows; lumped
mass: one factorisation of H - sigma M (LDL^T kept per pattern, or LU) and the Schur complement on the constraint columns,
``verify.shift_invert``), and decides with ``verdict.classify``, the rule the matrix-free check (``verify.lobpcg``) uses too.

Excluded modes (``SecondOrder.excluded``, ``verdict``'s docstring): on periodic grids the spectral
translations d_i phi ("translations": the grid's whole-cell shifts are exact symmetries, d_i phi the
tangent of the interpolant's shifts through them), M-orthogonally projected out of T, their Rayleigh
quotients on T reported and checked; nothing on other meshes. Rotations are not excluded, here or
in the matrix-free check: the rotation mode is one of the eigenvalues (measured 4.1e-3 mu_ref on the
64^2 ellipse, below the first shape mode 1.28); the rotation generators' own quotients on T are
reported (``rotation_rayleigh``). Error bounds: the residual norm on T, or Kato-Temple where the
next eigenvalue is separated (``block_eig.error_bounds``).
Meridian meshes: the axial slide d_z phi is near-null, not a symmetry, and is never excluded as one;
where the solve imposed a linear row (the axial pin of ``nlp.reuse``), T is the tangent space of all
the solve's rows, that one included (``pin``), and ``verdict.axial_note`` says so or names the slide.
The Hessian comes from the NLP's CasADi graph (the same one IPOPT used); the KKT residual it
relies on is checked independently in ``verify.kkt``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from threadpoolctl import threadpool_limits

from vesicle_opt.mesh.axisymmetric import axial_translation
from vesicle_opt.mesh.spectral import FourierGrid
from vesicle_opt.model import functionals as F
from vesicle_opt.verify import shift_invert as SI
from vesicle_opt.verify import verdict as V
from vesicle_opt.verify.axial import overlap as slide_overlap
from vesicle_opt.verify.block_eig import EPS, error_bounds
from vesicle_opt.verify.verdict import SecondOrder

N_EIG = 6
NCV = 4 * N_EIG  # ARPACK's Krylov space: 4k vectors converge the k wanted without a restart at the 20.3 k-node
# refined meridian points (25 solves against 30-31 with scipy's default max(2k + 1, 20); eigenvalues equal to 1e-15 mu_ref)
POWER_STEPS = 20  # power steps for the norm in the round-off floor (``_floor``)
MAX_SHIFTS = 4  # shift-invert passes: one at a minimum, two at the saddles seen here (p1 32^2: -8.7, then -9.9)


def hessian(nlp, x, lam_g) -> sp.csr_matrix:
    """Physical Hessian of the Lagrangian: f_scale * Hessian(f + lam_g . g) (see the nlp.exact scaling)."""
    import casadi as ca  # third-party, lazy: only IPOPT paths need it (0.25 s at import)
    lam = ca.MX.sym("lam", nlp.g.shape[0])
    H, _ = ca.hessian(nlp.f + ca.dot(lam, nlp.g), nlp.x)
    fun = ca.Function("lagrangian_hessian", [nlp.x, lam], [H])
    return sp.csr_matrix(fun(x, lam_g).sparse()) * nlp.f_scale


def translation_modes(disc, phi: np.ndarray) -> list[np.ndarray]:
    """Spectral d_i phi on a periodic grid (C-ordered nodes): the tangent of the trigonometric
    interpolant's shifts, which pass through every grid-shifted copy; none on other meshes. The
    matrix-free check uses the same modes. (Central differences, used before, are far from null:
    Rayleigh quotients 1.6, 2.3 mu_ref against 0.004, 0.018 on the 64^2 ellipse, both on T.)"""
    if disc.grid_shape is None:
        return []
    return FourierGrid(disc.box, disc.grid_shape).derivatives(np.asarray(phi, float))


def constraint_rows(nlp, x, trans, Mphi, jacobian_of=None, pin=None) -> sp.csr_matrix:
    """Jacobian of all NLP constraints at x, plus the translation rows t_i^T M and the solve's pin
    row c (``nlp.reuse.pin_of``), phi block only;
    ``jacobian_of(x)``: the Jacobian from a function built before (``nlp.reuse.derivatives``)."""
    if jacobian_of is not None:
        J = jacobian_of(x)
    else:
        import casadi as ca  # third-party, lazy: only IPOPT paths need it (0.25 s at import)
        jac = ca.Function("constraint_jacobian", [nlp.x], [ca.jacobian(nlp.g, nlp.x)])
        J = sp.csr_matrix(jac(x).sparse())
    rows = [Mphi @ t for t in trans] + ([np.asarray(pin, float)] if pin is not None else [])
    if rows:
        T = np.vstack(rows)
        T = np.hstack([T, np.zeros((len(rows), J.shape[1] - T.shape[1]))])
        J = sp.vstack([J, sp.csr_matrix(T)], format="csr")
    return J


def _tangent_projector(C, solve_mass):
    """v -> v - M^{-1} C (C^T M^{-1} C)^{-1} C^T v: the M-orthogonal projection onto {C^T v = 0};
    and its transpose r -> r - C (C^T M^{-1} C)^{-1} C^T M^{-1} r (the residual on that space)."""
    MC = np.column_stack([solve_mass(c) for c in C.T])
    G = np.linalg.cholesky(C.T @ MC)

    def coef(y):
        return np.linalg.solve(G.T, np.linalg.solve(G, y))
    return (lambda v: v - MC @ coef(C.T @ v)), (lambda r: r - C @ coef(MC.T @ r))


tangent_projector = _tangent_projector  # the public name (``branch.symmetric_fold`` restricts H to a subspace of T)


def _floor(reduced, Mphi, solve_mass, n: int, steps: int = POWER_STEPS) -> float:
    """The round-off floor of a Rayleigh quotient of the reduced Hessian in the mass metric, eps
    ||M^{-1} H|| (a backward-stable product's relative error), the norm by a few power steps (a
    lower estimate of the largest |eigenvalue|, within a small factor after ``POWER_STEPS``): no
    error bound is reported below it (Kato-Temple's r^2 / gap can be)."""
    v = np.random.default_rng(0).standard_normal(n)
    lam = 0.0
    for _ in range(steps):
        v /= np.sqrt(v @ (Mphi @ v))
        w = solve_mass(reduced(v))
        lam = float(np.sqrt(w @ (Mphi @ w)))
        v = w
    return EPS * lam


def start_vector(n: int) -> np.ndarray:
    """The Lanczos start: deterministic (bitwise-reproducible summaries) with a part in every direction.
    Not ones(n), which with lumped mass is M^-1 grad A: ARPACK's forced start OPinv(M v0) then lies in
    the constraints' normal space and was round-off only, its sign and size set by the BLAS kernel and
    the thread count ("starting vector is zero" under OMP_NUM_THREADS=1 on an FD ellipse, measured)."""
    return np.random.default_rng(0).standard_normal(n)


def _eigenpairs(H, B, J, Aop, Mphi, C_rows, mu_ref, n, nx, n_eig):
    """Shift-invert Lanczos (ARPACK) from sigma = -mu_ref / 2, moved below the least eigenvalue found
    until none lies below it (``check``); on lumped meshes the bordered solve by one factorisation of H - sigma M
    and the Schur complement (``shift_invert.factorise``; the bordered LU where that fails).
    Returns (mu, vectors)."""
    pad = np.zeros(J.shape[0] + nx - n)
    v0 = start_vector(n)
    sigma = -0.5 * mu_ref
    for _ in range(MAX_SHIFTS):
        bordered = SI.factorise(H, Mphi, sigma, C_rows) if C_rows is not None else None
        if bordered is not None:
            OPinv = spla.LinearOperator((n, n), matvec=bordered.solve, dtype=float)
        else:
            lu = spla.splu(sp.bmat([[H - sigma * B, J.T], [J, None]], format="csc"))
            OPinv = spla.LinearOperator((n, n), matvec=lambda r, lu=lu: lu.solve(np.concatenate([r, pad]))[:n],
                                        dtype=float)
        mu, Vec = spla.eigsh(Aop, k=n_eig, M=Mphi, sigma=sigma, which="LM", OPinv=OPinv, v0=v0, tol=1e-10,
                             ncv=min(max(NCV, 2 * n_eig + 1), n) if NCV else None)
        if mu.min() >= sigma:
            break
        sigma = 2 * mu.min()
    return mu, Vec


def check(nlp, result, n_eig: int = N_EIG, derivatives=None, pin=None) -> SecondOrder:
    """``_check`` (below) with one BLAS thread: its dense work is ARPACK's Krylov basis and vector
    products, where a second OpenBLAS thread only spin-waits on a busy machine, as in ``nk.solve``
    (measured, refined meridian prolate at eps/R0 = 0.02, 20.3 k nodes, OMP_NUM_THREADS=2, load
    ~19 on 2 cores, 6 points: check median 3.48 s wall with the default threads against 1.01 s)."""
    with threadpool_limits(limits=1, user_api="blas"):
        return _check(nlp, result, n_eig, derivatives, pin)


def _check(nlp, result, n_eig: int = N_EIG, derivatives=None, pin=None) -> SecondOrder:
    """Smallest eigenvalues by shift-invert Lanczos (ARPACK) on the bordered system

        [[H - sigma B, J^T], [J, 0]] [u; y] = [M r; 0],   B = blockdiag(M, 0 for w),

    whose phi-block is (H - sigma M)^{-1} restricted to the tangent space (w eliminated by the
    linear rows M w + K phi = 0 inside J). ARPACK returns the eigenvalues nearest sigma: starting at
    sigma = -mu_ref / 2 (below the soft modes of a minimum), sigma is moved below the least eigenvalue
    found (to twice it) until none lies below sigma, so that a deep saddle reports its least one.
    ``derivatives``: (hessian_of(x, lam_g), jacobian_of(x)) built before, e.g. the IPOPT solver's own
    of a parametric NLP reused along a branch (``nlp.reuse.derivatives``); default: built here.
    ``pin``: the row c of a linear constraint c . phi = d the solve imposed (``nlp.reuse.pin_of``, the
    axial position on a refined meridian mesh): T is the tangent space of all the solve's rows, the
    pin's included, and the reason says "axial position pinned". On a meridian mesh the axial
    slide's Rayleigh quotient on {dA.v = dB.v = 0} is reported (``axial_rayleigh``); unpinned, the
    slide stays in T and the reason names it where it is the least mode (``verdict.axial_note``).
    """
    disc, sc = nlp.disc, nlp.scene
    n = disc.n_nodes
    eps, rig = sc.model.epsilon, sc.model.rigidity
    hessian_of, jacobian_of = derivatives or (None, None)
    H = hessian_of(result.x, result.lam_g) if hessian_of else hessian(nlp, result.x, result.lam_g)
    Mphi = sp.csr_matrix(disc.M) if disc.consistent else sp.diags(disc.weights, format="csr")
    nx = H.shape[0]
    B = sp.block_diag([Mphi, sp.csr_matrix((nx - n, nx - n))], format="csr") if nx > n else Mphi
    trans = translation_modes(disc, result.phi)
    J = constraint_rows(nlp, result.x, trans, Mphi, jacobian_of, pin)
    mu_ref = V.mu_ref(rig, eps, nlp.beta, disc.dim)

    def reduced(v):  # H on phi with w = Delta_h v (only used for residuals)
        if nx == n:
            return H @ v
        full = np.concatenate([v, disc.apply_laplacian(v)])
        return (H @ full)[:n] + disc.apply_laplacian_transpose((H @ full)[n:])

    Aop = spla.LinearOperator((n, n), matvec=reduced, dtype=float)
    lumped = nx == n and not disc.consistent  # the bordered solve by the Schur complement (shift_invert)
    mu, Vec = _eigenpairs(H, B, J, Aop, Mphi, J.toarray().T if lumped else None, mu_ref, n, nx, n_eig)
    order = np.argsort(mu)
    mu, Vec = mu[order], Vec[:, order]
    grads = F.gradients(disc, result.phi, eps, sc.model.C)[1:]
    C_ab = np.column_stack(grads)
    C_all = np.column_stack([*grads, *(Mphi @ t for t in trans), *([pin] if pin is not None else [])])
    _, on_t = _tangent_projector(C_all, disc.solve_mass)

    def m_norm_inv(r):  # sqrt(r^T M^{-1} r)
        return float(np.sqrt(max(r @ disc.solve_mass(r), 0.0)))

    res = []
    for i in range(len(mu)):  # residual of each pair on T in the M^{-1} norm: its eigenvalue error bound
        v = Vec[:, i]
        r = on_t(reduced(v) - mu[i] * (Mphi @ v))
        res.append(m_norm_inv(r) / (np.sqrt(v @ (Mphi @ v)) * mu_ref))
    floor = _floor(reduced, Mphi, disc.solve_mass, n) / mu_ref
    errors = list(np.maximum(error_bounds(mu / mu_ref, np.maximum(res, floor)), floor))
    onto_ab, _ = _tangent_projector(C_ab, disc.solve_mass)

    def rayleigh_of(t):  # a direction M-orthogonally onto {dA.v = dB.v = 0}; nan where it vanishes there
        u = onto_ab(t)
        if not np.linalg.norm(u) > 1e-8 * np.abs(t).max() * np.sqrt(t.size):
            return float("nan")
        return float((u @ reduced(u)) / (u @ (Mphi @ u)) / mu_ref)
    rayleigh = [rayleigh_of(t) for t in trans]  # each excluded mode
    x = np.asarray(disc.nodes, float)
    pairs = (((1, 2), (2, 0), (0, 1)) if disc.dim == 3 else ((0, 1),)) if trans else ()
    rotation = tuple(rayleigh_of(x[:, i] * trans[j] - x[:, j] * trans[i]) for i, j in pairs)
    rel = float(mu[0] / mu_ref)
    verdict, reason = V.classify(rel, errors[0], rayleigh)
    axial, overlap = float("nan"), float("nan")
    if getattr(disc, "axisymmetric", False):
        axial = rayleigh_of(axial_translation(disc, result.phi))
        overlap = slide_overlap(disc, result.phi, Vec[:, 0], eps, sc.model.C, Mphi)
    reason = V.axial_note(verdict, reason, pin is not None, axial, overlap, mu / mu_ref)
    return SecondOrder(verdict, float(mu[0]), rel, tuple(float(m / mu_ref) for m in mu), tuple(rayleigh),
                       float(max(errors)), reason, Vec[:, 0] / np.sqrt(Vec[:, 0] @ (Mphi @ Vec[:, 0])),
                       excluded=V.excluded_label(disc, trans), errors=tuple(float(e) for e in errors),
                       rotation_rayleigh=rotation, axial_rayleigh=axial)
