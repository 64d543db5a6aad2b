"""The continuation core on curves with a closed form (no vesicle): a fold is passed, the walk's
state is a function of its records (resume), failures halve the step and are recorded."""

import math

import numpy as np
import pytest

from vesicle_opt.branch import arclength as arc

WEIGHTS = np.ones(2)


def circle_corrector(calls=None):
    """Points of x^2 + p^2 = 1 at fixed p by Newton from the start (x = (x, 0)): a fold at p = 1."""
    def correct(p, phi):
        if calls is not None:
            calls.append(p)
        x = 1.0 if phi is None else float(phi[0])
        if abs(p) >= 1:
            return arc.Attempt(p, np.array([x, 0.0]), False, 0)
        for k in range(1, 60):
            dx = (x * x + p * p - 1) / (2 * x) if x != 0 else math.inf
            x -= dx
            if not math.isfinite(x):
                return arc.Attempt(p, np.array([0.0, 0.0]), False, k)
            if abs(dx) < 1e-14:
                return arc.Attempt(p, np.array([x, 0.0]), True, k)
        return arc.Attempt(p, np.array([x, 0.0]), False, 60)
    return correct


def test_the_walk_approaches_a_fold_and_stops_honestly():
    """A fixed-p corrector cannot pass the fold (arclength docstring): the pseudo-arclength
    iteration takes the walk close to it, every failure is a record, and the walk says why it
    stopped. (The fold at p = 1 is where x = 0.)"""
    s = arc.Settings(step=0.1, to=2.0, max_points=40)
    records = []
    track, why = arc.walk(s, 0.6, circle_corrector(), WEIGHTS, record=records.append)
    pts = [(st.attempt.p, st.attempt.phi[0]) for st in records if st.accepted]
    p = np.array([q for q, _ in pts])
    x = np.array([y for _, y in pts])
    assert np.max(np.abs(x * x + p * p - 1)) < 1e-12  # every accepted point on the curve (Newton to 1e-14)
    assert np.all(np.diff(p) > 0)  # the parameter only rises on this sheet
    # near the fold: within 1e-3 in p (measured 8e-6 with these settings)
    assert 1 - p.max() < 1e-3, p.max()
    assert any(st.corrector == "arclength" for st in records if st.accepted)
    assert any(not st.accepted for st in records)  # the trials beyond the fold are recorded
    assert why in ("step below minimum", "max_points"), why


def test_resume_from_records_gives_the_same_walk():
    s = arc.Settings(step=0.1, to=2.0, max_points=30)
    full = []
    arc.walk(s, 0.6, circle_corrector(), WEIGHTS, record=full.append)
    part = []
    arc.walk(arc.Settings(step=0.1, to=2.0, max_points=12), 0.6, circle_corrector(), WEIGHTS, record=part.append)
    recs = [{"p": st.attempt.p, "phi": st.attempt.phi if st.accepted else None, "accepted": st.accepted,
             "arc_step": st.arc_step, "theta": st.theta} for st in part]
    rest = []
    arc.walk(s, 0.6, circle_corrector(), WEIGHTS, arc.replay(s.step, recs), record=rest.append)
    both = part + rest
    assert len(both) == len(full)
    for a, b in zip(both, full):  # bitwise: the resumed walk is the same computation
        assert a.attempt.p == b.attempt.p and a.accepted == b.accepted and a.arc_step == b.arc_step
        assert np.array_equal(a.attempt.phi, b.attempt.phi)


def test_a_failed_corrector_halves_the_step_and_is_recorded():
    calls = []
    inner = circle_corrector(calls)
    fail_at = {2}

    def correct(p, phi):
        a = inner(p, phi)
        if len(calls) - 1 in fail_at:  # the third call fails once
            return arc.Attempt(p, a.phi, False, 7)
        return a
    records = []
    arc.walk(arc.Settings(step=0.1, to=0.6, max_points=30), 0.3, correct, WEIGHTS, record=records.append)
    failed = [k for k, st in enumerate(records) if not st.accepted]
    assert failed == [2]
    assert records[2].arc_step == records[1].arc_step / 2  # halved exactly
    assert records[-1].attempt.p == 0.6 and records[-1].accepted  # the end is hit exactly


def circle_free_corrector():
    """The point of x^2 + p^2 = 1 on the predictor's hyperplane, p free: Newton on the 2x2 bordered
    system [x^2 + p^2 - 1, theta^2 (x - x_pred) t_x + (p - p_pred) t_p] (the vesicle's is
    ``branch.bordered``)."""
    def free(phi_pred, p_pred, t_phi, t_p, theta):
        x, p = float(phi_pred[0]), float(p_pred)
        for k in range(1, 40):
            F = np.array([x * x + p * p - 1, theta**2 * (x - phi_pred[0]) * t_phi[0] + (p - p_pred) * t_p])
            J = np.array([[2 * x, 2 * p], [theta**2 * t_phi[0], t_p]])
            dx, dp = np.linalg.solve(J, -F)
            x, p = x + dx, p + dp
            if abs(dx) + abs(dp) < 1e-14:
                return arc.Attempt(p, np.array([x, 0.0]), True, k)
        return arc.Attempt(p, np.array([x, 0.0]), False, 40)
    return free


