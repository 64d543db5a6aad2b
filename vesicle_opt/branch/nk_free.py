"""The pseudo-arclength corrector with the parameter free on the Newton-Krylov backend.

The equations are those of ``branch.bordered`` (the KKT system (6)-(8) of one branch, alpha, beta,
C = sqrt(2) c0 affine in p, bordered by the arclength hyperplane and the phase conditions); here
nothing is assembled: H, the Hessian of the Lagrangian rigidity H_E - lambda_B H_B (H_A = 0), is
the matrix-free product of ``model.lumped.PhaseField.hvp_operator``, its model P^{-1} that of the
fixed-p Newton-CG (``nk.precond``, cE = rigidity, cB = -lambda_B; on 2D sparse meshes, where that
model is factored by LU, the interface-aware Gauss-Newton model ``SparsePreconditioner.gauss_newton``
at the state's own g'(phi); on mirror grids the bulk model plus the interface band's coarse space,
``model.band_coarse``, its Galerkin matrix that of H itself, not of the Gauss-Newton model: GMRES
needs no positive definite preconditioner. Measured on ``studies.bench_branch_3d``'s octant prolate
walk at 525 k nodes, points 2-5 back to back: 570 -> 397 GMRES iterations, 65.3 -> 51.8 CPU s, the same
28 Newton steps: ``VesicleKKT.pinv``), and the bordered Newton steps are
GMRES solves with the Schur-complement preconditioner of ``branch.krylov_bordered``. The operators
are the branch's Newton-Krylov setup (``nk.setup.prepare``: Fourier, mirror and FD-by-FFT grids, or
the sparse path); where the parameter is c0 only the pointwise part (PhaseField at C(p)) changes.

Phase conditions (the near-null modes that would make J numerically singular): the translations
w d_i phi_pred on spectral periodic grids (exact symmetries, as ``nk.setup`` projects them; their
multipliers vanish at a solution up to aliasing); on meridian meshes the axial pin
(``branch.bordered.axial_pin``). None on FD grids (whole-cell shifts only, as
``nk.setup``) and mirror grids (their symmetry class fixes position and orientation). The rotation
is not pinned: on FD grids it is no symmetry, and a rotation row (the IPOPT warm solves' row,
``branch.corrector.rotation_row``) held the FD ellipse at its axis orientation where the certified
point turns (measured: the switched branch of the nu = 0.8 ellipse in c0, its every fixed-p polish
at max_iter with the row, certified at 5-7 Newton steps without it); on the 2D spectral grids tried
its near-null mode (~1e-8 mu_ref) did not stall Newton (the circle's saddle: 3-4 steps a point).

r_p, the stationarity's derivative in p: 0 for the reduced volume; for c0, rigidity sqrt(2) dE'/dC,
dE' (the gradient) quadratic in C, so the central difference with step 1 is exact up to round-off.

The start's tangent (``tangent``): dphi/dp from the same bordered system at fixed p with the
right-hand side of a unit step in p, one GMRES solve to ``TANGENT_RTOL``; the walk's first step goes
along it with p free (``branch.arclength``), where a natural first step (p fixed, the previous field)
fails near a fold.

Newton's iterate after a step dphi is ``model.profile.step`` (the step taken in the profile's coordinate
T(phi) ~ d / (sqrt(2) eps), clipped; phi + dphi to first order): phi + dphi blurs a moving interface as
a linear predictor does, and at small eps that blur stalled Newton every other step at the prolate's
pole (``docs/guide/large-3d.md``).

Stop: the relative dual stationarity (P0's dual norm, as ``nk.solve`` measures it) <= ``STOP`` x tol
and the relative constraint residual (IPOPT's scaling) 100x below it (``CONSTRAINT_WEIGHT``): the fixed-p Newton-Krylov
solve at the p found (``branch.nk_corrector``), started there with these multipliers, then meets
its own test at once (0 Newton steps: inner 0.1 tol, constraints ``constraint_margin`` tol) and
certifies the point with the one certificate (``verify.certify``), its second-order check and
topology, as the IPOPT path certifies ``branch.bordered``'s point. On a meridian mesh the point is
certified as it stands (``NewtonKrylovCorrector.certify``: the certificate, the check, no solve):
the fixed-p solve has no pin and slides along the near-null slide (measured on the eps 0.05
stomatocyte: 200 Newton steps without converging from a pinned point whose certificate holds).
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.branch.bordered import Affine, axial_pin
from vesicle_opt.branch.krylov_bordered import Free, Linearization, border, bordered_solve, newton
from vesicle_opt.mesh.cosine import KIND as MIRROR_KIND
from vesicle_opt.model.lumped import PhaseField
from vesicle_opt.model.band_coarse import Lagged
from vesicle_opt.model import profile

CERTIFY_MAX_ITER = 10  # the certifying fixed-p solve's Newton budget, a safeguard: from a point Newton
# converged it takes 0 steps; one that needs many is off, and on a saddle sheet the minimiser then drifts
# (measured once, before CONSTRAINT_WEIGHT: 94 steps to another branch, refused 78 ds off): fail it fast
CONSTRAINT_WEIGHT = 100.0  # the constraints held 100x tighter than stationarity: the fixed-p solve reads
# its start through the augmented Lagrangian, whose multiplier is lam - rho c, so a constraint residual
# c shifts its stationarity by rho |c| |dB|_* (measured: relative 4.4e-10 in B on the 3D octant, rho_B =
# 167, shifted the dual residual to 1.5e-8 > its inner 0.1 tol: 94 steps instead of 0); A is linear and B
# converges quadratically, so this costs at most one more Newton step
STOP = 0.05  # x tol: below the fixed-p solve's own tests (0.1 tol on both), so it takes the point as is
TANGENT_RTOL = 1e-8  # GMRES's relative tolerance on the tangent. Its residual is the preconditioned one,
# small long before the near-null direction (the one that matters near a fold) is resolved: measured on
# a meridian cup 0.004 below its fold (eps 0.04, 11.5 k nodes), rtol 1e-4 / 1e-6 / 1e-8 / 1e-10 stopped
# at 4 / 20 / 188 / 192 iterations with |dphi/dp|_w 5.6 / 6.4 / 28.0 / 28.4 and cosine 0.22 / 0.23 /
# 0.99999 / 0.99999 to the finite difference of two certified points (|.|_w 28.1)
TANGENT_MAX_KRYLOV = 2000  # its GMRES iterations (one solve a walk): 188 on that cup, 741 on the eps 0.03 cup
# 0.006 below its fold (19.5 k nodes, 12 CPU-s); on the eps 0.03 saddle next to it 2000 did not reach 1e-8
# (restarted GMRES stagnates on the indefinite system): the tangent is then None, the first step natural


LAG_G = 0.3  # eps g'(phi) = 1 - 3 phi^2 spans [-2, 1]: a tenth of that span (|d phi| <~ 0.05 at the interface).
# Measured on the eps 0.04 meridian cup walk (16 points): 7 factorizations instead of one a Newton step
# (183), GMRES a point 132 -> 141, the same Newton steps, 154 -> 115 CPU s
LAG_CB = 0.1  # relative change of -lambda_B (the model's cB S term) that a factorization is kept through


class VesicleKKT:
    """``krylov_bordered``'s model of one branch: the KKT residual and its linearisation at (phi, lam, p);
    a Newton step moves phi along the interface's profile (``advance``: ``model.profile.step``)."""

    advance = staticmethod(profile.step)

    def __init__(self, setup, scene, affine: Affine):
        self.disc, pf, self.prec, self.translations = setup
        self.ops, self.eps, self.rig = pf.ops, scene.model.epsilon, scene.model.rigidity
        self.affine = affine
        self._pf: dict = {}
        self.volume = self.disc.volume
        self._lag = Lagged(self.eps, LAG_G, LAG_CB)  # the last factorization of the preconditioner (``pinv``)

    def pf(self, C: float) -> PhaseField:
        if C not in self._pf:
            if len(self._pf) > 8:
                self._pf.clear()
            self._pf[C] = PhaseField(self.ops, self.eps, C)
        return self._pf[C]

    def targets(self, p: float) -> tuple[float, float, float]:
        a = self.affine
        return a.alpha[0] + a.alpha[1] * p, a.beta[0] + a.beta[1] * p, a.C[0] + a.C[1] * p

    def at(self, phi, lam, p) -> Linearization:
        alpha, beta, C = self.targets(p)
        pf = self.pf(C)
        st = pf.state(phi)
        dE, dA, dB = pf.gradients(st)
        r = self.rig * dE - lam[0] * dA - lam[1] * dB
        c = np.array([st.A - alpha, st.B - beta])
        r_p = None
        if self.affine.C[1]:  # c0: d r/dp = rigidity C'(p) d(dE)/dC, central difference (exact: quadratic)
            up, down = (self.pf(C + h) for h in (1.0, -1.0))
            dE_up = up.gradients(up.state(phi))[0]
            dE_down = down.gradients(down.state(phi))[0]
            r_p = self.rig * self.affine.C[1] * (dE_up - dE_down) / 2.0
        dn = self.prec.dual_norm
        scale = self.rig * dn(dE) + abs(lam[0]) * dn(dA) + abs(lam[1]) * dn(dB)
        cscale = np.array([self.volume, abs(beta)])

        def error(r_, c_):
            dual = dn(r_) / max(scale, np.finfo(float).tiny)
            return max(dual, CONSTRAINT_WEIGHT * float(np.max(np.abs(c_) / cscale)))
        parts = pf.hessian_parts(st)
        return Linearization(r=r, c=c, hvp=pf.hvp_operator(st, parts, self.rig, -lam[1], 0.0),
                             pinv=self.pinv(st, lam, parts), G=[dA, dB], r_p=r_p,
                             c_p=np.array([-self.affine.alpha[1], -self.affine.beta[1]]), error=error)

    def pinv(self, st, lam, parts=None):
        """The Krylov solves' preconditioner at one state: where the mesh's bulk model is factored by LU
        (2D sparse meshes: ``nk.precond``) the interface-aware Gauss-Newton model; on mirror grids the
        bulk model plus the band's coarse space (``model.band_coarse``) with the Galerkin matrix of the
        Hessian (``parts``: its diagonals, ``PhaseField.hessian_parts``; None: P_GN's); else the bulk model. The
        factorization (the Gauss-Newton LU, the coarse space and its Galerkin LU) is reused while
        eps |g' - g'_factored| <= ``LAG_G`` everywhere and -lambda_B is within ``LAG_CB`` of its
        factored value (it only preconditions: GMRES solves the true system either way); where only
        -lambda_B moved, the coarse space's Galerkin matrix is re-factored at the new value, its space
        kept (``band_coarse.Lagged``)."""
        lu = getattr(self.prec, "kind", None) == "lu"
        grid = self.ops.fourier
        coarse = grid is not None and getattr(grid, "kind", None) == MIRROR_KIND
        if not (lu or coarse):
            return self.prec.inverse(self.rig, -lam[1], 0.0)
        s, cB = np.asarray(st.s, float), -float(lam[1])
        if lu:
            return self._lag.get(s, cB, lambda: self.prec.gauss_newton(s, self.rig, cB))
        return self._lag.band_coarse(grid, st.phi, s, self.rig, cB, parts).additive(self.prec.inverse(self.rig, cB, 0.0))

    def phase(self, phi_pred) -> list:
        """The phase conditions' vectors at the prediction (module docstring)."""
        if getattr(self.disc, "axisymmetric", False):  # the axial pin (``branch.bordered.axial_pin``)
            return [axial_pin(self.disc)]
        T = self.translations(np.asarray(phi_pred, float))
        w = self.disc.weights
        return [] if T is None else [w * T[:, i] for i in range(T.shape[1])]


