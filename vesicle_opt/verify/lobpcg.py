"""The second-order check without matrices (``verify.verdict`` defines the quantity and the rule).

At a KKT point of (6)-(8) with rigidity * grad E_h = lam_A grad A + lam_B grad B the Hessian of the
Lagrangian is H_L = rigidity H_E - lam_B H_B (A is linear). ``reduced_hessian_eigenvalues`` returns
the smallest eigenvalues of H_L v = mu M v (M = diag(m), the lumped mass) on the tangent space
T = {v : dA.v = 0, dB.v = 0}, minus the excluded symmetry modes, in units of ``verdict.mu_ref``: the
same number as the assembled check ``verify.second_order``, by LOBPCG (``verify.block_eig``, hand-rolled)
preconditioned with the Newton solve's own model P of ``nk.precond`` (Fourier symbol with cB = -lam_B;
on lumped P1 meshes the bending model (rigidity/eps) S M^{-1} S, whose approximate inverse is
``SparsePreconditioner.inverse``), the tangent space kept exactly by orthogonal projection. (An
earlier P-metric check iterated on {(P c).v = 0}, not on T, and its "excluded" rotation came back:
run to 330 iterations on the 64^2 ellipse, its least eigenvalue fell from 1.45e-3 to the rotation
mode's 4.5e-6.)

Start and stop (the cost): on Fourier grids the check first runs on coarser grids
(``lobpcg_rules.coarse_shape``: n/2 while that keeps eps/h >= ``ACCURATE``, then the least 5-smooth size with
eps/h >= ``ACCURATE``, then the least that resolves the interface, eps/h >= 1; e.g. 64^3 -> 40^3 ->
26^3, 96^3 -> 48^3 -> 26^3), on the Fourier-interpolated field, and each level starts from the
interpolated eigenvectors of the one below; on the coarsest level (and on meshes) the start is the
Rayleigh-Ritz selection from interface modulations p(x) (1 - phi^2) (p of degree <= 2: the smooth
shape modes; plus the rotation modes where they are not excluded), each column mixed with a random
one of equal norm (so that no symmetry class is missing: with a tenth of that norm the P1 48^3 box
ended at 0.137 and missed its least pair 0.0039). Each level stops when its Ritz values but the
guard have settled (``lobpcg_rules.settled``: to ``COARSE_EIG_TOL`` on the coarse level that starts the
fine one, ``LOWER_EIG_TOL`` on those below it, to ``EIG_TOL`` on the fine
one, which also needs a decided verdict and stops at the latest ``DECIDED_EXTRA`` iterations after
it), when every error bound is below ``TOL``, or at ``MAX_ITER``. Warm start (``warm``, a branch's
next point, ``branch.nk_corrector``): the coarse level that starts the fine one from the previous
point's eigenvectors there, the levels below it skipped (where the previous check ran it; else the
coarsest level from its eigenvectors, the finer ones as above: measured, 108 x 48 x 48 prolate, 26
against 300 coarsest iterations). Measured on the octant prolate's walk, the same points' checks
replayed (check CPU s, coarsest warm -> the level that starts the fine one warm, fine iterations 5
either way, the eigenvalues within their error bounds): 205 k nodes 1.54 / 1.63 / 2.15 / 1.73 ->
1.40 / 1.33 / 1.37 / 1.10 (the coarsest level's 16-70 iterations gone, the 80 x 24 x 24 level's
22-28 -> 19-30). The warm level starts from the Rayleigh-Ritz best k of the previous rows and the same
rows carried to this point's interface (``lobpcg_level.transported``, with the previous point's coarse
phi that ``levels`` keeps): where the interface moved by a sizeable part of eps the previous rows
sit beside it (Rayleigh quotient 14-38 against mu_min 0.032-0.036 at 525 k nodes, 9-12 against
0.069-0.083 at 205 k), the carried ones on it (0.042-0.046, 0.090-0.106); where it barely moved
(31 k nodes: 1.1-1.3 against 0.66-0.69) the previous rows are the better and Rayleigh-Ritz keeps
them. Replayed (the same checks, CPU s): 525 k nodes 35-38 -> 21-26 coarse iterations, 4.5-5.0 ->
3.3-4.6 s; 31 k 14-20 -> 17-21, 0.18-0.23 -> 0.23-0.26 s; fine iterations and eigenvalues unchanged
within their error bounds. Measured on the Table-1 torus (load ~6-9, one process, every coarse level then
to 1e-6): 64^3 26^3/40^3/64^3 levels 68/22/4 iterations, 3.0 s (from 32^3, the level before this
one: 62/19, 4.2 s; from random-mixed 48^3 for 96^3: 238-300 iterations); mu_min within 3e-7 of its
converged value 0.14520727. scipy's lobpcg (random start, 150 iterations at 64^3) ended with error
bound 0.32 against mu_min 0.145, no verdict.

It runs in the variables u = M^{1/2} v on the operator Pi M^{-1/2} H_L M^{-1/2} Pi / mu_ref (Pi the
orthogonal projector onto T there), which is the same iteration (every trial vector maps one to one,
Rayleigh-Ritz on T gives the same Ritz pairs), except that LOBPCG's residual test then measures the
residual on T in the M^{-1} norm, in units of mu_ref: the error bound ``err`` of ``verdict.classify``
(Bauer-Fike). An unprojected residual would count the multipliers' component of H v along the
constraint gradients, which is not an error and does not vanish. The dense work is a few
N x 3k products (``block_eig``: Gram matrices, no orthonormal basis formed), where BLAS threads
only spin: it runs with one BLAS thread (threadpoolctl).

Excluded modes (reported as ``excluded``; ``verdict``'s docstring says why): on Fourier grids the
translations d_i phi (the grid's whole-cell shifts are exact symmetries); the rotations
(x_i d_j - x_j d_i) phi only where a caller asks (``rotations``: studies that compare; the front
door and the branches keep them, since no grid in a periodic box is rotation-invariant and the
excluded generator can hide a descent direction). On periodic tensor P1 meshes the spectral
translations of ``second_order.translation_modes``, as the assembled check; nothing on other
meshes. The excluded modes' Rayleigh quotients on T are reported and enter the verdict; the
rotations' are reported beside it (``rotation_rayleigh``). The eigensolver's own final check
(``block_eig``) can turn the verdict into "not checked" with its reason. This is a numerical check
(a few eigenvalues, iterative), not a proof.
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from vesicle_opt.mesh.spectral import fourier_grid, resample
from vesicle_opt.model.lumped import LumpedOperators, PhaseField
from vesicle_opt.model.problem import constraint_data
from vesicle_opt.verify import axial, block_eig
from vesicle_opt.verify import lobpcg_level as level
from vesicle_opt.verify import lobpcg_rules as rules
from vesicle_opt.verify.lobpcg_rules import COARSE_EIG_TOL, DECIDED_EXTRA, EIG_TOL, LOWER_EIG_TOL, SETTLED_RUN, TOL
from vesicle_opt.verify import verdict as V
from vesicle_opt.verify.verdict import SecondOrder

K = 3  # block size: the least pair is often degenerate (saddles of the 2D ellipse elongate either way)
MAX_ITER = 300  # per level; a cap, not the usual end: the levels stop on EIG_TOL (measured: 64^3 torus
# from its 32^3 start settled after ~10 fine iterations; 32^3 from its interface start ~50). The cold
# check of the eps = 0.14 prolate (108 x 48 x 48) meets it on its 44 x 20 x 20 level (the partner of
# the nearly degenerate least pair), but the cap costs little there; tried and dropped (cold checks,
# interleaved, load ~2): a coarsest block of k + 3 (252 -> 95 iterations at v = 0.6955, check 2.0 ->
# 1.8 s; at v = 0.75 300 -> 174, 2.4-2.8 s -> 2.6-2.7 s, 10 fine iterations against 6; at v = 0.655
# 1.8-1.9 -> 2.0-2.1 s; 64^3 torus the same), and settling the least value only (2.1 -> 3.2 s: 28
# fine iterations against 6; 2.5 -> 4.1 s at v = 0.75)


def _start(scene, disc, pf, prec, phi, cB, ref, rotations, k, seed, counts, max_iter, warm=None, levels=None,
           feeds_fine=True):
    """Nodal start block for this level: the coarse eigenvectors interpolated, or None where there
    is no coarse level (the caller then starts from the interface block mixed with random columns).
    ``warm``: {coarse shape: nodal rows, ("phi", coarse shape): the phi they were found at} of a nearby
    point's check (a branch's previous point): the level that starts the fine one starts from its rows
    (and those rows carried to this phi, ``lobpcg_level.transported``, where warm holds that phi) where it
    holds them, and the levels below it are not run; else the coarsest level starts from its rows
    instead of the random-mixed interface block (module docstring, warm start); ``levels``: filled
    with {coarse shape: the nodal rows found there, ("phi", coarse shape): phi there};
    ``feeds_fine``: this level's eigenvectors start the fine level (its settling tolerance, ``lobpcg_rules``)."""
    shape = rules.coarse_shape(disc, scene.model.epsilon)
    if shape is not None:
        cdisc = fourier_grid(disc.box, shape, disc.kind)
        cpf = PhaseField(LumpedOperators(cdisc), scene.model.epsilon, scene.model.C)
        # the fine level's preconditioner class on the coarse grid (the same model; verify cannot
        # import nk, whose layer is above)
        cprec = type(prec)(cdisc.fourier, cdisc.weights[0], scene.model.epsilon)

        def ctrans(p, f=cdisc.fourier):
            rows = f.derivatives(p)
            return np.column_stack(rows) if rows else None
        cphi = resample(phi, disc.grid_shape, shape, disc.kind)
        here = None if warm is None else warm.get(tuple(shape))  # a nearby point's rows on this level
        if here is not None and np.shape(here) != (k, cphi.size):
            here = None
        if feeds_fine and here is not None:
            cX = None  # warm: this level starts from the nearby point's rows, the levels below are not run
        else:
            cX = _start(scene, cdisc, cpf, cprec, cphi, cB, ref, rotations, k, seed, counts, max_iter, warm, levels,
                        False)
        clev = level.setup(cdisc, cpf, cprec, ctrans, scene, cphi, cB, ref, rotations, band=True)
        settled = rules.settled(COARSE_EIG_TOL if feeds_fine else LOWER_EIG_TOL)
        if cX is not None:
            U0 = level.start_block(clev, clev.rows_to_u(cX, owned=True), k)  # the finer rows resampled here: its own
        elif here is not None:  # the nearby point's rows, and the same carried to this point's interface
            U = clev.rows_to_u(here)
            then = warm.get(("phi", tuple(shape)))
            if then is not None and np.shape(then) == cphi.shape:
                U = np.vstack([U, clev.rows_to_u(level.transported(here, then, cphi))])
            U0 = level.start_block(clev, U, k)
        else:
            U0 = level.start_block(clev, level.interface_block(clev, cphi, not rotations), k, seed)
        out = block_eig.lobpcg(clev.a_u, clev.t_u, U0, clev.Qall, max_iter,
                               lambda th, res: rules.coarse_stop(settled(th), res))
        counts.append((shape, out.iterations))
        rows = clev.rows_to_nodal(out.vectors)
        if levels is not None:
            levels[tuple(shape)] = rows
            levels[("phi", tuple(shape))] = cphi  # where they were found (``level.transported``)
        return np.stack([resample(v, shape, disc.grid_shape, disc.kind) for v in rows])
    return None


