"""Closed-form problems for the tree of branches (``branch.tree``): E(u; p) on R^2, its exact
gradient, Hessian and eigenpairs, behind ``branch.problem.TreeProblem`` with an in-memory store.

* ``pitchfork``: E = x^4/4 - p x^2/2 + (y - 1)^2/2: branch point at p = 0 (x = 0), branches
  x = +-sqrt(p) (images of each other under x -> -x);
* ``fold``: E = x^3/3 - p x + (y - 1)^2/2: x^2 = p, a fold at p = 0 (x = 0), x > 0 stable;
* ``ring``: E = x^4/4 + (p^2 - 1) x^2/2 + (y - 1)^2/2: branch points at p = -1 and p = +1 joined by
  the circle x^2 + p^2 = 1 (x > 0 and x < 0 halves images of each other).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from vesicle_opt.branch import arclength as arc
from vesicle_opt.branch import deflation
from vesicle_opt.branch.events import Point
from vesicle_opt.branch.problem import TreeProblem
from vesicle_opt.branch.store import Store

PROBLEMS = {
    "pitchfork": (lambda x, p: x**4 / 4 - p * x**2 / 2, lambda x, p: x**3 - p * x, lambda x, p: 3 * x**2 - p,
                  lambda x, p: -x),
    "fold": (lambda x, p: x**3 / 3 - p * x, lambda x, p: x**2 - p, lambda x, p: 2 * x, lambda x, p: -1.0),
    "ring": (lambda x, p: x**4 / 4 + (p**2 - 1) * x**2 / 2, lambda x, p: x**3 + (p**2 - 1) * x,
             lambda x, p: 3 * x**2 + p**2 - 1, lambda x, p: 2 * p * x),
}


class Toy(TreeProblem):
    def __init__(self, name, start, to, step, x0, symmetric=True, max_points=200, out=None, shift=0.0):
        # shift: the problem in p - shift (a second parameter moving the diagram, ``branch.lines``)
        self.E, self.Fx, self.Hx, self.Fp = ((lambda f: (lambda x, p: f(x, p - shift)))(f) for f in PROBLEMS[name])
        self.store = Store(out, {"toy": name, "to": to, "step": step}, snapshots=False)
        # a stand-in for a mesh discretisation as io.fields writes it: phi's two entries at two nodes
        self.disc = SimpleNamespace(grid_shape=None, box=[[0.0, 1.0]], nodes=[[0.0], [1.0]], dim=1)
        self.s = arc.Settings(step=step, to=to, max_points=max_points)
        self.weights, self.start, self.param, self.x0 = np.ones(2), start, "p", x0
        self.symmetric = symmetric
        self.solves = 0

    # the numerics --------------------------------------------------------------------------
    def energy(self, u, p):
        return self.E(u[0], p) + (u[1] - 1) ** 2 / 2

    def grad(self, u, p):
        return np.array([self.Fx(u[0], p), u[1] - 1.0])

    def hess(self, u, p):
        return np.diag([self.Hx(u[0], p), 1.0])

    def result(self, u, p, converged, iterations):
        h = np.linalg.eigh(self.hess(u, p))
        return SimpleNamespace(phi=u, energy=self.energy(u, p), converged=converged, iterations=iterations, disc=self.disc,
                               extra={"second_order_eigenvalues": tuple(h[0]), "second_order_errors": (0.0, 0.0)},
                               history={"second_order_mode": h[1][:, 0]}, vectors=h[1])

    def newton(self, u, p, t=None, theta=1.0, pred=None):
        """Newton at fixed p, or with p free on the hyperplane theta^2 <u - u_pred, t_u> + (p - p_pred) t_p = 0."""
        u = np.array(u, float)
        self.solves += 1
        for k in range(1, 60):
            if t is None:
                if np.abs(self.grad(u, p)).max() < 1e-15:  # a root already (also where H is singular)
                    return u, p, True, k - 1
                try:
                    du = -np.linalg.solve(self.hess(u, p), self.grad(u, p))
                except np.linalg.LinAlgError:
                    return u, p, False, k
                dp = 0.0
            else:
                (u0, p0), (tu, tp) = pred, t
                J = np.zeros((3, 3))
                J[:2, :2], J[0, 2], J[2, :2], J[2, 2] = self.hess(u, p), self.Fp(u[0], p), theta**2 * tu, tp
                r = np.concatenate([self.grad(u, p), [theta**2 * (u - u0) @ tu + (p - p0) * tp]])
                try:
                    d = -np.linalg.solve(J, r)
                except np.linalg.LinAlgError:
                    return u, p, False, k
                du, dp = d[:2], d[2]
            if not np.all(np.isfinite(du)) or np.abs(du).max() > 1e3:
                return u, p, False, k
            u, p = u + du, p + dp
            if np.abs(du).max() < 1e-13 and abs(dp) < 1e-13:
                return u, p, True, k
        return u, p, False, 60

    def correct(self, k):
        def c(p, u0):
            u, p, ok, it = self.newton(self.x0 if u0 is None else u0, p)
            return arc.Attempt(p, u, ok, it, self.result(u, p, ok, it))
        return c

    def free_attempt(self, k):
        def f(u_pred, p_pred, t_u, t_p, theta):
            u, p, ok, it = self.newton(u_pred, p_pred, (t_u, t_p), theta, (u_pred, p_pred))
            return arc.Attempt(p, u, ok, it, self.result(u, p, ok, it))
        return f

    def row(self, k, st):
        a = st.attempt
        res = a.payload
        row = {"branch": k, "param": "p", "target": a.p, "accepted": st.accepted, "converged": a.converged,
               "iterations": a.iterations, "solves": st.solves, "corrector": st.corrector,
               "arc_step": st.arc_step, "arc_theta": st.theta, "energy": res.energy,
               "second_order_min_eigenvalue": res.extra["second_order_eigenvalues"][0]}
        return row, res

    def point_row(self, k, point, corrector):
        st = arc.Step(arc.Attempt(point.p, point.phi, True, 0, point.payload), True, corrector, 1,
                      abs(self.s.step), None)
        return self.row(k, st)

    def _point(self, u, p, ok, it):
        if not ok:
            return None
        res = self.result(u, p, ok, it)
        return Point(p, u, res.energy, res.extra["second_order_eigenvalues"], (0.0, 0.0), None, res)

    def solve(self, p, u0, lam0=None):
        return self._point(*self.newton(u0, p))

    @property
    def free(self):
        def f(u_pred, p_pred, t_u, t_p, theta):
            u, p, ok, it = self.newton(u_pred, p_pred, (t_u, t_p), theta, (u_pred, p_pred))
            return self._point(u, p, ok, it)
        return f

    def mode(self, point, m):
        return np.linalg.eigh(self.hess(point.phi, point.p))[1][:, m]

    def align(self, u, ref):
        if not self.symmetric:
            return u
        v = u * np.array([-1.0, 1.0])
        return v if np.sum((v - ref) ** 2) < np.sum((u - ref) ** 2) else u

    def deflate(self, p, u0, known):
        u, ok, _ = deflation.newton(lambda u: self.grad(u, p), lambda u: self.hess(u, p), u0 + 0.5, known,
                                    self.weights)
        return self._point(u, p, ok, 0)