def test_a_corrector_with_p_free_passes_the_fold():
    """With p free near the fold the walk goes through it: p rises to the fold (p = 1) and falls
    on the other sheet (x < 0), every accepted point on the curve; it stops when p turns back
    past the start."""
    s = arc.Settings(step=0.1, to=2.0, max_points=60)
    records = []
    track, why = arc.walk(s, 0.6, circle_corrector(), WEIGHTS, record=records.append,
                          free=circle_free_corrector())
    acc = [st for st in records if st.accepted]
    p = np.array([st.attempt.p for st in acc])
    x = np.array([st.attempt.phi[0] for st in acc])
    assert np.max(np.abs(x * x + p * p - 1)) < 1e-12  # on the curve (Newton to 1e-14)
    top = int(np.argmax(p))
    assert 0 < top < len(p) - 1 and 1 - p[top] < 0.05, p  # a turning point inside the walk, near p = 1
    assert np.all(np.diff(p[: top + 1]) > 0) and np.all(np.diff(p[top:]) < 0), p  # up, then down
    assert x[0] > 0 and x[-1] < 0  # the other sheet
    assert any(st.corrector == "arclength" for st in acc)
    assert why == "left the range (turned back past the start)", why


def circle_tangent(p, phi):
    """dx/dp on x^2 + p^2 = 1: -p / x (the closed form)."""
    return np.array([-p / phi[0], 0.0])


def test_a_tangent_first_step_starts_next_to_a_fold_and_passes_it():
    """From p0 = 0.95 (x0 = 0.312, the fold at p = 1) a natural first step of 0.06 lies past the fold
    and fails; along the start's tangent with p free (``_first_tangent``) it is accepted at once, and
    the walk passes the fold (turn = 2: p free at every step after the first, as on Newton-Krylov). A
    resumed walk is the same computation (the first step's theta recorded)."""
    s = arc.Settings(step=0.06, to=2.0, max_points=30, turn=2.0)
    natural = []
    arc.walk(s, 0.95, circle_corrector(), WEIGHTS, record=natural.append, free=circle_free_corrector())
    assert natural[1].corrector == "natural" and not natural[1].accepted
    recs = []
    _, why = arc.walk(s, 0.95, circle_corrector(), WEIGHTS, record=recs.append, free=circle_free_corrector(),
                      tangent=circle_tangent)
    assert recs[1].accepted and recs[1].corrector == "arclength"
    acc = [st for st in recs if st.accepted]
    p = np.array([st.attempt.p for st in acc])
    x = np.array([st.attempt.phi[0] for st in acc])
    assert np.max(np.abs(x * x + p * p - 1)) < 1e-12  # on the curve (Newton to 1e-14)
    top = int(np.argmax(p))
    assert 0 < top < len(p) - 1 and x[0] > 0 and x[-1] < 0  # p rose, turned, fell: the other sheet
    assert why == "left the range (turned back past the start)", why
    part = []
    arc.walk(arc.Settings(step=0.06, to=2.0, max_points=4, turn=2.0), 0.95, circle_corrector(), WEIGHTS, record=part.append,
             free=circle_free_corrector(), tangent=circle_tangent)
    rec = [{"p": st.attempt.p, "phi": st.attempt.phi if st.accepted else None, "accepted": st.accepted,
            "arc_step": st.arc_step, "theta": st.theta} for st in part]
    rest = []
    arc.walk(s, 0.95, circle_corrector(), WEIGHTS, arc.replay(s.step, rec), record=rest.append,
             free=circle_free_corrector(), tangent=circle_tangent)
    assert len(part + rest) == len(recs)
    for a, b in zip(part + rest, recs):  # bitwise
        assert a.attempt.p == b.attempt.p and a.accepted == b.accepted and np.array_equal(a.attempt.phi, b.attempt.phi)