def free_newton(model: VesicleKKT, phi_pred, lam_pred, p_pred: float, t_phi, t_p: float, theta: float,
                tol: float, deflation=None, max_newton: int | None = None, start=None) -> Free:
    """The bordered Newton-Krylov point on the hyperplane (``krylov_bordered.newton``; t_phi = 0,
    t_p = 1: at fixed p; ``deflation``: the step factor of ``branch.deflation``; ``start``: a candidate
    first iterate, taken where its error is the smaller, ``krylov_bordered.newton``)."""
    return newton(model, phi_pred, lam_pred, p_pred, t_phi, t_p, theta, model.disc.weights, STOP * tol,
                  phase=model.phase(phi_pred), deflation=deflation, start=start,
                  **({} if max_newton is None else {"max_newton": max_newton}))


def tangent(model: VesicleKKT, phi, lam, p: float) -> np.ndarray | None:
    """dphi/dp at a KKT point (phi, lam, p) of the branch: the bordered system of ``newton`` at fixed
    p (t_phi = 0, t_p = 1) with the right-hand side of a unit step in p and no residual, solved once
    by GMRES (``krylov_bordered.bordered_solve``): H dphi - G dlam + r_p = 0, G^T dphi + c_p = 0, the
    phase conditions held (T^T dphi = 0). None where GMRES did not converge. Near a fold H is nearly
    singular on the tangent space and dphi/dp large: the first step then predicts mostly in phi,
    and its corrector (p free, on the hyperplane orthogonal to the tangent) stays well posed."""
    phi = np.asarray(phi, float)
    lin = model.at(phi, np.asarray(lam, float), float(p))
    T = model.phase(phi)
    zero = np.zeros_like(phi)
    cols, rows, D = border(lin, T, zero, 1.0)  # p held: the hyperplane row is dp = 1
    g = np.zeros(len(rows))
    g[len(lin.G)] = 1.0
    dx, _, _, ok = bordered_solve(lin.hvp, lin.pinv, cols, rows, D, zero, g, TANGENT_RTOL, TANGENT_MAX_KRYLOV)
    return dx if ok and np.all(np.isfinite(dx)) else None
