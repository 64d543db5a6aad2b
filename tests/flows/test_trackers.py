"""The in-memory flow ``vesicle_opt.flow`` and its trackers (py-pde style): no directory needed,
stop criteria, checkpoint + resume bit-for-bit, progress on a given stream, ``throw=True``."""

from __future__ import annotations

import dataclasses
import io

import numpy as np
import pytest

import vesicle_opt as vo
from vesicle_opt.flows.api import build_model, initial_field, make_scheme, stepper_options
from vesicle_opt.flows.stepper import run
from vesicle_opt.flows.trackers import (CallbackTracker, CheckpointTracker, HistoryTracker, ProgressTracker,
                                        StopTracker)

# Round-off yardstick of the laws on these grids (same as tests/flows/test_schemes.py: measured 1e-15..3e-13)
LAW_TOL = 1e-11


def _scene(*sets):
    return vo.load_scene("ellipse-2d", ["mesh.n=16", "solver.M=100", 'flow.scheme="penalty"', "flow.dt=1e-3",
                                        "flow.t_end=5e-3", "flow.steady_tol=0", *sets])


def test_flow_in_memory_writes_nothing(tmp_path, monkeypatch, capsys):
    """Five steps of (18) on 16^2 FD: no file anywhere, nothing printed, the history in memory, and the
    same field as the stepper driven by hand with the scene's options."""
    monkeypatch.chdir(tmp_path)
    sc = _scene()
    hist = HistoryTracker()
    res = vo.flow(sc, trackers=[hist])
    assert list(tmp_path.iterdir()) == [] and capsys.readouterr() == ("", "")
    assert res.status is vo.Status.T_END and res.steps == 5 and res.rejections == 0
    assert res.t == pytest.approx(5e-3, rel=1e-12, abs=0)  # five additions of 1e-3: round-off only
    assert res.history == tuple(hist.rows) and [r["step"] for r in res.history] == [1, 2, 3, 4, 5]
    assert all(abs(r["energy_law_residual"]) <= LAW_TOL for r in res.history)
    E = [r["penalized_energy"] for r in res.history]
    assert all(b < a for a, b in zip(E, E[1:]))  # (22) implies strict decrease
    assert res.energy == res.observed["energy"] == res.history[-1]["energy"]
    assert res.scheme == "penalty" and res.law == "(22)" and res.model.disc.n_nodes == 256
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.steps = 0
    md = build_model(sc)
    by_hand = run(make_scheme(sc, md), initial_field(sc, md), stepper_options(sc))
    assert np.array_equal(by_hand.phi, res.phi)
    assert vo.flow(sc).history == ()  # rows are kept only by a HistoryTracker


def test_stop_tracker_stops_with_status_stopped():
    sc = _scene("flow.t_end=1.0")
    res = vo.flow(sc, trackers=[StopTracker(lambda row: row["step"] >= 3)])
    assert res.status is vo.Status.STOPPED and res.status == "stopped" and res.steps == 3
    three = vo.flow(_scene("flow.t_end=1.0", "flow.steps=3"))
    assert three.status is vo.Status.MAX_STEPS and np.array_equal(three.phi, res.phi)
    # a plain callable fn(state, row) is a tracker too; every tracker sees the stopping step
    seen = HistoryTracker()
    res = vo.flow(sc, trackers=[lambda state, row: state.step == 2, seen])
    assert res.status == "stopped" and res.steps == 2 and len(seen.rows) == 2


def test_checkpoint_resume_bit_for_bit(tmp_path):
    """Adaptive k (the checkpoint carries k_try, k_last, the previous field for the Newton guess):
    killed after step 5 (last checkpoint at step 3), resumed from the file to step 8, equals the
    uninterrupted 8-step run bit for bit; so does resuming from the in-memory final state."""
    sc = _scene('flow.stepping="adaptive"', "flow.dt=1e-4", "flow.t_end=1.0", "flow.steps=8")
    full = vo.flow(sc, trackers=[HistoryTracker()])
    assert full.steps == 8 and len({r["dt"] for r in full.history}) > 1  # k really adapted

    def kill(state, row):
        if state.step == 5:
            raise KeyboardInterrupt

    ckpt = tmp_path / "checkpoint.npz"
    with pytest.raises(KeyboardInterrupt):
        vo.flow(sc, trackers=[CheckpointTracker(ckpt, every=3), kill])
    assert CheckpointTracker.load(ckpt).step == 3  # finish() is not called when an exception escapes
    rest = vo.flow(sc, resume_from=ckpt, trackers=[CheckpointTracker(ckpt, every=3)])
    assert rest.resumed_from_step == 3 and rest.steps == 8 and rest.status is vo.Status.MAX_STEPS
    assert np.array_equal(full.phi, rest.phi) and rest.t == full.t
    assert CheckpointTracker.load(ckpt).step == 8  # and at the end
    part = vo.flow(_scene('flow.stepping="adaptive"', "flow.dt=1e-4", "flow.t_end=1.0", "flow.steps=4"))
    more = vo.flow(sc, resume_from=part.state)
    assert more.resumed_from_step == 4 and np.array_equal(full.phi, more.phi)


