"""``branch.nk_free``: the p-free Newton-Krylov corrector gives the IPOPT corrector's points at a 2D
fold (the same predictions, both certified at their own p), and follows the circle's index-2
saddle branch past nu = 0.657, where the fixed-p Newton-Krylov solve (a minimiser) stopped."""

import numpy as np
import pytest

from vesicle_opt.branch import arclength as arc
from vesicle_opt.branch import branch
from vesicle_opt.branch import vesicle as ves
from vesicle_opt.branch.params import parameter
from vesicle_opt.branch.store import Store
from vesicle_opt.scene.schema import from_dict


def ellipse_c0(backend, c0=0.70, n=48):
    """The nu = 0.8 ellipse of ``test_run.test_a_turning_point_in_c0_is_reported_once_as_a_fold``
    (FD 48^2, eps 0.4: the branch turns at c0 = 0.734765), started at c0."""
    raw = {"domain": {"box": [[-4.0, 4.0], [-4.0, 4.0]], "boundary": "periodic"},
           "mesh": {"kind": "fd", "n": n}, "model": {"epsilon": 0.4, "c0": c0},
           "constraints": {"reduced_volume": 0.8, "area": 8.0},
           "initial": {"shape": "ellipse", "semi_axes": [1.6, 0.9]},
           "solver": {"method": "exact", "tol": 1e-8, "second_order": True, "max_iter": 200,
                      "shape_check": False, "backend": backend}}
    return from_dict(raw, f"ellipse-c0-{backend}")


def test_the_nk_fold_corrector_passes_the_fold_on_the_ipopt_correctors_points(monkeypatch):
    """The Newton-Krylov walk from c0 = 0.70 passes the fold (FD 48^2: the FFT-FD operators of the NK
    path equal IPOPT's sparse FD to round-off) and locates it where the IPOPT walk did; the three
    p-free predictions nearest the turn (phi_pred, p_pred, tangent, theta) are handed to the IPOPT
    path's p-free corrector (``branch.bordered``, sparse LU, then IPOPT at its p): the two certified
    points agree in p, energy and phi to the certificate's tolerance."""
    calls = []
    real = ves.VesicleProblem.nk_newton_point

    def recording(self, branch_, phi0, p0, lam, t_phi, t_p, theta, t0, start=None):
        a = real(self, branch_, phi0, p0, lam, t_phi, t_p, theta, t0, start)
        if t_p != 1.0 or theta != 0.0:  # a p-free call (not the fixed-p fallback)
            calls.append((np.array(phi0), p0, np.array(t_phi), t_p, theta, a))
        return a
    monkeypatch.setattr(ves.VesicleProblem, "nk_newton_point", recording)
    b = branch(ellipse_c0("newton-krylov"), "c0", to=0.9, step=0.02, max_points=14, switch=False)
    pts = b.points()
    p = np.array([r["target"] for r in pts])
    assert all(r["converged"] for r in pts)
    k = int(np.argmax(p))
    # passed: the parameter rose to the turn and fell back by far more than the zigzag at its top
    # (~5e-6: the IPOPT walk's and this one's points there; measured fall 4.2e-4 here)
    assert 0 < k < len(p) - 1 and p[-1] < p[k] - 1e-4, p
    folds = [r for r in b.located(0) if r["event"] == "fold"]
    # IPOPT's walk located it at 0.734765 (``test_run``; chord and parabola agree to 1.1e-6), within
    # the zigzag (measured here 0.7347630 - 0.7347690 over runs with other first steps)
    assert len(folds) == 1 and abs(folds[0]["target"] - 0.734765) < 1e-5, folds
    for r in pts[2:]:  # the p-free points: a few bordered Newton steps of a few GMRES iterations
        steps = [int(m) for m in r["krylov_iterations"].split(";")]
        # measured 4-10 steps of 3-25 iterations (a failure is MAX_NEWTON = 25 steps or MAX_KRYLOV = 400)
        assert len(steps) <= 12 and max(steps) <= 40, steps
    sc_ip = ellipse_c0("ipopt")
    problem = ves.VesicleProblem(sc_ip, parameter(sc_ip, "c0"), arc.Settings(step=0.02, to=0.9),
                                 Store(None, {}, False), None, None, None, None)
    free, w = problem.free_corrector(None), problem.weights
    for phi_pred, p_pred, t_phi, t_p, theta, a in sorted(calls, key=lambda c: abs(c[3]))[:3]:
        ip = free(phi_pred, p_pred, t_phi, t_p, theta)
        assert a.converged and ip.converged
        # both certified to tol 1e-8 on the same equations and hyperplane (measured over the walk:
        # |dp| <= 1.5e-9, relative |dE| <= 8.3e-9, |dphi|_w <= 6.1e-11 |phi|_w)
        assert abs(ip.p - a.p) < 1e-8, (ip.p, a.p)
        e_nk, e_ip = a.payload[0].energy, ip.payload[0].energy
        assert abs(e_nk - e_ip) < 5e-8 * abs(e_ip), (e_nk, e_ip)  # dE/dc0 ~ -2, E ~ 0.41: 5e-8 per 1e-8 in p
        assert np.sqrt(w @ (a.phi - ip.phi) ** 2) < 1e-8 * np.sqrt(w @ ip.phi**2)