def spectrum(scene, result, setup, k: int = K, rotations: bool = False, max_iter: int | None = None,
             tol: float = TOL, seed: int = 0, X0=None, warm: dict | None = None) -> dict:
    """Everything the check computes: eigenvalues mu/mu_ref (ascending), their error bounds, the
    M-normalised eigenvectors (columns), the excluded modes' label and Rayleigh quotients on T
    (mu_ref units), mu_ref, the fine level's iteration count and each coarse level's, and
    ``levels``: {coarse shape: the nodal eigenvector rows found there, ("phi", coarse shape): the
    coarse phi}, which a nearby point's check
    takes as ``warm`` (``_start``). ``X0``: a nodal start block (columns) instead of the
    coarse-level / interface start. ``max_iter``: the LOBPCG cap per level, by default the scene's
    ``solver.second_order_max_iter`` (``MAX_ITER`` unless the scene raises it)."""
    if max_iter is None:
        max_iter = scene.solver.second_order_max_iter
    disc, pf, prec, translations = setup
    phi = np.asarray(result.phi, float)
    cB = -result.lambda_area
    ref = V.mu_ref(scene.model.rigidity, scene.model.epsilon, constraint_data(scene, disc)[1], disc.dim)
    with threadpool_limits(limits=1, user_api="blas"):
        lev = level.setup(disc, pf, prec, translations, scene, phi, cB, ref, rotations)
        rayleigh = level.excluded_rayleigh(lev)
        rotation = level.rotation_rayleigh(lev, phi) if not rotations else rayleigh[disc.dim:]
        lev.modes = None  # in Qall now; N x 6 less at the peak
        coarse, levels = [], {}
        rows = None if X0 is None else np.asarray(X0, float).reshape(phi.size, -1).T
        if rows is None:
            rows = _start(scene, disc, pf, prec, phi, cB, ref, rotations, k, seed, coarse, max_iter, warm, levels)
        # the start block goes to lobpcg as the call's only reference (``start.pop()``, ``overwrite``):
        # neither it nor the nodal rows it came from are held through the fine level's iteration
        start = [level.start_block(lev, level.interface_block(lev, phi, not rotations), k, seed) if rows is None
                 else level.start_block(lev, lev.rows_to_u(rows, owned=X0 is None), k)]  # _start's rows are its own, X0 the caller's
        del rows
        settled = rules.settled(EIG_TOL)
        since = [0]  # iterations since the verdict was first decided

        def stop(theta, res):
            err = block_eig.error_bounds(theta, res)
            verdict = V.classify(float(theta[0]), float(err[0]), rayleigh)[0]
            decided = verdict in ("minimum", "saddle")
            n_settled = settled(theta)
            since[0] += bool(decided or since[0])
            if decided and since[0] > DECIDED_EXTRA:
                return True
            # "marginal" does not end the level early: more iterations may still decide the sign
            return (decided and n_settled >= SETTLED_RUN) or bool(np.all(err <= tol))
        out = block_eig.lobpcg(lev.a_u, lev.t_u, start.pop(), lev.Qall, max_iter, stop, overwrite=True)
    return {"eigenvalues": out.values, "errors": out.errors, "vectors": lev.rows_to_nodal(out.vectors).T,
            "excluded": lev.excluded, "excluded_rayleigh": rayleigh, "mu_ref": ref,
            "iterations": out.iterations, "coarse_iterations": tuple(coarse), "history": out.history,
            "levels": levels, "residuals": out.residuals, "failure": out.reason, "rotation_rayleigh": rotation}


