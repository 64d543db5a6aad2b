"""``io.interrupt`` (a signal: one exception, recorded for C code that swallows it, deferred over a
commit) and ``io.staging`` (a run's files moved in whole; a failed run never replaces a good one)."""

import json
import os
import signal

import pytest

from vesicle_opt.errors import OutputError
from vesicle_opt.io import interrupt, staging


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_raises_interrupted_with_the_conventional_exit_code(sig, code):
    with interrupt.handled():
        with pytest.raises(interrupt.Interrupted) as info:
            os.kill(os.getpid(), sig)
            signal.sigtimedwait([], 0)  # a bytecode boundary for the handler (it runs between them)
        assert info.value.exit_code == code and isinstance(info.value, KeyboardInterrupt)
        # the record stays: a C extension that swallowed the exception is caught up with by check()
        with pytest.raises(interrupt.Interrupted):
            interrupt.check()
    assert signal.getsignal(sig) is not interrupt._handler  # restored after the block


def _c_call_interrupted(sig, error):
    """What a C extension's call does when the handler raises inside it (CasADi, seen in CI runs): the
    handler's exception comes back chained under the extension's own error."""
    try:
        os.kill(os.getpid(), sig)
        signal.sigtimedwait([], 0)
    except KeyboardInterrupt as exc:
        raise error from exc


@pytest.mark.parametrize("error", [
    SystemError("<function DM.__array__> returned a result with an exception set"),
    RuntimeError("Error in Function::call for 'equilibrium' [IpoptInterface]: KeyboardInterrupt")])
def test_a_signal_that_a_c_call_turned_into_its_own_error_is_still_the_interrupt(error):
    with pytest.raises(interrupt.Interrupted) as info:
        with interrupt.handled():
            _c_call_interrupted(signal.SIGINT, error)
    assert info.value.exit_code == 130 and info.value.__cause__ is error
    with pytest.raises(type(error)):  # without a signal the error is an error, passed on as it is
        with interrupt.handled():
            raise type(error)("a C extension's own failure")


def test_a_signal_inside_deferred_is_raised_at_its_end():
    done = []
    with interrupt.handled():
        with pytest.raises(interrupt.Interrupted):
            with interrupt.deferred():
                os.kill(os.getpid(), signal.SIGTERM)
                signal.sigtimedwait([], 0)
                done.append("the block ran to its end")
    assert done == ["the block ran to its end"]


def test_the_message_says_where_and_whether_a_rerun_resumes():
    with interrupt.handled():
        interrupt.note("at step 12 (t = 0.012)", resume=True)
        assert interrupt.message(signal.SIGINT) == ("interrupted (SIGINT) at step 12 (t = 0.012); "
                                                    "rerun the same command to resume")
        interrupt.note("during the solve", resume=False)
        assert "left as they were" in interrupt.message(signal.SIGTERM)


def _run(out, text, converged=True):
    (out / "summary.json").write_text(json.dumps({"converged": converged, "text": text}))
    (out / "sub").mkdir(exist_ok=True)
    (out / "sub" / "f.txt").write_text(text)


def test_commit_moves_files_and_swaps_directories_whole(tmp_path):
    _run(tmp_path, "old")
    (tmp_path / "sub" / "stale.txt").write_text("of the old run")
    st = staging.Staging(tmp_path)
    _run(st.fresh(), "new")
    assert json.loads((tmp_path / "summary.json").read_text())["text"] == "old"  # not before the commit
    assert st.finish(ok=True) == tmp_path
    assert json.loads((tmp_path / "summary.json").read_text())["text"] == "new"
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["f.txt"]  # the old directory went whole
    assert not st.dir.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["sub", "summary.json"]


@pytest.mark.parametrize("old_converged, moved", [(True, False), (False, True), (None, True)])
def test_a_failed_run_replaces_only_a_run_that_was_not_good(tmp_path, old_converged, moved):
    if old_converged is not None:
        _run(tmp_path, "old", old_converged)
    st = staging.Staging(tmp_path)
    _run(st.fresh(), "new", converged=False)
    where = st.finish(ok=False)
    assert (where == tmp_path) == moved
    assert json.loads((where / "summary.json").read_text())["text"] == "new"
    if not moved:
        assert json.loads((tmp_path / "summary.json").read_text())["text"] == "old"


def test_a_disk_failure_while_writing_is_rescued_to_a_temporary_directory(tmp_path):
    _run(tmp_path, "old")
    calls = []

    def write(d):
        calls.append(d)
        if len(calls) == 1:  # the first attempt, into --out's staging directory: the disk is full
            raise OSError(28, "No space left on device", str(d / "phi.npz"))
        (d / "phi.npz").write_text("the result")
        return {}
    with pytest.raises(OutputError) as info:
        staging.write_run(tmp_path, write, lambda s: True, "tiny")
    msg = str(info.value)
    spare = calls[1]
    assert "No space left on device" in msg and str(spare) in msg and "\n" not in msg
    assert (spare / "phi.npz").read_text() == "the result" and info.value.exit_code == 1
    assert json.loads((tmp_path / "summary.json").read_text())["text"] == "old"  # --out untouched
    assert not (tmp_path / staging.PARTIAL).exists()
    (spare / "phi.npz").unlink()
    spare.rmdir()


def test_the_record_ends_with_the_block():
    """An API solve after an interrupted ``cli.main`` in the same process is not taken for interrupted."""
    with pytest.raises(interrupt.Interrupted):
        with interrupt.handled():
            os.kill(os.getpid(), signal.SIGINT)
            signal.sigtimedwait([], 0)
    assert interrupt.received() is None
    interrupt.check()  # no exception
