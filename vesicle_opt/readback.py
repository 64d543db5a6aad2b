"""Output directories read back into objects, and a solve's result written from Python (a unit
above ``branch``: it builds Branch, Result and Scene objects).

    import vesicle_opt as vo
    res = vo.solve(vo.load_scene("ellipse-2d"))
    vo.write_result(res, "out/ellipse")          # what `vesicle-opt solve ellipse-2d --out out/ellipse` writes
    back = vo.load("out/ellipse")                # a Result again: back.energy, back.reduced_volume, ...

``load(path)`` reads the directory of any of the four verbs, told apart by their files:

* ``solve``  (``summary.json`` + ``phi.npz`` of kind ``solve``)  -> :class:`~vesicle_opt.result.Result`
  (``load_result``): every summary key back in its field or in ``extra``, so
  ``back.summary(name)`` equals summary.json; phi and w from ``phi.npz``; the scene from
  ``scene.resolved.toml`` and its discretisation rebuilt (``disc=False`` skips that);
* ``flow``   (``summary.json`` with ``scheme``)                -> :class:`FlowRecord` (``load_flow``);
* ``branch`` (``branch.json``)                                  -> :class:`~vesicle_opt.branch.Branch`
  (``load_branch``), its rows parsed from ``branch.csv``, the scene from branch.json's ``scene_data``,
  ``parents`` (the tree) from the rows' ``parent`` column, ``Branch.field(point)`` the point's snapshot;
* ``study``  (anything else with CSV files)                     -> :class:`StudyRecord` (``load_study``).

Every file is read through the checked loader of the state files (``io.state``; the ``.npz`` files
through ``io.fields.read``, its format version checked): a file that does not parse (bytes that are
not UTF-8, a CSV line with another number of fields than its header, a branch.csv value of the
wrong type or an unknown column, a JSON file that is not an object or lacks a key, an npz that is
not a zip or holds an array of another type or length) raises ``StateFileError`` (an InputError)
naming the file, never a raw exception or a half-parsed object. The one thing read past is a torn
last CSV line (a killed run's), with a warning: a resume cuts it off the same way. A directory that
is none of these raises InputError naming it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vesicle_opt.errors import InputError, StateFileError
from vesicle_opt.io import fields, state
from vesicle_opt.result import Result, Status

ADVICE = "not a file vesicle-opt wrote, or a damaged one (rerun the command that wrote it)"
log = logging.getLogger(__name__)

# summary.json keys that are Result fields (the rest go to ``extra``, as ``Result.summary`` writes them)
_FIELDS = ("method", "energy", "volume_residual", "area_residual", "lambda_volume", "lambda_area",
           "kkt_residual", "status", "success", "converged", "iterations", "wall_time_s",
           "derivative_time_s", "other_time_s", "n_nodes", "hessian_nnz_per_row", "M", "penalized_energy")


@dataclass(frozen=True)
class FlowRecord:
    """A ``vesicle-opt flow`` directory read back: the summary, the final field, the history rows
    (``history.csv`` parsed), the snapshot files and the scene."""

    path: Path
    summary: dict
    phi: np.ndarray
    nodes: np.ndarray
    t: float
    history: tuple[dict, ...]
    snapshots: tuple[Path, ...]
    scene: object = field(default=None, repr=False)

    @property
    def energy(self) -> float:
        """rigidity * E_h of the final field."""
        return float(self.summary["energy"])

    @property
    def status(self) -> Status:
        """How the run ended (T_END, STEADY, MAX_STEPS, STOPPED, FAILED)."""
        return Status(self.summary["status"])

    @property
    def steps(self) -> int:
        """The accepted steps of the run."""
        return int(self.summary["steps"])

    def snapshot(self, j: int) -> dict:
        """The arrays of ``snapshots/phi_JJJ.npz`` (``io.fields`` layout): phi, t, nodes, ..."""
        return fields.read(self.path / "snapshots" / f"phi_{j:03d}.npz")


@dataclass(frozen=True)
class StudyRecord:
    """A ``vesicle-opt study`` directory read back: each CSV as a tuple of rows (numbers parsed),
    each JSON file's data, and the figures' paths, keyed by file stem."""

    path: Path
    tables: dict
    data: dict
    figures: tuple[Path, ...]


def _number(text: str):
    if text == "":
        return None
    if text in ("true", "True", "false", "False"):
        return text in ("true", "True")
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _header(names: list[str]) -> str | None:
    """What is wrong with a CSV header of a study (its names are the study's own)."""
    if not names or any(not n.strip() for n in names):
        return "an empty column name"
    if len(set(names)) != len(names):
        return "a column named twice"
    return None


def _rows(path: Path, check_header, check_row=lambda row, k: None) -> list[dict]:
    """The rows of a CSV file as text, read through the checked loader (module docstring)."""
    found = state.read_csv(path, check_header, check_row, ADVICE, "path")
    if found is None:
        return []
    _, rows, torn = found
    if torn is not None:
        log.warning("%s: its last line is torn (the run was killed while writing it); read without it", path)
    return rows


def read_csv(path: Path) -> tuple[dict, ...]:
    """The rows of a CSV file with numbers and booleans parsed ('' -> None); a StateFileError
    naming the file when it does not parse (module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise InputError("path", f"file not found: {path}")
    return tuple({k: _number(v) for k, v in row.items()} for row in _rows(path, _header))


def _json(path: Path, needs: tuple[str, ...] = ()) -> dict:
    """The JSON object of ``path`` with the keys ``needs``, through the checked loader."""
    if not path.is_file():
        raise InputError("path", f"{path.parent} has no {path.name}")
    return _needs(path, state.read_json(path, ADVICE, "path"), needs)


def _needs(path: Path, data: dict, keys: tuple[str, ...]) -> dict:
    missing = [k for k in keys if k not in data]
    if missing:
        raise StateFileError(path, f"has no {', '.join(map(repr, missing))}; {ADVICE}", "path")
    return data


def _scene(path: Path, name: str | None):
    """The scene of ``scene.resolved.toml`` under the run's own name (None when the file is absent)."""
    from vesicle_opt.scene import load as load_scene  # the schema: only when a scene is read back
    toml = path / "scene.resolved.toml"
    if not toml.exists():
        return None
    scene = load_scene(toml)
    return scene if name is None else scene.replace(name=name)


def _dir(path) -> Path:
    path = Path(path)
    if not path.is_dir():
        raise InputError("path", f"{str(path)!r} is not a directory written by vesicle-opt")
    return path


def _summary_error(path: Path, exc: Exception) -> StateFileError:
    """A summary.json / branch.json whose keys parse but hold values of another type."""
    what = f"key {exc.args[0]!r} missing" if isinstance(exc, KeyError) else str(exc)[:80]
    return StateFileError(path, f"holds a value of the wrong type ({what}); {ADVICE}", "path")


def load_result(path: str | Path, *, disc: bool = True) -> Result:
    """The :class:`Result` of a ``solve`` directory (module docstring). ``disc=False``: no
    discretisation rebuilt (``Result.disc`` None; faster for large 3D meshes)."""
    path = _dir(path)
    summary = _json(path / "summary.json", ("outcome", "iterations", "n_nodes"))
    if "scheme" in summary:
        raise InputError("path", f"{path} is a flow directory; use vo.load_flow (or vo.load)")
    npz = path / "phi.npz"
    data = fields.read(npz) if npz.exists() else {"phi": np.array([np.nan]), "kind": "solve"}
    if data["kind"] != "solve":
        raise InputError("path", f"{npz} holds a {data['kind']!r} field, not a solve's")
    scene = _scene(path, summary.get("scene"))
    discretisation = None
    if disc and scene is not None:
        from vesicle_opt.mesh import discretize  # the meshes: only when a discretisation is rebuilt
        refined = scene.mesh.kind == "axisymmetric" and scene.mesh.refine == "interface"
        # an interface-refined mesh was built about the solve's start (mesh.band_start), not the
        # scene alone: it is read back from the result's own phi.vtu (its nodes and triangles)
        discretisation = _refined_mesh(path, scene) if refined else discretize(scene)
    try:
        return _result(summary, data, discretisation, scene)
    except (KeyError, TypeError, ValueError) as exc:  # a value of another type than a solve writes
        raise _summary_error(path / "summary.json", exc) from None


def _result(summary: dict, data: dict, discretisation, scene) -> Result:
    def num(key: str, default: float = float("nan")) -> float:
        value = summary.get(key)
        return default if value is None else float(value)

    opt = {k: summary.get(k) for k in ("method", "M", "penalized_energy", "status")}
    extra = {k: v for k, v in summary.items() if k not in _FIELDS and k not in ("scene", "outcome")}
    return Result(
        phi=np.asarray(data["phi"], float), w=data.get("w"),
        energy=num("energy"), volume_residual=num("volume_residual"), area_residual=num("area_residual"),
        lambda_volume=num("lambda_volume"), lambda_area=num("lambda_area"), kkt_residual=num("kkt_residual"),
        status=opt["status"], success=bool(summary.get("success")), converged=bool(summary.get("converged")),
        outcome=Status(summary["outcome"]), iterations=int(summary["iterations"]),
        wall_time_s=num("wall_time_s"), derivative_time_s=num("derivative_time_s", 0.0),
        other_time_s=num("other_time_s", 0.0), n_nodes=int(summary["n_nodes"]),
        hessian_nnz_per_row=num("hessian_nnz_per_row", 0.0),
        method=opt["method"], M=opt["M"], penalized_energy=opt["penalized_energy"],
        extra=extra, disc=discretisation, scene=scene)


def _refined_mesh(path: Path, scene):
    """The discretisation of an interface-refined solve from its phi.vtu (None without one)."""
    if not (path / "phi.vtu").is_file():
        return None
    import meshio  # third-party: only meshes' .vtu files need it
    import skfem

    from vesicle_opt.mesh import axisymmetric, refine  # the meshes: only when a discretisation is rebuilt

    try:  # a damaged or foreign phi.vtu is refused like any other state file, never a raw exception
        m = meshio.read(str(path / "phi.vtu"))
        mesh = skfem.MeshTri(np.ascontiguousarray(m.points[:, :2].T),
                             np.ascontiguousarray(m.cells_dict["triangle"].T))
    except Exception as exc:  # meshio raises its own ReadError, KeyError, ValueError, ...
        raise StateFileError(path / "phi.vtu", f"is not a triangle mesh ({str(exc)[:80]}); {ADVICE}",
                             "path") from None
    h_fine = refine.square_side(scene.domain.box, scene.mesh.n) / 2**scene.mesh.levels
    return axisymmetric.assemble(mesh, scene.domain.box, scene.mesh.mass, scene.mesh.quadrature,
                                 h_fine=h_fine, band=scene.mesh.band)


def load_flow(path: str | Path) -> FlowRecord:
    """The :class:`FlowRecord` of a ``flow`` directory (module docstring)."""
    path = _dir(path)
    summary = _json(path / "summary.json")
    if "scheme" not in summary:
        raise InputError("path", f"{path} is not a flow directory (its summary.json has no 'scheme')")
    _needs(path / "summary.json", summary, ("energy", "status", "steps"))  # what FlowRecord's properties read
    try:
        float(summary["energy"]), Status(summary["status"]), int(summary["steps"])
    except (TypeError, ValueError) as exc:
        raise _summary_error(path / "summary.json", exc) from None
    data = fields.read(path / "phi.npz")
    if "nodes" not in data or "t" not in data:
        raise StateFileError(path / "phi.npz", f"has no 'nodes' or 't': not a flow's field; {ADVICE}", "path")
    hist = path / "history.csv"
    return FlowRecord(path, summary, np.asarray(data["phi"], float), np.asarray(data["nodes"], float),
                      float(data["t"]), read_csv(hist) if hist.exists() else (),
                      tuple(sorted((path / "snapshots").glob("phi_*.npz"))), _scene(path, summary.get("scene")))


def load_branch(path: str | Path) -> "Branch":
    """The :class:`~vesicle_opt.branch.Branch` of a ``branch`` directory (module docstring); a run
    that did not finish (killed) has ``stopped`` {0: "unfinished"}. branch.csv is checked as a
    resume checks it (its columns those of ``branch.store.COLUMNS`` or, from an older version, a
    subset; every value of its type; the points in order)."""
    from vesicle_opt.branch.run import Branch  # the branch package: only when a branch is read back
    from vesicle_opt.branch.store import COLUMNS, check_row, parse  # the same reason: a branch read back
    from vesicle_opt.scene.schema import from_dict  # the schema: only when a scene is read back
    path = _dir(path)
    meta_path = path / "branch.json"
    meta = _json(meta_path, ("param", "to", "step", "scene"))
    csv_path = path / "branch.csv"
    if not csv_path.is_file():
        raise InputError("path", f"{path} has no branch.csv")

    def header(names: list[str]) -> str | None:
        unknown = [n for n in names if n not in COLUMNS]
        return _header(names) or (f"unknown columns {', '.join(map(repr, unknown[:3]))}" if unknown else None) or \
            (None if {"point", "branch"} <= set(names) else "no 'point' and 'branch' columns")
    rows = tuple(parse(r) for r in _rows(csv_path, header, check_row))
    try:
        stopped = {int(k): str(v) for k, v in dict(meta.get("stopped", {"0": "unfinished"})).items()}
        to, step = float(meta["to"]), float(meta["step"])
    except (TypeError, ValueError) as exc:
        raise _summary_error(meta_path, exc) from None
    data = meta.get("scene_data")
    scene = from_dict(data, name=meta["scene"]) if isinstance(data, dict) else None
    parents = {}  # the tree (branch.tree): each branch's parent, from the parent column of its first row
    for r in rows:
        parents.setdefault(r["branch"], r.get("parent"))
    parents.update({k: None for k in stopped if k not in parents})  # a branch without rows: a root
    return Branch(meta["param"], to, step, rows, stopped, path, parents, scene=scene)


def load_study(path: str | Path) -> StudyRecord:
    """The :class:`StudyRecord` of a ``study`` directory: every ``*.csv``, ``*.json`` and ``*.png``
    directly in it."""
    path = _dir(path)
    tables = {p.stem: read_csv(p) for p in sorted(path.glob("*.csv"))}
    if not tables:
        raise InputError("path", f"{path} holds no summary.json, branch.json or CSV file: "
                         "not an output directory of vesicle-opt")
    data = {p.stem: _json(p) for p in sorted(path.glob("*.json"))}
    return StudyRecord(path, tables, data, tuple(sorted(path.glob("*.png"))))


def load(path: str | Path, **kwargs) -> "Result | FlowRecord | Branch | StudyRecord":
    """Any verb's output directory as an object: Result (solve), FlowRecord (flow), Branch
    (branch) or StudyRecord (study); see the module docstring."""
    path = _dir(path)
    if (path / "branch.json").exists():
        return load_branch(path)
    if (path / "summary.json").exists():
        summary = _json(path / "summary.json")
        return load_flow(path) if "scheme" in summary else load_result(path, **kwargs)
    return load_study(path)


def write_result(result: Result, out: str | Path, scene: "Scene | None" = None) -> dict:
    """Write a solve's files into ``out`` as ``vesicle-opt solve --out`` does (summary.json,
    phi.npz, the VTK files, phi.png, surface.ply on 3D grids, scene.resolved.toml); returns the
    summary dict. ``scene``: default ``result.scene`` (set by ``vo.solve``)."""
    from vesicle_opt.io import output  # the writers (matplotlib, meshio): only when writing
    from vesicle_opt.scene import resolved  # tomli-w: only when writing
    scene = scene if scene is not None else result.scene
    if scene is None:
        raise InputError("scene", "this Result carries no scene (not from vo.solve): pass scene=")
    if result.disc is None:
        raise InputError("result", "this Result carries no discretisation (Result.disc): solve it, or "
                         "load it with disc=True")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = output.write_result(out, scene, result.disc, result)
    resolved.write(out / "scene.resolved.toml", scene)
    return summary
