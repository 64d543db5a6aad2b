"""The stomatocyte branch reached WITHOUT a seed: by switching at the oblate branch's branch point
(sharp interface, ``sharp.stomatocyte``'s shapes and KKT system).

Along the up-down symmetric (oblate) branch the Hessian of the Lagrangian reduced to the tangent space
of the constraints (v, closure) splits into even and odd modes (psi - s's wavenumbers 2j and 2j - 1);
the least eigenvalue of the odd part, ``odd_eigenvalue``, changes sign where a branch of asymmetric
shapes leaves the oblate (a pitchfork: the shapes +-w are images under z -> -z). ``branch_point``
brackets that change on a scan in v and bisects it (secant on the eigenvalue); ``switch`` steps off
the oblate along the critical odd eigenvector w by the amplitude s, solving G = 0 with the extra
equation w . (a - a_b) = s (``stomatocyte.arclength_step`` with the tangent (w, 0, 0)), and continues
the new branch in v (``continue_branch``) until its fold, which the seeded branch of
``stomatocyte.reference`` also reaches: the same branch, found from the oblate alone.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from vesicle_opt.sharp import stomatocyte as st


def _reduced(sys: st.KKTSystem, p: st.Point) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues and eigenvectors (in a-space) of the Hessian of the Lagrangian on the constraints'
    tangent space at p."""
    J, _ = sys.jacobian(p.a, p.lam)
    n = sys.n
    C = -J[:n, n:n + 2]
    Z = np.linalg.svd(C.T)[2][2:].T  # an orthonormal basis of {d: C^T d = 0}
    w, y = np.linalg.eigh(Z.T @ J[:n, :n] @ Z)
    return w, Z @ y


def odd_eigenvalue(sys: st.KKTSystem, p: st.Point) -> tuple[float, np.ndarray]:
    """The least eigenvalue whose eigenvector lies in the odd wavenumbers (>= 99 % of its norm), and
    that eigenvector (unit norm)."""
    w, vecs = _reduced(sys, p)
    for k in np.argsort(w):
        e = vecs[:, k]
        if np.sum(e[0::2] ** 2) >= 0.99 * np.sum(e**2):
            return float(w[k]), e / np.linalg.norm(e)
    raise ValueError("no odd eigenvector: the point is not up-down symmetric")


def branch_point(vs, c0: float = 0.0, n_modes: int = 24, tol: float = 1e-7) -> dict:
    """The oblate's branch point to up-down asymmetric shapes: the odd eigenvalue scanned at ``vs``
    (descending, oblates by Newton warm-started along the scan), its sign change bisected by the
    secant to |v step| < ``tol``. Returns {"v", "f", "point" (the oblate there), "mode", "scan":
    [(v, odd eigenvalue), ...]}; ValueError without a sign change."""
    sys = st.KKTSystem(n_modes, c0)
    scan, prev, start = [], None, None
    for v in vs:
        o = st.oblate_point(float(v), c0, n_modes, start)
        start = o.a
        mu, _ = odd_eigenvalue(sys, o)
        scan.append((float(v), mu))
        if prev is not None and prev[1] * mu <= 0:
            break
        prev = (float(v), mu, o)
    else:
        raise ValueError(f"the oblate's odd eigenvalue keeps its sign on {list(vs)}: {scan}")
    (v0, m0, o0), (v1, m1), o1 = prev, scan[-1], o
    for _ in range(60):
        v2 = v1 - m1 * (v1 - v0) / (m1 - m0)
        o2 = st.newton(o1.a, v2, c0, n_modes)
        m2, _ = odd_eigenvalue(sys, o2)
        done = abs(v2 - v1) < tol
        v0, m0, v1, m1, o1 = v1, m1, v2, m2, o2
        if done:
            break
    _, mode = odd_eigenvalue(sys, o1)
    return {"v": v1, "f": o1.f, "point": o1, "mode": mode, "scan": scan}


def switch(bp: dict, c0: float = 0.0, amplitude: float = 0.05) -> st.Point:
    """The point of the asymmetric branch at amplitude ``amplitude`` along the critical odd mode from
    the branch point ``bp`` (module docstring), with its branch tangent."""
    p = bp["point"]
    n = len(p.a)
    sys = st.KKTSystem(n, c0)
    t = np.concatenate([bp["mode"], [0.0, 0.0, 0.0]])
    q = st.arclength_step(sys, dataclasses.replace(p, t=t), amplitude)
    return q


def stomatocyte_by_switching(vs=(0.6, 0.55, 0.5, 0.45, 0.4), c0: float = 0.0, n_modes: int = 24,
                             ds: float = 0.05, steps: int = 80) -> dict:
    """The branch point, the switched point, and the new branch continued up in v to its fold:
    {"branch_point": (v, f), "fold": (v, f), "points": [(v, f, asymmetry), ...], "scan": ...}."""
    bp = branch_point(vs, c0, n_modes)
    q = switch(bp, c0)
    pts = st.continue_branch(q, c0, ds, steps, 1.0, stop=lambda r: r.t[-1] < 0 and r.v < 0.655)
    fold = st.fold(pts, c0)
    return {"branch_point": (bp["v"], bp["f"]), "fold": (fold.v, fold.f),
            "points": [(r.v, r.f, r.asymmetry) for r in pts], "scan": bp["scan"]}
