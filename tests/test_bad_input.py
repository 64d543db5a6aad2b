"""Every bad input of the issue list through the CLI: exit 2, one line naming the key, no
traceback, and nothing already in the output directory lost."""

import pytest

from vesicle_opt import cli

from _scenes import PROBLEMS

SOLVE = ["solve", str(PROBLEMS / "ellipse-2d.toml"), "--set", "mesh.n=16"]


def _corrupt(tmp_path, name, content=b"\x00garbage"):
    path = tmp_path / name
    path.write_bytes(content)
    return str(path)


CASES = [
    # (id, argv builder, key named in the message)
    ("unknown key", lambda t: SOLVE + ["--set", "model.epsilonn=0.1"], "model.epsilonn"),
    ("missing key", lambda t: ["solve", _corrupt(t, "s.toml", b"[domain]\nbox=[[0,1],[0,1]]\n")], "mesh.n"),
    ("wrong type", lambda t: SOLVE + ["--set", "mesh.n='many'"], "mesh.n"),
    ("eps <= 0", lambda t: SOLVE + ["--set", "model.epsilon=0"], "model.epsilon"),
    ("rigidity <= 0", lambda t: SOLVE + ["--set", "model.rigidity=-1"], "model.rigidity"),
    ("n < 4", lambda t: SOLVE + ["--set", "mesh.n=3"], "mesh.n"),
    ("inverted box", lambda t: SOLVE + ["--set", "domain.box=[[4, -4], [-4, 4]]"], "domain.box"),
    ("degenerate box", lambda t: SOLVE + ["--set", "domain.box=[[1, 1], [-4, 4]]"], "domain.box"),
    ("alpha outside", lambda t: SOLVE + ["--set", "constraints.alpha=100.0", "--set", "constraints.beta=9.0"],
     "constraints.alpha"),
    ("beta <= 0", lambda t: SOLVE + ["--set", "constraints.alpha=-50.0", "--set", "constraints.beta=0"],
     "constraints.beta"),
    ("infeasible by (9)", lambda t: SOLVE + ["--set", "constraints.alpha=-50.0", "--set", "constraints.beta=5.0"],
     "constraints.beta"),
    ("M <= 0", lambda t: SOLVE + ["--set", "solver.M=0"], "solver.M"),
    ("tol <= 0", lambda t: SOLVE + ["--set", "solver.tol=-1e-8"], "solver.tol"),
    ("dt <= 0", lambda t: ["flow", str(PROBLEMS / "ellipse-2d.toml"), "--set", "mesh.n=16", "--dt", "0",
                           "--out", str(t / "out")], "dt"),
    ("missing mesh file", lambda t: SOLVE + ["--set", "mesh.kind='fem-p1'", "--set", "domain.boundary='natural'",
                                             "--set", f"mesh.file='{t / 'absent.msh'}'"], "mesh.file"),
    ("corrupt mesh file", lambda t: SOLVE + ["--set", "mesh.kind='fem-p1'", "--set", "domain.boundary='natural'",
                                             "--set", f"mesh.file='{_corrupt(t, 'm.vtk')}'"], "mesh.file"),
    ("corrupt warm start", lambda t: SOLVE + ["--set", "initial.shape='file'",
                                              "--set", f"initial.file='{_corrupt(t, 'phi.npz')}'"], "initial.file"),
    ("unknown method", lambda t: SOLVE + ["--set", "solver.method='newton'"], "solver.method"),
    ("unknown scheme", lambda t: ["flow", str(PROBLEMS / "ellipse-2d.toml"), "--scheme", "rk4"], "scheme"),
    ("unknown --set key", lambda t: SOLVE + ["--set", "solver.nothing=1"], "solver.nothing"),
]


@pytest.mark.parametrize("build, key", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_exit_2_one_line(tmp_path, capsys, build, key):
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text("{\"kept\": true}\n")  # an earlier result must survive
    argv = build(tmp_path)
    if argv[0] == "solve":
        argv = argv + ["--out", str(out)]
    rc = _run(argv)
    err = capsys.readouterr().err.strip()
    lines = [line for line in err.splitlines() if not line.startswith("vesicle-opt: warning")]
    assert rc == 2 and len(lines) == 1, err
    assert key in lines[0] and "Traceback" not in err
    assert (out / "summary.json").read_text() == "{\"kept\": true}\n"


def _run(argv) -> int:
    """The CLI's exit code, whether returned or raised by argparse (choices are checked there)."""
    try:
        return cli.main(argv)
    except SystemExit as exc:
        return int(exc.code)