def reduced_hessian_eigenvalues(scene, result, setup, k: int = K, rotations: bool = False,
                                max_iter: int | None = None, tol: float = TOL, seed: int = 0,
                                vectors: bool = False):
    """(eigenvalues mu/mu_ref, error bounds in mu_ref units), ascending (module docstring); with
    ``vectors`` also the M-normalised eigenvectors (columns, nodal values). ``setup`` is the
    backend's (disc, PhaseField, preconditioner, translations) of ``nk.setup.prepare``."""
    sp = spectrum(scene, result, setup, k, rotations, max_iter, tol, seed)
    if vectors:
        return sp["eigenvalues"], sp["errors"], sp["vectors"]
    return sp["eigenvalues"], sp["errors"]


def check(scene, result, setup, rotations: bool = False, **kw) -> SecondOrder:
    """The verdict of ``verify.verdict.classify`` on the matrix-free spectrum; the translations are
    excluded on periodic grids, the rotations only where ``rotations`` asks (the front door never:
    ``verdict.excludes_rotations``; studies compare both).
    ``lowest_mode`` holds the critical (least) eigenvector, M-normalised, for continuation."""
    return check_levels(scene, result, setup, rotations, **kw)[0]


def check_levels(scene, result, setup, rotations: bool = False, **kw) -> tuple[SecondOrder, dict]:
    """``check`` and the coarse levels' eigenvectors (``spectrum``'s ``levels``; {} where the
    check broke down): pass them as ``warm`` to the check of a nearby point (a branch's next)."""
    try:
        sp = spectrum(scene, result, setup, rotations=rotations, **kw)
    except np.linalg.LinAlgError as e:  # a breakdown of the small dense eigenproblems
        nan = float("nan")
        return SecondOrder("not checked", nan, nan, (nan,), (), nan, f"lobpcg: {e}", errors=(nan,)), {}
    mu, err = float(sp["eigenvalues"][0]), float(sp["errors"][0])
    verdict, reason = V.classify(mu, err, sp["excluded_rayleigh"], sp["failure"])
    # a meridian mesh: the reason names the axial slide where it is the least mode (verify.axial)
    disc = setup[0]
    slide = axial.overlap(disc, result.phi, sp["vectors"][:, 0], scene.model.epsilon, scene.model.C)
    reason = V.axial_note(verdict, reason, False, float("nan"), slide, sp["eigenvalues"])
    so = SecondOrder(verdict, mu * sp["mu_ref"], mu, tuple(float(x) for x in sp["eigenvalues"]),
                     sp["excluded_rayleigh"], float(max(sp["errors"])), reason,
                     sp["vectors"][:, 0], excluded=sp["excluded"], errors=tuple(float(e) for e in sp["errors"]),
                     iterations=sp["iterations"], rotation_rayleigh=tuple(sp["rotation_rayleigh"]))
    return so, sp["levels"]
