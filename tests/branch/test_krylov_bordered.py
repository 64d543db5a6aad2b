"""``branch.krylov_bordered`` without vesicles: the bordered GMRES solve against dense LU, the
bordering preconditioner exact where P = H (one iteration), and Newton with p free passing the
closed-form fold x^2 = p of E = x^3/3 - p x + (y - 1)^2/2 (``tests/branch/toy.py``'s ``fold``)."""

import numpy as np

from vesicle_opt.branch import arclength as arc
from vesicle_opt.branch import krylov_bordered as kb


def _bordered(seed, n=60, k=3):
    rng = np.random.default_rng(seed)
    Q = rng.standard_normal((n, n))
    H = Q @ Q.T / n + np.diag(np.linspace(-0.5, 3.0, n))  # indefinite: a saddle's Hessian
    cols = [rng.standard_normal(n) for _ in range(k)]
    rows = [rng.standard_normal(n) for _ in range(k)]
    D = rng.standard_normal((k, k))
    J = np.block([[H, np.column_stack(cols)], [np.vstack(rows), D]])
    return H, cols, rows, D, J, rng


def test_bordered_gmres_matches_dense_lu():
    """An indefinite, nonsymmetric bordered matrix with the SPD diagonal model as P: GMRES to 1e-12
    reproduces LU's solution to 1e-9 (cond(J) = 3e2: measured 1.3e-12)."""
    H, cols, rows, D, J, rng = _bordered(0)
    b = rng.standard_normal(J.shape[0])
    d = np.abs(np.diag(H)) + 1.0
    x, y, its, ok = kb.bordered_solve(lambda v: H @ v, lambda r: r / d, cols, rows, D, b[:60], b[60:], 1e-12)
    ref = np.linalg.solve(J, b)
    assert ok and its <= 63  # at most n + k steps in exact arithmetic (measured 43)
    assert np.linalg.norm(np.concatenate([x, y]) - ref) <= 1e-9 * np.linalg.norm(ref)


def test_a_zero_column_costs_no_preconditioner_application():
    """r_p = 0 (a walk in a constraint's target): the same solution as LU's, and P^{-1} never applied
    to the zero column (it is linear: that column's P^{-1} b is zero), the nonzero ones once each."""
    H, cols, rows, D, J, rng = _bordered(2)
    cols[1] = np.zeros(60)
    J[:60, 61] = 0.0
    b = rng.standard_normal(63)
    d = np.abs(np.diag(H)) + 1.0
    seen = []

    def pinv(r):
        seen.append(r)
        return r / d
    x, y, its, ok = kb.bordered_solve(lambda v: H @ v, pinv, cols, rows, D, b[:60], b[60:], 1e-12)
    assert ok and np.linalg.norm(np.concatenate([x, y]) - np.linalg.solve(J, b)) <= 1e-9 * np.linalg.norm(b)
    assert [sum(r is c for r in seen) for c in cols] == [1, 0, 1]


def test_bordering_preconditioner_is_exact_where_p_is_h():
    """With P = H the Schur-complement preconditioner is J^{-1}: one GMRES iteration."""
    H, cols, rows, D, J, rng = _bordered(1)
    H = H + 2.0 * np.eye(60)  # invertible
    J[:60, :60] = H
    Hinv = np.linalg.inv(H)
    b = rng.standard_normal(63)
    x, y, its, ok = kb.bordered_solve(lambda v: H @ v, lambda r: Hinv @ r, cols, rows, D, b[:60], b[60:], 1e-10)
    assert ok and its == 1
    assert np.linalg.norm(J @ np.concatenate([x, y]) - b) <= 1e-10 * np.linalg.norm(b)  # round-off of a 63-dim solve


class FoldModel:
    """r = (x^2 - p, y - 1): KKT of E = x^3/3 - p x + (y - 1)^2/2, no constraints; H = diag(2x, 1),
    P = diag(|2x| + 1, 1) (an SPD model that is wrong at the fold, where H is singular)."""

    def at(self, u, lam, p):
        x, y = u
        r = np.array([x * x - p, y - 1.0])
        H = np.diag([2 * x, 1.0])
        d = np.array([abs(2 * x) + 1.0, 1.0])
        return kb.Linearization(r=r, c=np.zeros(0), hvp=lambda v: H @ v, pinv=lambda q: q / d, G=[],
                                r_p=np.array([-1.0, 0.0]), c_p=np.zeros(0),
                                error=lambda r_, c_: float(np.max(np.abs(r_))))


def test_newton_with_p_free_passes_the_closed_form_fold():
    """From x = 1 at p = 1 towards p = -1: the branch x = sqrt(p) turns at p = 0 (x = 0) and comes
    back on x = -sqrt(p). Fixed-p Newton (t_phi = 0, t_p = 1) before the fold, p free near it."""
    model, w = FoldModel(), np.ones(2)

    def correct(p, u):
        u = np.array([1.0, 1.0]) if u is None else u
        f = kb.newton(model, u, (), p, np.zeros(2), 1.0, 0.0, w, 1e-13)
        return arc.Attempt(f.p, f.phi, f.converged, f.iterations)

    def free(u_pred, p_pred, t_u, t_p, theta):
        f = kb.newton(model, u_pred, (), p_pred, t_u, t_p, theta, w, 1e-13)
        return arc.Attempt(f.p, f.phi, f.converged, f.iterations)

    s = arc.Settings(step=-0.2, to=-1.0, max_points=25)
    records = []
    arc.walk(s, 1.0, correct, w, record=records.append, free=free)
    pts = np.array([(st.attempt.p, *st.attempt.phi) for st in records if st.accepted])
    p, x, y = pts.T
    assert np.max(np.abs(x * x - p)) < 1e-12 and np.max(np.abs(y - 1)) < 1e-12  # Newton to 1e-13 in r
    assert x.min() < -0.5 and x.max() > 0.9  # both sheets: the fold was passed
    k = int(np.argmin(p))  # the turn: p decreases to it, then increases
    assert np.all(np.diff(p[: k + 1]) < 0) and np.all(np.diff(p[k:]) > 0)
    assert -1e-12 < p[k] < 1e-2  # the walk's closest point to the fold (measured 4.6e-4; ds ~ 0.08 there)
    assert any(st.corrector == "arclength" and st.accepted for st in records)


