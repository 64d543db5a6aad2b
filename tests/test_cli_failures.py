"""Failures explained where they happen: a branch whose start fails says its outcome and why, and
does not claim "all certified"; a library's warning is not printed as the tool's own."""

import warnings

from vesicle_opt import cli


def test_branch_with_no_certified_point_says_why(tmp_path, capfd):
    code = cli.main(["branch", "ellipse-2d", "--param", "reduced_volume", "--to", "0.8", "--out", str(tmp_path),
                     "--set", "mesh.n=32", "--set", "solver.max_iter=1", "--set", "solver.second_order=false"])
    out, err = capfd.readouterr()
    assert code == 1
    # before: "0 points, stopped {0: 'start failed'}, all certified=True" and matplotlib's legend warning
    assert "all certified" not in out and "no certified point; last failure: max_iterations" in out
    assert "outcome=max_iterations (solver status" in err
    assert "No artists with labels" not in err
    assert "reason" in (tmp_path / "branch.csv").read_text().splitlines()[0]


def test_library_warnings_keep_their_origin(capsys):
    code = None
    def verb(args):
        warnings.warn_explicit("No artists with labels found", UserWarning,
                               "/x/site-packages/matplotlib/legend.py", 1)
        return 0
    from vesicle_opt.cli import app  # main's own module (cli reads its names from it)
    parser = app.build_parser
    try:
        app.build_parser = lambda: _Fake(verb)
        code = cli.main(["solve", "x"])
    finally:
        app.build_parser = parser
    err = capsys.readouterr().err
    assert code == 0 and "matplotlib: UserWarning: No artists" in err and "vesicle-opt: warning" not in err


class _Fake:
    def __init__(self, fn):
        self.fn = fn

    def parse_args(self, argv):
        import argparse
        return argparse.Namespace(func=self.fn, verbose=0, quiet=False)


def test_a_failed_study_row_says_its_outcome_and_certifiable_tol(caplog):
    """A study row of a round-off floor: the runner's console line and the CSV columns."""
    from vesicle_opt.studies.runner import failed_line
    row = {"scene": "ellipse-2d", "method": "penalty", "n": 128, "converged": "False",
           "outcome": "roundoff_floor", "reason": "round-off floor: stationarity is known only to ~1.2e-07",
           "certifiable_tol": 2e-7}
    line = failed_line("penalty_continuation", "c1", row)
    assert line.startswith("penalty_continuation c1 scene=ellipse-2d method=penalty n=128: roundoff_floor (")
    assert line.endswith("tol >= 2e-07 can be certified")
    assert failed_line("s", "c", {**row, "converged": "True", "outcome": "converged"}) is None
    assert failed_line("s", "c", {"status": "error: ValueError: x"}) == "s c: error: ValueError: x"