def circle_spectral(n=48):
    raw = {"domain": {"box": [[-4.0, 4.0], [-4.0, 4.0]], "boundary": "periodic"},
           "mesh": {"kind": "spectral", "n": n}, "model": {"epsilon": 0.4},
           "constraints": {"reduced_volume": 0.95, "area": 8.0},
           "initial": {"shape": "circle", "radius": 1.27},
           "solver": {"method": "exact", "tol": 1e-8, "second_order": True, "max_iter": 200,
                      "backend": "newton-krylov", "shape_check": False}}
    return from_dict(raw, "circle-saddle")


def test_the_nk_saddle_branch_of_the_circle_passes_nu_0_657():
    """The circle start converges to the four-fold symmetric saddle (index 2); with the fixed-p
    Newton-Krylov corrector (a minimiser) the branch stopped at nu = 0.657 (max_iter, step below
    minimum). The p-free corrector (the default on Newton-Krylov) walks it to 0.6: every point
    certified, index 2, each by 3-5 bordered Newton steps."""
    b = branch(circle_spectral(), "reduced_volume", to=0.6, step=-0.025, switch=False)
    pts = b.points()
    assert b.stopped == {0: "reached"} and all(r["converged"] for r in pts)
    assert [r["index"] for r in pts] == [2] * len(pts)
    assert min(r["target"] for r in pts) == 0.6
    free = [r for r in pts if r["corrector"] == "arclength"]
    assert len(free) >= len(pts) - 3  # every point after the first step (and the final one)
    for r in free:
        steps = r["krylov_iterations"].split(";")
        assert 2 <= len(steps) <= 5 and r["iterations"] == len(steps)  # the fixed-p certification: 0 steps
    energies = np.array([r["energy"] for r in pts])
    assert np.all(np.diff(energies) > 0)  # E rises as nu falls at fixed perimeter (dE/dnu = lambda_A dalpha < 0)


