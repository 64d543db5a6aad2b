"""Progress output: nothing unless switched on; plain lines (no carriage return) off a terminal."""

import io

from vesicle_opt.io import progress


def test_off_by_default_and_plain_off_a_terminal():
    assert not progress.enabled()
    assert isinstance(progress.bar("x", total=3), progress.NullBar)
    buf = io.StringIO()
    b = progress.bar("cases", total=4, unit="cases", stream=buf, interval=0.0, force=True)
    for _ in range(2):
        b.update(1)
    b.set_postfix_str("last c2")
    b.close()
    lines = buf.getvalue().splitlines()
    assert "\r" not in buf.getvalue() and len(lines) == 3
    assert lines[0].startswith("cases: 1/4 cases (25%)") and "ETA" in lines[0]
    assert lines[-1].startswith("cases: 2/4 cases (50%)") and lines[-1].endswith("last c2")


def test_eta_is_the_mean_rate_extrapolated():
    assert progress.eta_text(1, 4, 10.0) == "ETA 30 s"
    assert progress.eta_text(0, 4, 10.0) == "" and progress.eta_text(1, None, 1.0) == ""
    assert progress.eta_text(1, 100, 10.0) == "ETA 16.5 min"
