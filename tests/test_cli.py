"""Every bad input of the issue list through the CLI: exit 2, one line naming the key, no
traceback, and nothing already in the output directory lost; in 2D and in 3D."""

import os
import subprocess
import sys

import pytest

from vesicle_opt import cli

SOLVE = ["solve", "ellipse-2d", "--set", "mesh.n=16"]
SPHERE = ["solve", "sphere-3d"]
TORUS = ["solve", "torus-table1-3d"]
NATURAL = ["--set", "mesh.kind='fem-p1'", "--set", "domain.boundary='natural'"]


def _corrupt(tmp_path, name, content=b"\x00garbage"):
    path = tmp_path / name
    path.write_bytes(content)
    return str(path)


def _disk_mesh(tmp_path):
    """A valid 2D triangle mesh file (for a 3D scene: the wrong dimension)."""
    import contextlib
    import io

    import skfem
    path = tmp_path / "disk.vtk"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        skfem.MeshTri.init_circle(2).save(str(path))  # meshio notes that VTK stores 3D points
    return str(path)


def _wrong_size_phi(tmp_path):
    """A readable phi.npz from another mesh (10 values)."""
    import numpy as np
    path = tmp_path / "phi.npz"
    np.savez(path, phi=np.zeros(10))
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
    ("dt <= 0", lambda t: ["flow", "ellipse-2d", "--set", "mesh.n=16", "--dt", "0",
                           "--out", str(t / "out")], "dt"),
    ("missing mesh file", lambda t: SOLVE + ["--set", "mesh.kind='fem-p1'", "--set", "domain.boundary='natural'",
                                             "--set", f"mesh.file='{t / 'absent.msh'}'"], "mesh.file"),
    ("corrupt mesh file", lambda t: SOLVE + ["--set", "mesh.kind='fem-p1'", "--set", "domain.boundary='natural'",
                                             "--set", f"mesh.file='{_corrupt(t, 'm.vtk')}'"], "mesh.file"),
    ("corrupt warm start", lambda t: SOLVE + ["--set", "initial.shape='file'",
                                              "--set", f"initial.file='{_corrupt(t, 'phi.npz')}'"], "initial.file"),
    ("unknown method", lambda t: SOLVE + ["--set", "solver.method='newton'"], "solver.method"),
    ("unknown scheme", lambda t: ["flow", "ellipse-2d", "--scheme", "rk4"], "scheme"),
    ("unknown --set key", lambda t: SOLVE + ["--set", "solver.nothing=1"], "solver.nothing"),
    # 3D scenes (sphere-3d, torus-table1-3d), refused before any solve
    ("3D box with 4 pairs", lambda t: SPHERE + ["--set", "domain.box=[[-2,2],[-2,2],[-2,2],[-2,2]]"], "domain.box"),
    ("3D box pair of 3", lambda t: SPHERE + ["--set", "domain.box=[[-2,2],[-2,2],[-2,2,3]]"], "domain.box"),
    ("3D inverted box", lambda t: SPHERE + ["--set", "domain.box=[[-2,2],[2,-2],[-2,2]]"], "domain.box"),
    ("3D degenerate box", lambda t: TORUS + ["--set", "domain.box=[[-3,3],[-3,3],[1,1]]"], "domain.box"),
    ("3D n < 4", lambda t: SPHERE + ["--set", "mesh.n=[16,16,3]"], "mesh.n"),
    ("3D n of 2 sides", lambda t: SPHERE + ["--set", "mesh.n=[16,16]"], "mesh.n"),
    ("3D alpha outside", lambda t: TORUS + ["--set", "constraints.alpha=-300.0"], "constraints.alpha"),
    ("3D infeasible by (9)", lambda t: TORUS + ["--set", "constraints.beta=10.0"], "constraints.beta"),
    ("3D infeasible by (9), sphere", lambda t: SPHERE + ["--set", "constraints.alpha=-50.0",
                                                        "--set", "constraints.beta=1.0"], "constraints.beta"),
    # spectral + natural is the mirror grid (mesh.cosine, issue 11); it runs on numpy only
    ("3D spectral natural on jax", lambda t: SPHERE + ["--set", "mesh.kind='spectral'", "--set", "domain.boundary='natural'",
                                                      "--set", "solver.array='jax'"], "solver.array"),
    ("3D fd, natural boundary", lambda t: TORUS + ["--set", "domain.boundary='natural'"], "domain.boundary"),
    ("3D fd, consistent mass", lambda t: TORUS + ["--set", "mesh.mass='consistent'"], "mesh.mass"),
    ("3D corrupt mesh file", lambda t: SPHERE + NATURAL + ["--set", f"mesh.file='{_corrupt(t, 'm.msh')}'"],
     "mesh.file"),
    ("3D scene, 2D mesh file", lambda t: SPHERE + NATURAL + ["--set", f"mesh.file='{_disk_mesh(t)}'"], "mesh.file"),
    ("3D warm start from another mesh", lambda t: TORUS + ["--set", "initial.shape='file'",
                                                          "--set", f"initial.file='{_wrong_size_phi(t)}'"],
     "initial.file"),
    ("3D shape in 2D", lambda t: SOLVE + ["--set", "initial.shape='torus'", "--set", "initial.radii=[1.0, 0.4]"],
     "initial.shape"),
    ("3D semi-axes of 2", lambda t: SPHERE + ["--set", "constraints.target.shape='ellipsoid'",
                                             "--set", "constraints.target.semi_axes=[1.0, 1.0]"],
     "constraints.target.semi_axes"),
    ("3D torus minor > major", lambda t: TORUS + ["--set", "initial.radii=[0.5, 1.0]"], "initial.radii"),
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


def test_output_into_a_closed_pipe_is_not_an_error():
    """`vesicle-opt study --list | head -1`: the reader may leave before the writer is done."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # buffered, as a plain shell
    p = subprocess.Popen([sys.executable, "-m", "vesicle_opt.cli", "study", "--list"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    p.stdout.close()  # gone before the child writes (its imports take ~1 s)
    err = p.stderr.read().decode()
    p.wait(timeout=60)
    assert p.returncode == 0 and "Traceback" not in err, err


@pytest.mark.parametrize("verb", [["solve", "ellipse-2d", "--set", "mesh.n=16"], ["flow", "ellipse-2d"],
                                  ["study", "table1", "--quick"]])
def test_an_output_path_that_is_a_file_is_bad_input(verb, tmp_path, capsys):
    target = tmp_path / "taken"
    target.write_text("keep me\n")
    rc = cli.main([*verb, "--out", str(target)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--out" in err[0] and "Traceback" not in err[0]
    assert target.read_text() == "keep me\n"  # nothing already there lost