def test_the_branch_verb_on_newton_krylov_writes_the_gmres_counts(tmp_path, capsys):
    """``vesicle-opt branch`` with solver.backend = newton-krylov runs the p-free corrector (no new
    flag): its rows are ``arclength`` from the first step to the final one, and every point after the
    start (those at fixed p too: Newton with p held) has the GMRES count of each bordered Newton step
    in ``krylov_iterations`` (as many as its Newton ``iterations``)."""
    import csv

    from vesicle_opt import cli
    raw = {"domain": {"box": [[-4.0, 4.0], [-4.0, 4.0]], "boundary": "periodic"},
           "mesh": {"kind": "spectral", "n": 48}, "model": {"epsilon": 0.4},
           "constraints": {"reduced_volume": 0.95, "area": 8.0},
           "initial": {"shape": "circle", "radius": 1.27},
           "solver": {"method": "exact", "tol": 1e-8, "second_order": True, "max_iter": 200,
                      "backend": "newton-krylov", "shape_check": False}}
    toml = tmp_path / "circle.toml"
    toml.write_text("".join(f"[{sec}]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in body.items())
                            for sec, body in raw.items()))
    out = tmp_path / "out"
    code = cli.main(["branch", str(toml), "--param", "reduced_volume", "--to", "0.875", "--step", "-0.025",
                     "--no-switch", "--out", str(out)])
    capsys.readouterr()
    assert code == 0
    with open(out / "branch.csv") as fh:
        rows = list(csv.DictReader(fh))
    kinds = [r["corrector"] for r in rows]  # the final step to --to is at fixed p (Newton with p held);
    # the first along the start's tangent with p free (``arclength._first_tangent``)
    assert kinds[0] == "start" and set(kinds[1:-1]) == {"arclength"} and len(rows) >= 4
    for r in rows[1:]:
        counts = r["krylov_iterations"].split(";")
        assert r["converged"] == "true" and len(counts) == int(r["iterations"]) and all(int(c) > 0 for c in counts)


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    return repr(v).replace("(", "[").replace(")", "]")


@pytest.mark.slow
def test_a_3d_mirror_grid_branch_passes_its_turning_point():
    """The prolate at v = 0.8 on the octant mirror grid (eps 0.2, 50 x 20 x 20, Newton-Krylov) in c0
    from -1.8 towards -3 (measured: 34 points, 100-130 s at load ~10). Near c0 = -1.99 the stable
    prolate sheet (index 0, its least eigenvalue dipping to 0.002 and rising again: a fine walk goes
    on past -2.3) comes within ~0.01 of a second sheet, onto which this walk (step 0.05) crosses; that
    sheet turns at a fold, located on the chord with p free at c0 = -1.982793 (its second eigenvalue
    zero to its bound), and the walk comes back on its index-1 part past the start. The shape check is
    off: at |C| = 2.8 and eps = 0.2 the outer bulk carries 5 % of the volume (``wrong_shape``), a
    phase-field effect of this coarse eps, not the continuation's."""
    from vesicle_opt.studies import crossing_3d as cx
    box, n = cx.octant_box(tuple(1.3 * h for h in cx.HALF_EXTENT["prolate"]), 0.2)
    raw = {"domain": {"box": box, "boundary": "natural"}, "mesh": {"kind": "spectral", "n": n},
           "model": {"epsilon": 0.2, "c0": -1.8}, "constraints": {"reduced_volume": 0.8, "area": cx.AREA},
           "initial": {"shape": "ellipsoid", "semi_axes": [1.6, 0.75, 0.75], "center": [0.0, 0.0, 0.0]},
           "solver": {"method": "exact", "tol": 1e-8, "backend": "newton-krylov", "max_iter": 500,
                      "second_order": True, "shape_check": False}}
    b = branch(from_dict(raw, "prolate-octant-c0"), "c0", to=-3.0, step=-0.05, max_points=45, switch=False)
    pts = b.points()
    p = np.array([r["target"] for r in pts])
    assert all(r["converged"] for r in pts) and b.stopped[0].startswith("left the range")
    assert pts[0]["index"] == 0 and pts[-1]["index"] == 1 and p[-1] > -1.8  # turned and came back past the start
    folds = [r for r in b.located(0) if r["event"] == "fold"]
    assert len(folds) == 1 and folds[0]["located_by"] == "chord"
    # this walk and a walk on the second sheet alone (step 0.01, started from this one's index-1 point
    # at -1.9395) located it at -1.9827927 and -1.9827930
    assert abs(folds[0]["target"] + 1.982793) < 1e-5, folds[0]["target"]
    assert abs(folds[0]["critical_eigenvalue"]) <= folds[0]["critical_error"]  # measured 2.5e-5 <= 9.1e-5


