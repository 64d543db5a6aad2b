"""The Hessian of the Lagrangian of the exact NLP (6)-(8), assembled by sparse products, for IPOPT.

CasADi differentiates the NLP's MX graph twice and evaluates the Hessian by graph colouring: one
second-order sweep per colour of the bi-Laplacian stencil. On a 62 k-node refined meridian mesh that is
0.14-0.23 s a call, some 40 % of an IPOPT iteration (``phase_diagram``'s prolate at eps 0.025:
``t_wall_nlp_hess_l`` 4.8 s of 21 iterations, measured). The matrix has a closed form; with lumped
nodal quadrature (weights m, Delta_h = L = -M_L^{-1} K, Definition 2.2) and f_c = eps L phi + g(phi):

    E_h = 1/(2 eps) sum m f_c^2                 d2E = 1/eps [J^T diag(m) J + diag(m f_c g''(phi))],
                                                J = eps L + diag(g'(phi))          ((6); ``model.functionals``)
    A   = m . phi                               d2A = 0                            ((7))
    B   = eps/2 phi^T K phi + 1/eps sum m W     d2B = eps K + 1/eps diag(m W''(phi))   ((8))

and the NLP's scaling (``nlp.exact``: f = rigidity E_h / f_scale, g_B = (B - beta) / beta, the volume
and pin rows linear) makes IPOPT's matrix sigma rigidity / f_scale d2E + lam_B / beta d2B, with
(beta, C, f_scale) read from the parametric NLP's p at each call. ``hess_lag`` is that matrix as a
CasADi Function (a ``Callback`` on CasADi's buffers: ``Assembled``, vector operations on the fixed
pattern of L^T L + K + I with L^T diag(m) L kept per mesh), given to ``nlpsol`` as ``hess_lag``: its
upper triangle. Only for parametric exact NLPs with lumped mass and nodal quadrature (``applies``);
elsewhere CasADi's own Hessian stays. ``tests/nlp/test_lumped_hessian.py``: the same matrix as CasADi's
and as scipy's sparse products of the formulas above to round-off, and the same solve.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from vesicle_opt.model import functionals as F


def applies(nlp) -> bool:
    """Whether ``hess_lag`` holds for this NLP: a parametric exact NLP (p = (alpha, beta, C, f_scale, ...))
    on lumped mass with nodal quadrature (x = phi)."""
    d = nlp.disc
    return (not d.consistent and not d.gauss and nlp.p.shape[0] >= 4 and nlp.x.shape[0] == d.n_nodes
            and getattr(d, "grid_shape", None) is None)


class Assembled:
    """IPOPT's matrix (module docstring) on a fixed pattern, by arrays kept per mesh: the upper
    triangle (CSC, CasADi's order) of the pattern of L^T L + K + I, and on it L^T diag(m) L, L_ij, L_ji and
    (K + K^T)/2, so that each call is a few vector operations on the pattern's entries (0.01 s at 62 k
    nodes, 430 k entries, against 0.065 s for the same matrix by scipy's sparse products: measured)."""

    def __init__(self, disc):
        L, K, m = disc.laplacian.tocsc(), disc.K.tocsc(), np.asarray(disc.weights, float)
        n = L.shape[0]
        one = lambda a: sp.csc_matrix((np.ones(a.nnz), a.indices, a.indptr), shape=a.shape)  # noqa: E731
        full = (one(L).T @ one(L) + one(K) + one(K).T + sp.identity(n, format="csc")).tocsc()
        upper = sp.triu(full, format="csc")
        upper.sort_indices()
        self.upper, self.n = upper, n
        self.rows = upper.indices.astype(np.int64)
        self.cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(upper.indptr))
        self.diag = np.flatnonzero(self.rows == self.cols)  # node k's diagonal entry: self.diag[k] (CSC order)
        on = lambda a: np.asarray(a.tocsr()[self.rows, self.cols], float).ravel()  # noqa: E731
        self.LtDL = on(L.T @ sp.diags(m) @ L)
        self.Lij, self.Lji = on(L), on(L.T.tocsc())
        self.Ks = on((K + K.T) / 2)
        self.m = m
        self.L = L.tocsr()

    def values(self, phi, epsilon: float, rigidity: float, f_scale: float, beta: float, C: float,
               sigma: float, lam_area: float) -> np.ndarray:
        """The upper triangle's values of sigma rigidity / f_scale d2E_h + lam_area / beta d2B at phi
        (module docstring; ``lam_area`` IPOPT's multiplier of the area row) on ``upper``:
        J^T D J = eps^2 L^T D L + eps (L^T D G + G D L) + D G^2 with G = diag(g'(phi)), D = diag(m)."""
        phi = np.asarray(phi, float)
        m, i, j = self.m, self.rows, self.cols
        gp = F.reaction_derivative(phi, epsilon, C)
        fc = F.curvature_residual(phi, self.L @ phi, epsilon, C)
        a, b = sigma * rigidity / f_scale / epsilon, lam_area / beta
        mg = m * gp
        out = a * (epsilon**2 * self.LtDL + epsilon * (self.Lji * mg[j] + self.Lij * mg[i])) + b * epsilon * self.Ks
        out[self.diag] += a * m * (gp * gp + fc * F.reaction_second_derivative(phi, epsilon, C)) \
            + b * m * F.double_well_second_derivative(phi) / epsilon
        return out


def hess_lag(nlp):
    """The CasADi Function (x, p, lam_f, lam_g) -> upper triangle of IPOPT's Hessian of the Lagrangian
    (``nlpsol``'s ``hess_lag``) for an NLP where ``applies``; keep it alive as long as its solver."""
    import casadi as ca  # third-party, lazy: only the IPOPT path builds graphs (0.25 s at import)

    disc, scene = nlp.disc, nlp.scene
    eps, rigidity = scene.model.epsilon, scene.model.rigidity
    pattern = Assembled(disc)
    up = pattern.upper
    sparsity = F.sparsity_of(up)  # sorted CSC (``Assembled``): the callback's values in its order
    n, n_p, n_g = pattern.n, nlp.p.shape[0], nlp.g.shape[0]

    class _Hessian(ca.Callback):
        def __init__(self):
            ca.Callback.__init__(self)
            self.construct("lumped_hess_lag", {})

        def get_n_in(self):
            return 4

        def get_n_out(self):
            return 1

        def get_sparsity_in(self, i):
            return ca.Sparsity.dense((n, n_p, 1, n_g)[i], 1)

        def get_sparsity_out(self, i):
            return sparsity

        def has_eval_buffer(self):
            return True  # CasADi's memory as buffers: no DM conversion (0.05 s each way at 62 k nodes, measured)

        def eval_buffer(self, arg, res):
            x, p = (np.frombuffer(arg[k], dtype=np.float64) for k in (0, 1))
            sigma, lam = float(np.frombuffer(arg[2], dtype=np.float64)[0]), np.frombuffer(arg[3], dtype=np.float64)
            np.frombuffer(res[0], dtype=np.float64)[:] = pattern.values(x, eps, rigidity, p[3], p[1], p[2], sigma, lam[1])
            return 0

    cb = _Hessian()
    xs, ps, lf, lg = ca.MX.sym("x", n), ca.MX.sym("p", n_p), ca.MX.sym("lam_f"), ca.MX.sym("lam_g", n_g)
    fun = ca.Function("nlp_hess_l", [xs, ps, lf, lg], [cb(xs, ps, lf, lg)], ["x", "p", "lam_f", "lam_g"],
                      ["hess_gamma_x_x"])
    fun.callback = cb  # the Callback must outlive every call
    return fun
