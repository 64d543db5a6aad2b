"""A bare hand-written CasADi MX model of the FD ellipse problem, the speed baseline of the core.

No vesicle_opt abstractions: grid, 5-point Laplacian, E (6), A (7), B (8) written inline, as a user
would type them from the paper, and handed to IPOPT with its default options and the same tol.
Used by ``bench_equilibrium.py`` to show the toolkit's abstractions cost nothing measurable.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np
import scipy.sparse as sp


def bare_solve(n: int, tol: float = 1e-8, L: float = 4.0, eps: float = 0.2) -> dict:
    h = 2 * L / n
    x1 = -L + h * np.arange(n)
    X, Y = np.meshgrid(x1, x1, indexing="ij")
    e = np.ones(n)
    D = sp.diags([e[:-1], -2 * e, e[:-1]], [-1, 0, 1], shape=(n, n), format="lil")
    D[0, -1] = D[-1, 0] = 1
    D = sp.csr_matrix(D) / h**2
    I = sp.identity(n)
    Lap = (sp.kron(D, I) + sp.kron(I, D)).tocsc()
    def tanh_ellipse(a, b):
        f = (X / a) ** 2 + (Y / b) ** 2 - 1
        g = np.hypot(2 * X / a**2, 2 * Y / b**2)
        return np.tanh(-(f / np.maximum(g, 1e-12)) / (np.sqrt(2) * eps)).ravel()
    w = h * h
    def AB(p):
        return w * p.sum(), eps / 2 * w * (-p @ (Lap @ p)) + w * ((p**2 - 1) ** 2).sum() / (4 * eps)
    alpha, beta = AB(tanh_ellipse(2.0, 1.0))
    phi = ca.MX.sym("phi", n * n)
    r = eps * ca.mtimes(ca.DM(Lap), phi) + phi / eps * (1 - phi**2)
    E = w * ca.sumsqr(r) / (2 * eps)
    A = w * ca.sum1(phi)
    B = -eps / 2 * w * ca.dot(phi, ca.mtimes(ca.DM(Lap), phi)) + w * ca.sum1((phi**2 - 1) ** 2) / (4 * eps)
    solver = ca.nlpsol("bare", "ipopt", {"x": phi, "f": E, "g": ca.vertcat(A - alpha, B - beta)},
                       {"ipopt.tol": tol, "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"})
    t0 = time.perf_counter()
    sol = solver(x0=tanh_ellipse(1.6, 1.25), lbg=0, ubg=0)
    wall = time.perf_counter() - t0
    st = solver.stats()
    return {"energy": float(sol["f"]), "iterations": st["iter_count"], "wall_time_s": wall,
            "status": st["return_status"]}


if __name__ == "__main__":
    import sys
    print(bare_solve(int(sys.argv[1]) if len(sys.argv) > 1 else 128))