def test_the_start_tangent_is_the_derivative_of_the_branch():
    """``nk_free.tangent`` (one bordered GMRES solve at the start) against central differences of
    Newton-Krylov points at c0 -/+ delta on the FD 48^2 ellipse (c0 = 0.70, the fold at 0.734765; in c0
    the stationarity's own p-derivative r_p enters): an independent derivative of the same branch. The
    difference falls as delta^2 (the central difference's order) down to 4e-5: the tangent is the
    derivative, not a nearby vector (whose difference would level off)."""
    from vesicle_opt.branch.nk_free import free_newton, tangent
    sc = ellipse_c0("newton-krylov")
    problem = ves.VesicleProblem(sc, parameter(sc, "c0"), arc.Settings(step=0.02, to=0.9),
                                 Store(None, {}, False), None, None, None, None)
    p0 = parameter(sc, "c0").start
    a = problem.correct(0)(p0, None)
    assert a.converged
    res = a.payload[0]
    lam = (res.lambda_volume, res.lambda_area)
    d = tangent(problem.kkt(), a.phi, lam, p0)
    assert d is not None
    w = problem.weights
    deltas, rels = (2e-3, 1e-3, 5e-4), []
    for delta in deltas:
        side = []
        for p in (p0 - delta, p0 + delta):
            nw = free_newton(problem.kkt(), a.phi + (p - p0) * d, lam, p, np.zeros_like(d), 1.0, 0.0, 1e-8)
            assert nw.converged
            side.append(nw.phi)
        fd = (side[1] - side[0]) / (2 * delta)
        rels.append(np.sqrt(w @ (d - fd) ** 2) / np.sqrt(w @ fd**2))
    order = np.polyfit(np.log(deltas), np.log(rels), 1)[0]
    # measured 6.9e-4, 1.7e-4, 4.4e-5: order 1.99; the solves' own error (5e-10 relative / delta <= 1e-6)
    # is far below, so the order is the central difference's 2, held to +-0.3
    assert abs(order - 2) < 0.3, (order, rels)
    assert rels[-1] < 1e-4, rels


def test_the_gauss_newton_factorization_is_reused_while_the_field_moves_little():
    """``VesicleKKT.pinv`` on a 2D sparse mesh (the LU path): the Gauss-Newton model's solve is kept
    while eps |g' - g'_factored| <= LAG_G and -lambda_B moves less than LAG_CB, refactored beyond;
    either way it solves the model at the field it was factored at (to round-off: LU)."""
    from vesicle_opt import load_scene
    from vesicle_opt.branch.bordered import Affine
    from vesicle_opt.branch.nk_free import LAG_G, VesicleKKT
    from vesicle_opt.nk.setup import prepare
    sc = load_scene("ellipse-2d", ["mesh.kind='fem-p1'", "mesh.n=24", "mesh.mass='lumped'", "domain.boundary='natural'"])
    setup = prepare(sc, tensor_fft=False)
    assert setup[2].kind == "lu"
    kkt = VesicleKKT(setup, sc, Affine((1.0, 0.0), (1.0, 0.0), (0.0, 0.0)))
    x, y = np.asarray(setup[0].nodes, float).T
    phi = np.tanh((1.0 - np.hypot(x / 1.2, y / 0.8)) / (np.sqrt(2) * sc.model.epsilon))
    pf = kkt.pf(0.0)
    first = kkt.pinv(pf.state(phi), (0.0, -0.5))
    near = phi + 0.2 * LAG_G / 6 * np.sign(phi)  # eps dg' = -6 phi dphi: within LAG_G / 5
    assert kkt.pinv(pf.state(near), (0.0, -0.52)) is first
    assert kkt.pinv(pf.state(near), (0.0, -0.6)) is not first  # -lambda_B 20 % away
    far = phi + 0.2 * np.sign(phi)  # eps dg' up to 1.2 > LAG_G
    again = kkt.pinv(pf.state(far), (0.0, -0.6))
    assert again is not kkt.pinv(pf.state(phi), (0.0, -0.6))
    r = np.random.default_rng(0).standard_normal(phi.size)
    P = setup[2].gauss_newton_matrix(pf.state(far).s, kkt.rig, 0.6)
    assert np.linalg.norm(P @ again(r) - r) <= 1e-10 * np.linalg.norm(r)  # LU: round-off times cond(P)