def test_forcing_is_eisenstat_walker_capped_and_never_oversolves():
    """eta = min(ETA_MAX, max(sqrt(err), OVERSOLVE tol / err)): the cap far from the root, sqrt(err)
    near it, and at an error just above tol only the reduction that ends Newton (x OVERSOLVE)."""
    assert kb.forcing(0.5, 1e-9) == kb.ETA_MAX
    assert kb.forcing(1e-6, 1e-12) == np.sqrt(1e-6)
    assert kb.forcing(8e-10, 5e-10) == min(kb.ETA_MAX, kb.OVERSOLVE * 5e-10 / 8e-10)  # not sqrt: 2.8e-5


class CubicModel:
    """r = A u + u^3 - b on n unknowns (A SPD tridiagonal, b fixed), no constraints, p fixed: Newton's
    H = A + 3 diag(u^2), and the model P = diag(A) + 3 diag(u^2) (GMRES needs many iterations)."""

    def __init__(self, n=300):
        self.A = np.diag(np.full(n, 4.0)) - np.diag(np.full(n - 1, 1.9), 1) - np.diag(np.full(n - 1, 1.9), -1)
        self.b = np.sin(np.linspace(0.0, 7.0, n)) * 3.0

    def at(self, u, lam, p):
        H = self.A + np.diag(3 * u * u)
        d = np.diag(H).copy()
        r = self.A @ u + u**3 - self.b
        return kb.Linearization(r=r, c=np.zeros(0), hvp=lambda v: H @ v, pinv=lambda q: q / d, G=[],
                                r_p=None, c_p=np.zeros(0),
                                error=lambda r_, c_: float(np.linalg.norm(r_) / np.linalg.norm(self.b)))


def test_newton_without_oversolving_takes_fewer_gmres_iterations_to_the_same_root(monkeypatch):
    """Fixed-p Newton on the cubic model to tol 1e-10: the forcing floor (OVERSOLVE tol / err) cuts
    the GMRES iterations of the last step against the pure sqrt(err) rule, and both end within tol of
    the same root (the residual's relative norm below tol at both ends)."""
    model, n = CubicModel(), 300
    u0, tol = np.zeros(n), 1e-10

    def run():
        return kb.newton(model, u0, (), 0.0, np.zeros(n), 1.0, 0.0, np.ones(n), tol)
    new = run()
    monkeypatch.setattr(kb, "OVERSOLVE", 0.0)
    old = run()
    assert new.converged and old.converged
    # measured: 53 against 56 GMRES iterations in 7 Newton steps each (the last step 10 against 13)
    assert sum(new.krylov) < sum(old.krylov), (new.krylov, old.krylov)
    r = model.at(new.phi, (), 0.0).r
    assert np.linalg.norm(r) <= tol * np.linalg.norm(model.b)
    # both within the error bound of the root: |u_new - u_old| <= |H^-1| (|r_new| + |r_old|), |H^-1| <= 1/(4 - 3.8)
    assert np.linalg.norm(new.phi - old.phi) <= 2 * tol * np.linalg.norm(model.b) / 0.2


class ProfileModel:
    """r = atanh(u) - c on n unknowns, no constraints, p fixed: H = diag(1 / (1 - u^2)), P = H (GMRES
    exact in one iteration). In the profile's coordinate T = atanh the residual is linear, so a
    Newton step taken there (``advance``: ``model.profile.step``) lands on the root u = tanh(c)."""

    def __init__(self, c, advance=None):
        self.c = np.asarray(c, float)
        if advance is not None:
            self.advance = advance

    def at(self, u, lam, p):
        d = 1.0 / (1.0 - u * u)
        return kb.Linearization(r=np.arctanh(u) - self.c, c=np.zeros(0), hvp=lambda v: d * v,
                                pinv=lambda q: q / d, G=[], r_p=None, c_p=np.zeros(0),
                                error=lambda r_, c_: float(np.max(np.abs(r_))))


def test_newton_takes_its_step_through_the_models_advance():
    """From u = tanh(c - 0.4) (T below the cap 0.5 from the root in every component): with the
    profile's step one Newton step reaches the root to round-off; the plain step phi + dphi needs
    several (the same root)."""
    from vesicle_opt.model import profile

    rng = np.random.default_rng(5)
    c = rng.uniform(-2.5, 2.5, 40)
    u0 = np.tanh(c - 0.4)
    n = c.size

    def run(model):
        return kb.newton(model, u0, (), 0.0, np.zeros(n), 1.0, 0.0, np.ones(n), 1e-12)
    along, plain = run(ProfileModel(c, profile.step)), run(ProfileModel(c))
    assert along.converged and along.iterations == 1
    assert np.max(np.abs(along.phi - np.tanh(c))) < 1e-14  # tanh(atanh) round-off
    assert plain.converged and plain.iterations >= 3  # quadratic from T-error 0.4, near |u| = 1 slowly (measured 6)
    assert np.max(np.abs(plain.phi - np.tanh(c))) < 1e-12