def test_progress_tracker_writes_to_the_given_stream(capsys):
    buf = io.StringIO()
    vo.flow(_scene("flow.t_end=3e-3"), trackers=[ProgressTracker(buf, interval=0.0, t_end=3e-3)])
    text = buf.getvalue()
    assert [f"step {j}" in text for j in (1, 2, 3)] == [True] * 3 and "t = 0.003/0.003" in text
    assert text.endswith("\n") and capsys.readouterr() == ("", "")  # the stepper itself prints nothing


def test_throw_raises_on_a_failed_run():
    """k = 1 is rejected from the raw shape at M = 1e4 (test_rejection_on_oversized_step); with
    dt_min = 0.1 above the first acceptable k the run fails on its first step."""
    sc = _scene("solver.M=1e4", 'flow.initial="shape"', "flow.dt=1.0", "flow.t_end=2.0", "flow.steps=3",
                "flow.dt_min=0.1")
    res = vo.flow(sc)
    assert res.failed and res.status is vo.Status.FAILED and res.steps == 0 and res.rejections >= 1
    assert np.array_equal(res.phi, initial_field(sc, res.model))  # the last accepted field
    with pytest.raises(vo.SolverError, match="flow failed") as exc:
        vo.flow(sc, throw=True)
    assert exc.value.result.status is vo.Status.FAILED
    assert vo.flow(_scene(), throw=True).status is vo.Status.T_END  # a good run does not raise


def test_bad_inputs_are_one_line_input_errors(tmp_path):
    sc = _scene()
    for kwargs, key in (({"x0": np.zeros(7)}, "x0"), ({"resume_from": tmp_path / "missing.npz"}, "resume_from"),
                        ({"trackers": [42]}, "trackers")):
        with pytest.raises(vo.InputError, match=key) as info:
            vo.flow(sc, **kwargs)
        assert "\n" not in str(info.value)  # one line


def test_phi0_is_a_deprecated_alias_of_x0():
    sc = _scene()
    start = vo.flow(sc).phi
    with pytest.warns(DeprecationWarning, match="x0"):
        old = vo.flow(sc, phi0=start)
    np.testing.assert_array_equal(old.phi, vo.flow(sc, x0=start).phi)  # the same run, bit for bit
    with pytest.raises(vo.InputError, match="x0"):
        vo.flow(sc, x0=start, phi0=start)


def test_a_checkpoint_is_not_resumed_under_another_problem(tmp_path):
    """The flow writes its problem's fingerprint into the checkpoint; another scene (or scheme) is refused."""
    ckpt = tmp_path / "checkpoint.npz"
    vo.flow(_scene("flow.t_end=2e-3"), trackers=[CheckpointTracker(ckpt)])
    other = vo.load_scene("circle-2d", ["mesh.n=16", "solver.M=100", 'flow.scheme="lagrange"', "flow.dt=1e-3",
                                        "flow.steady_tol=0"])
    with pytest.raises(vo.InputError, match="resume_from"):
        vo.flow(other, resume_from=ckpt)
    with pytest.raises(vo.InputError, match="resume_from"):
        vo.flow(_scene("flow.t_end=2e-3", "solver.M=1000"), resume_from=ckpt)  # the model changed
    again = vo.flow(_scene("flow.t_end=4e-3"), resume_from=ckpt)  # the same problem, a later t_end: fine
    assert again.resumed_from_step == 2 and again.steps == 4


def test_history_tracker_csv_and_callback(tmp_path):
    """A CSV flushed row by row with the given columns, prior rows first; CallbackTracker sees the state."""
    path = tmp_path / "h.csv"
    fields = []
    hist = HistoryTracker(path, columns=["step", "t", "energy"], keep=False, prior=[{"step": 0, "t": 0.0}])
    vo.flow(_scene("flow.t_end=2e-3"),
            trackers=[hist, CallbackTracker(lambda state, row: fields.append(state.phi.copy()))])
    lines = path.read_text().splitlines()
    assert lines[0] == "step,t,energy" and lines[1] == "0,0.0," and len(lines) == 4
    assert hist.rows == [] and len(fields) == 2 and not np.array_equal(fields[0], fields[1])


def test_write_flow_is_the_in_memory_flow_plus_directory_trackers(tmp_path):
    """The CLI writer keeps its files and summary keys (adds ``outcome``) and ends on the same field."""
    from vesicle_opt.flows.run import write_flow
    sc = _scene("flow.t_end=3e-3", "flow.frames=3")
    run_dir = write_flow(sc, tmp_path, frames=False)
    keys = {"scene", "scheme", "law", "status", "message", "steps", "t", "rejections", "wall_time_s",
            "resumed_from_step", "n_nodes", "gamma", "M", "alpha", "beta", "energy", "penalized_energy",
            "volume_residual", "area_residual"}
    assert keys <= set(run_dir.summary) and run_dir.summary["outcome"] == run_dir.summary["status"] == "t_end"
    names = {p.name for p in tmp_path.iterdir()}
    assert {"history.csv", "checkpoint.npz", "checkpoint.id", "phi.npz", "phi.vtu", "phi.png", "summary.json",
            "snapshots", "frames"} <= names
    assert sorted(p.name for p in (tmp_path / "snapshots").iterdir()) == [f"phi_{j:03d}.npz" for j in range(4)]
    assert np.array_equal(run_dir.result.phi, vo.flow(sc).phi)
