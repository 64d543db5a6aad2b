"""The pseudo-arclength corrector with the parameter free: Newton on the bordered (Keller) system.

A branch point is a KKT point of (6)-(8) at its parameter p. Near a fold the fixed-p problem is
singular (the least reduced-Hessian eigenvalue crosses zero there) and beyond it in p it has no
point on this branch, so a corrector that holds p fixed cannot pass it. Here p is an unknown, and
the extra equation is the arclength hyperplane of the predictor (``branch.arclength``):

    rigidity dE(phi; C(p)) - lambda_A dA - lambda_B dB - sum_i mu_i W t_i = 0   (stationarity, nodal)
    A(phi) - alpha(p) = 0,   B(phi) - beta(p) = 0                                (7), (8)
    theta^2 <phi - phi_pred, t_phi>_w + (p - p_pred) t_p = 0                   (the hyperplane)
    <W t_i, phi - phi_pred> = 0                                                  (phase conditions)

with alpha, beta, C = sqrt(2) c0 affine in p (``Affine``: the reduced volume moves alpha at fixed
beta, c0 moves C at fixed alpha, beta; ``branch.params``), W = diag(w) the lumped mass. The phase
conditions pin the translations t_i = d_i phi_pred (spectral derivatives, periodic grids only):
exact symmetries of the continuum and near-null modes of the grid's KKT matrix (Rayleigh quotients
~1e-10 mu_ref, ``verify.second_order``), which would make the Newton matrix numerically singular;
their multipliers mu_i vanish at a solution up to that symmetry breaking. On a meridian mesh the
one phase condition is the axial pin (``axial_pin``: the inside's centre of mass held at the
prediction's), the slide between the natural end walls being near-null (+-1e-5 mu_ref) and not an
exact symmetry; its multiplier is the walls' tiny force (-3.6e-6 on the eps 0.05 stomatocyte,
measured), which the certificate, recomputing stationarity without the row, judges. At a simple fold the
Jacobian of this system is nonsingular where the fixed-p one is not (Keller's bordering lemma), so
Newton converges quadratically through it.

The Jacobian: one CasADi function of (phi, lambda_A, lambda_B, p) built once per branch (the
Hessian's sparsity, two dense columns, one p column), bordered in scipy and factorised by sparse
LU; a factorisation is reused (chord steps) while the steps shrink by ``CHORD_RATIO`` or faster. The result is not trusted by itself: the branch hands the point to the
fixed-p IPOPT solve at the p found (``branch.corrector``), warm, which certifies it as a KKT point
of the fixed-p problem (the common certificate; 0-1 IPOPT iterations from a Newton-converged point).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vesicle_opt.model import functionals as F
from vesicle_opt.nlp.reuse import pin_row
from vesicle_opt.verify.second_order import translation_modes

MAX_NEWTON = 30  # steps, Newton or chord
CHORD_RATIO = 0.25  # a step reuses the last factorisation (chord) while the steps shrink at least
# this fast, else the Jacobian is refreshed (Newton): at 128^2 a factorisation is ~0.9 s, a solve ~0.05 s
ORDERING = "COLAMD"  # SuperLU's column ordering, robust to its row pivoting. The symmetric MMD_AT_PLUS_A was
# faster where the pivots stay on the diagonal (128^2: 0.85 s and 5.0e6 factor entries against 1.33 s and
# 7.7e6), but off-diagonal pivots wreck a symmetric ordering's fill: on the eps 0.03 meridian branch out of
# the oblate's odd branch point (19.7 k unknowns, ``_stomatocyte.switched``) one Jacobian took 88 s and
# 1.2e8 entries against COLAMD's 0.29 s and 5.4e6 (residual 4.9e-8 and 4.8e-8 of a unit right-hand side),
# and that walk's LUs averaged 2.8 s (measured)
HALVINGS = 12  # a merit-guarded (deflated) step is halved at most this often (to 2.4e-4 of itself)
STEP_TOL = 1e-10  # |d phi|_w <= STEP_TOL |phi|_w and |d p| <= STEP_TOL max(1, |p|) ends Newton: the
# step after it is ~STEP_TOL^2 (quadratic convergence), far below IPOPT's tol 1e-8 on the polish


@dataclass(frozen=True)
class Affine:
    """alpha(p), beta(p), C(p) = v0 + v1 p for one branch parameter."""

    alpha: tuple[float, float]
    beta: tuple[float, float]
    C: tuple[float, float]


@dataclass(frozen=True)
class Newton:
    """What the bordered Newton iteration found (``converged`` false: diverged or stalled)."""

    phi: np.ndarray
    p: float
    lam: tuple[float, float]
    converged: bool
    iterations: int
    message: str = ""


def axial_pin(disc) -> np.ndarray:
    """The row c of the warm solves' axial pin on a meridian mesh: the centre of mass of the inside,
    c . phi = sum m (z - z_m) phi / sum m |z - z_m| (``nlp.reuse.pin_row``, the front door's pin, linear
    and the same at every point), held at the prediction's value c . phi0 (``branch.corrector.IpoptCorrector.solve``)
    and, as a phase condition, by the p-free correctors (``phase_rows``; ``branch.nk_free``).
    Unpinned, the slide between the natural end walls is near-null (+-1e-5 mu_ref): the stomatocyte's
    warm solves at eps 0.1 (uniform, h = eps / 2) ran IPOPT into 50 iterations of step lengths 1.5e-5
    at dual 1.4e-7 after dv = 1e-4, and Newton on the bordered system diverged (a numerically singular
    LU) even at the converged point's own v (measured)."""
    return pin_row(disc)[:-1]