def test_the_step_reads_the_control_count_not_a_fixed_extra_count():
    """A corrector that spends a fixed count besides its Newton steps (IPOPT's certifying solve after
    the bordered Newton point, ``VesicleProblem.free_corrector``: 3-4 iterations warm) reports the sum in
    ``iterations`` and the step-dependent count in ``control``, which the step control reads. Here p is
    free at every point (turn 2) and 3 is added to Newton's 4 steps: read as 7 (> the target 6) the
    step shrinks at every point (0.071 -> 0.033 in ten), read as 4 it stays at its cap sqrt(2) |step|;
    both walks pass the fold (measured 76 and 33 points)."""
    def padded(control: bool):
        inner = circle_free_corrector()

        def free(*a):
            at = inner(*a)
            return arc.Attempt(at.p, at.phi, at.converged, at.iterations + 3, at.payload,
                               control=at.iterations if control else None)
        return free

    runs = {}
    for control in (False, True):
        records = []
        _, why = arc.walk(arc.Settings(step=0.05, to=2.0, max_points=200, turn=2.0), 0.6, circle_corrector(),
                          WEIGHTS, record=records.append, free=padded(control))
        acc = [st for st in records if st.accepted]
        p = np.array([st.attempt.p for st in acc])
        x = np.array([st.attempt.phi[0] for st in acc])
        assert np.max(np.abs(x * x + p * p - 1)) < 1e-12 and x[-1] < 0  # on the curve, the fold passed
        assert why == "left the range (turned back past the start)", why
        runs[control] = (len(acc), [st.arc_step for st in records[2:12]])
    cap = math.sqrt(2) * 0.05
    assert all(b < a for a, b in zip(runs[False][1], runs[False][1][1:]))  # the sum: every step shorter
    assert all(ds == cap for ds in runs[True][1])  # the control count: at the cap
    assert runs[True][0] < runs[False][0] / 2, runs  # the walk in half the points or fewer


def test_the_predict_hook_starts_the_free_corrector_at_its_field_on_the_linear_hyperplane():
    """``Settings.predict(phi_a, phi_b, k)`` gives the p-free corrector's start (``start=``) with k =
    ds / |secant|: the linear secant b + k (b - a) is then exactly the linear prediction (k's
    definition), and a walk with it accepts the same points as one without (to round-off: the step
    control reads the nearer of the start and the prediction, here round-off apart)."""
    starts, preds = [], []
    inner = circle_free_corrector()

    def free(phi_pred, p_pred, t_phi, t_p, theta, start=None):
        starts.append(start)
        preds.append(np.array(phi_pred))
        return inner(phi_pred, p_pred, t_phi, t_p, theta)

    def linear(a, b, k):
        return b + k * (b - a)
    runs = []
    for predict, f in ((None, circle_free_corrector()), (linear, free)):
        records = []
        arc.walk(arc.Settings(step=0.1, to=2.0, max_points=40, predict=predict), 0.6, circle_corrector(), WEIGHTS,
                 record=records.append, free=f)
        runs.append([(st.attempt.p, st.attempt.phi[0]) for st in records if st.accepted])
    assert starts and all(s is not None for s in starts)
    # the hook's linear secant is the prediction to round-off
    assert max(float(np.max(np.abs(s - p))) for s, p in zip(starts, preds)) < 1e-14
    assert len(runs[0]) == len(runs[1]) and np.allclose(runs[0], runs[1], rtol=0.0, atol=1e-12)


def test_the_step_control_reads_the_deviation_from_the_nearer_start():
    """``_free`` with a start from ``Settings.predict``: the step control reads the deviation of the
    corrector's point from the nearer of the start and the linear prediction (the start the corrector
    may have used), the jump test and the record the linear prediction's. The point here is 0.3 ds
    from the prediction (above the target 0.08): without a start, or with one farther off, the step
    shrinks by sqrt(0.08 / 0.3); from a start at the point itself only the iteration count reads
    (4 against the target 6: it grows by sqrt(6 / 4)); a point past ``max_deviation`` is refused
    whatever the start."""
    s = arc.Settings(step=0.1, to=2.0)
    track = arc.Track(points=((0.5, np.array([0.0, 0.0])), (0.6, np.array([0.1, 0.0]))), ds=0.1, theta=1.0,
                      accepted=2, started=True)
    phi_pred, p_pred, ds = np.array([0.2, 0.0]), 0.7, 0.1

    def run(point, start):
        def free(phi_pred, p_pred, t_phi, t_p, theta, start=None):
            return point
        return arc._free(track, s, free, WEIGHTS, 1.0, ds, np.array([1.0, 0.0]), 0.0, phi_pred, p_pred, start)
    near = arc.Attempt(0.7, np.array([0.23, 0.0]), True, 4)
    steps = {}
    for name, start in (("none", None), ("far", np.array([0.5, 0.0])), ("at the point", near.phi.copy())):
        new, (rec,) = run(near, start)
        assert rec.accepted and rec.deviation == pytest.approx(0.3)  # the record: the linear prediction's
        steps[name] = new.ds
    assert steps["none"] == pytest.approx(0.1 * math.sqrt(0.08 / 0.3)) and steps["far"] == steps["none"]
    assert steps["at the point"] == pytest.approx(0.1 * math.sqrt(6 / 4))
    jump = arc.Attempt(0.7, np.array([0.45, 0.0]), True, 4)  # 2.5 ds off the prediction
    new, (rec,) = run(jump, jump.phi.copy())
    assert not rec.accepted and new.ds == ds / 2