def phase_rows(disc, phi_pred) -> list[np.ndarray]:
    """The phase conditions' rows (module docstring): the weighted translations w d_i phi_pred on
    periodic grids; on a meridian mesh the axial pin (``axial_pin``: the centre of
    mass of the inside held at the prediction's), the slide between the natural end walls being
    near-null; none elsewhere."""
    if getattr(disc, "axisymmetric", False):
        return [axial_pin(disc)]
    return [disc.weights * t for t in translation_modes(disc, phi_pred)]


class BorderedCorrector:
    """The bordered system of one branch (module docstring), its CasADi Jacobian built once; its
    phase conditions ``phase_rows``."""

    def __init__(self, scene, disc, affine: Affine):
        import casadi as ca  # third-party, lazy: only the IPOPT path builds graphs (0.25 s at import)
        self.scene, self.disc, self.affine = scene, disc, affine
        if disc.consistent:
            raise ValueError("the bordered corrector runs on lumped mass (unknowns phi only)")
        n = disc.n_nodes
        eps, rig = scene.model.epsilon, scene.model.rigidity
        phi, lam_a, lam_b, p = (ca.MX.sym(name, k) for name, k in (("phi", n), ("lam_a", 1), ("lam_b", 1), ("p", 1)))
        ops = F.CasadiOps(disc)
        lap = ca.mtimes(F.sparse_dm(disc.laplacian), phi)
        C = affine.C[0] + affine.C[1] * p
        E = F.energy(ops, phi, lap, eps, C)
        A = F.volume_functional(ops, phi)
        B = F.area_functional(ops, phi, eps)
        stat = rig * ca.gradient(E, phi) - lam_a * ca.gradient(A, phi) - lam_b * ca.gradient(B, phi)
        R = ca.vertcat(stat, A - (affine.alpha[0] + affine.alpha[1] * p), B - (affine.beta[0] + affine.beta[1] * p))
        J = ca.horzcat(*(ca.jacobian(R, v) for v in (phi, lam_a, lam_b, p)))
        self._fun = ca.Function("bordered_kkt", [phi, lam_a, lam_b, p], [R, J])
        self._res = ca.Function("bordered_residual", [phi, lam_a, lam_b, p], [R])
        self.n = n

    def fixed(self, phi0, p: float, lam0, deflation=None, merit=None) -> Newton:
        """Newton at fixed p (the hyperplane p = const: t_phi = 0, t_p = 1) from (phi0, lam0): the
        fallback of the IPOPT corrector, which as a minimiser may wander near a saddle of the
        discrete problem; Newton converges to the KKT point whatever its inertia."""
        return self.solve(phi0, p, lam0, np.zeros(self.n), 1.0, 0.0, deflation, merit)

    def _rows(self, z, mu, R, trans, phi_pred, t_phi, theta, t_p, p_pred) -> np.ndarray:
        """The bordered system's residual at (z, mu) from the KKT rows R there: stationarity less the
        phase multipliers' forces, the hyperplane row, the phase rows."""
        n = self.n
        R = np.asarray(R).ravel()
        R[:n] -= sum(m * t for m, t in zip(mu, trans)) if len(trans) else 0.0
        N = theta**2 * float(self.disc.weights @ ((z[:n] - phi_pred) * t_phi)) + (z[n + 2] - p_pred) * t_p
        return np.concatenate([R, [N], [float(t @ (z[:n] - phi_pred)) for t in trans]])

    def _backtrack(self, z, mu, du, trans, phi_pred, t_phi, theta, t_p, p_pred, merit, g0) -> np.ndarray:
        """du halved until merit(phi) |R| at z + du is below g0 (``solve``, which evaluates it with
        overflow ignored: a trial far out is non-finite and halved); du itself if none is."""
        n = self.n
        for _ in range(HALVINGS + 1):
            zt, mt = z + du[: n + 3], mu + du[n + 3:]
            R = self._res(zt[:n], zt[n], zt[n + 1], zt[n + 2])
            g = merit(zt[:n]) * np.linalg.norm(self._rows(zt, mt, R, trans, phi_pred, t_phi, theta, t_p, p_pred))
            if np.isfinite(g) and g < g0:
                return du
            du = du / 2
        return du * 2 ** (HALVINGS + 1)

    def solve(self, phi_pred, p_pred: float, lam_pred, t_phi, t_p: float, theta: float,
              deflation=None, merit=None) -> Newton:
        """Newton from the prediction (phi_pred, p_pred, lam_pred) onto the hyperplane through it
        orthogonal to the tangent (t_phi, t_p) in the metric theta^2 <., .>_w + dp^2.
        ``deflation(phi, dphi)``: the factor of each step (``branch.deflation``), None: 1.
        ``merit(phi)``: a positive weight m(phi) of the residual (the deflation operator M); given, each
        step is halved (at most ``HALVINGS`` times) until m |R| decreases (a backtracking line search
        on the deflated residual, Farrell et al.'s globalisation), else taken whole."""
        n, w = self.n, self.disc.weights
        trans = phase_rows(self.disc, phi_pred)
        d = len(trans)
        z = np.concatenate([np.asarray(phi_pred, float), np.asarray(lam_pred, float), [p_pred]])
        mu = np.zeros(d)
        n_row = np.concatenate([theta**2 * w * t_phi, [0.0, 0.0, t_p]])
        scale = np.sqrt(w @ (z[:n] ** 2))
        T = sp.csc_matrix(np.column_stack(trans)) if d else None
        lu, last = None, np.inf

        def result(converged: bool, k: int, why: str = "") -> Newton:
            return Newton(z[:n], float(z[n + 2]), (float(z[n]), float(z[n + 1])), converged, k, why)
        for k in range(1, MAX_NEWTON + 1):
            if lu is None:
                R, J = self._fun(z[:n], z[n], z[n + 1], z[n + 2])
            else:
                R = self._res(z[:n], z[n], z[n + 1], z[n + 2])
            rhs = -self._rows(z, mu, R, trans, phi_pred, t_phi, theta, t_p, p_pred)
            if lu is None:
                J = sp.csc_matrix(J.sparse())
                if d:
                    rows = [[J, sp.vstack([-T, sp.csc_matrix((2, d))])],
                            [sp.csr_matrix(n_row), sp.csr_matrix((1, d))],
                            [sp.hstack([T.T, sp.csr_matrix((d, 3))]), sp.csr_matrix((d, d))]]
                else:
                    rows = [[J], [sp.csr_matrix(n_row)]]
                try:
                    lu = spla.splu(sp.bmat(rows, format="csc"), permc_spec=ORDERING)
                except RuntimeError as exc:  # an exactly singular bordered matrix: not a simple fold
                    return result(False, k, str(exc))
            du = lu.solve(rhs)
            if not np.all(np.isfinite(du)):
                return result(False, k, "non-finite step")
            if deflation is not None:  # the deflated Newton step: the same direction, rescaled
                du = du * deflation(z[:n], du[:n])
            with np.errstate(over="ignore", invalid="ignore"):  # a diverging iterate or trial: refused below
                if merit is not None:
                    du = self._backtrack(z, mu, du, trans, phi_pred, t_phi, theta, t_p, p_pred, merit,
                                         merit(z[:n]) * np.linalg.norm(rhs))
                z = z + du[: n + 3]
                mu = mu + du[n + 3:]
                dphi = np.sqrt(w @ (du[:n] ** 2))
            if not (np.isfinite(dphi) and np.all(np.isfinite(z))):
                return result(False, k, "non-finite step")
            if dphi <= STEP_TOL * scale and abs(du[n + 2]) <= STEP_TOL * max(1.0, abs(z[n + 2])):
                return result(True, k)
            if dphi > CHORD_RATIO * last:  # the chord contracts too slowly: a fresh Jacobian next
                lu = None
            last = dphi
        return result(False, MAX_NEWTON, f"no convergence in {MAX_NEWTON} Newton steps")
