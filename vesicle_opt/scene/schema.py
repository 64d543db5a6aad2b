"""Scenes: TOML files describing one equilibrium problem, validated into frozen dataclasses.

A scene has the sections ``domain``, ``mesh``, ``model``, ``constraints``, ``initial`` and ``solver``
(keys listed in ``SCHEMA``, the table of ``scene.keys``). Every key is checked for existence, type
and range; a violation raises :class:`~vesicle_opt.errors.InputError` naming the key and the
allowed range. ``--set KEY=VALUE`` overrides use the same dotted keys, with values parsed as TOML.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from vesicle_opt import extras
from vesicle_opt.errors import InputError
from vesicle_opt.geometry import targets, volume_of_reduced
from vesicle_opt.scene import ranges
from vesicle_opt.scene.axisymmetric import check_box, parse_axisymmetric_shape
from vesicle_opt.scene.bundled import resolve as resolve_scene
from vesicle_opt.scene.keys import POSITIVE, REQUIRED, SCHEMA, known  # SCHEMA: the key table, re-exported
from vesicle_opt.scene.overrides import override_items, parse_value, replace_targets  # noqa: F401 (parse_value: re-exported)
from vesicle_opt.scene.shape_spec import SHAPE_KEYS, SHAPES, Shape, number, numbers  # noqa: F401 (re-exported)

@dataclass(frozen=True)
class Domain:
    box: tuple[tuple[float, float], ...]
    boundary: str  # "periodic" | "natural"
    mirror_cells: int = 1  # spectral + natural (``mesh.cosine``): 2^d, the box is one mirror cell of the
    # doubled periodic box, and |Omega| (so alpha, volume, area, energy) is the full symmetric field's
    axisymmetric: bool = False  # mesh.kind "axisymmetric" (``mesh.axisymmetric``): the box is the
    # meridian half-plane [[0, R], [z0, z1]] of the cylinder Omega, and |Omega| is the cylinder's

    def __post_init__(self):  # the ranges wherever it is built or replaced (scene.ranges)
        ranges.check_domain(self)

    @property
    def dim(self) -> int:
        """The mesh's dimension: the box's pairs (2 on the meridian half-plane; ``Scene.dim`` is 3 there)."""
        return len(self.box)

    @property
    def volume(self) -> float:
        """|Omega|: the box's volume, times ``mirror_cells`` on mirror grids (``mesh.cosine``); the
        cylinder's pi R^2 (z1 - z0) on the meridian half-plane (``mesh.axisymmetric``)."""
        if self.axisymmetric:
            (r0, r1), (z0, z1) = self.box
            return math.pi * (r1 * r1 - r0 * r0) * (z1 - z0)
        return self.mirror_cells * math.prod(b - a for a, b in self.box)


@dataclass(frozen=True)
class Mesh:
    kind: str  # "fem-p1" | "fd" | "spectral" | "axisymmetric"
    n: tuple[int, ...]  # cells per side
    mass: str  # "lumped" | "consistent"
    quadrature: str  # "nodal" | "gauss"
    file: str | None = None
    refine: str = "none"  # "none" | "interface" (``mesh.refine``: a band about the start's interface)
    levels: int = 2  # mesh.refine = "interface": halvings of the cells in the band
    band: float = 8.0  # ... and the band's half-width in units of model.epsilon

    def __post_init__(self):  # the ranges wherever it is built or replaced (scene.ranges)
        ranges.check_mesh(self)


@dataclass(frozen=True)
class Model:
    epsilon: float
    c0: float = 0.0
    rigidity: float = 1.0

    def __post_init__(self):  # the ranges wherever it is built or replaced (scene.ranges)
        ranges.check_model(self)

    @property
    def C(self) -> float:
        """The paper's C = sqrt(2) c0."""
        return math.sqrt(2.0) * self.c0


@dataclass(frozen=True)
class Constraints:
    alpha: float | None = None
    beta: float | None = None
    target: Shape | None = None
    # physical targets (geometry.targets): given together, they set alpha and beta
    reduced_volume: float | None = None
    area: float | None = None

    def __post_init__(self):  # the ranges wherever it is built or replaced (scene.ranges)
        ranges.check_constraints(self)


@dataclass(frozen=True)
class Solver:
    method: str  # "exact" | "penalty" | "continuation"
    M: float | str  # a number, or "auto" (scene.ranges.M_AUTO): the number is ``M_value``
    tol: float
    max_iter: int
    backend: str = "auto"  # "auto" | "ipopt" | "newton-krylov" (see vesicle_opt.backends.choose_backend)
    second_order: bool = True  # run the second-order check after a converged solve
    second_order_max_iter: int = 300  # the matrix-free check's LOBPCG cap per level (verify.lobpcg.MAX_ITER)
    # penalty continuation / augmented Lagrangian (see vesicle_opt.continuation)
    M0: float = 100.0  # continuation start (and the augmented ramp's): at 10 the constraints are so weak
    # that the bundled oblate-3d opened into a slab (wrong_shape) and prolate-axisymmetric slid to another
    # minimum; from 100 both end on exact's point, with 30 / 82 steps instead of 103 / 133 (measured)
    M_factor: float = 10.0
    M_max: float = 1e6  # continuation end; the round-off floor (model.penalty.roundoff_floor) grows like
    # M sqrt(N), so the schedule stops earlier where the next stage's floor would reach tol
    # (model.penalty.next_stage: ~2.7e3 on the default 128^2 scene at tol 1e-8)
    max_outer: int = 20
    array: str = "numpy"  # "numpy" | "jax": the array library of the newton-krylov backend (nk_jax)
    fft: str = "auto"  # "auto" | "scipy" | "pyfftw": the real FFTs of Fourier grids (mesh.spectral.fft_library;
    # auto: pyFFTW where the optional extra is installed, else scipy)
    max_memory_gb: float | None = None  # the resource guard's limit (vesicle_opt.resources); None: available memory
    # a wrong shape (verify.shape: bulk carrying the volume, merged images) is not converged; out of the
    # repr, so the flows' checkpoint fingerprints (flows.api.fingerprint, the repr) stay what they were
    shape_check: bool = dataclasses.field(default=True, repr=False)

    def __post_init__(self):  # the ranges wherever it is built or replaced (scene.ranges)
        ranges.check_solver(self)

    @property
    def M_auto(self) -> bool:
        """solver.M = 'auto': the penalty method may lower M to what tol can certify."""
        return self.M == ranges.M_AUTO

    @property
    def M_value(self) -> float:
        """The penalty constant as a number (``scene.ranges.penalty_M``: 'auto' is M_DEFAULT)."""
        return ranges.penalty_M(self.M)


@dataclass(frozen=True)
class Flow:
    """Gradient-flow settings (``vesicle_opt.flows``); the penalty constant is ``solver.M``."""

    scheme: str = "penalty"  # "penalty" (18) | "lagrange" (17) | "backward-euler" (23)
    gamma: float = 1.0  # time relaxation gamma of (13)/(14)
    dt: float = 1e-3
    t_end: float = 1.0
    steps: int = 100000  # at most this many accepted steps
    stepping: str = "constant"  # "constant" | "adaptive"
    dt_min: float = 1e-12
    dt_max: float = 1.0
    steady_tol: float = 1e-6  # stop when ||phi_t|| < steady_tol * its first value; 0 = never
    law_tol: float = 1e-9  # reject a step whose relative energy-law residual exceeds this
    frames: int = 10  # snapshots + PNG frames at t_end * j / frames
    checkpoint_every: int = 50
    initial: str = "projected"  # "projected" onto A = alpha, B = beta | "shape" (not for lagrange)

    def __post_init__(self):  # the ranges wherever it is built or replaced (scene.ranges)
        ranges.check_flow(self)


@dataclass(frozen=True)
class Scene:
    name: str
    domain: Domain
    mesh: Mesh
    model: Model
    constraints: Constraints
    initial: Shape
    solver: Solver
    flow: Flow = Flow()

    def __post_init__(self):  # the checks across sections, wherever it is built or replaced (scene.ranges)
        ranges.check_scene(self)

    @property
    def dim(self) -> int:
        """The vesicle's dimension: 3 on the meridian half-plane (``mesh.axisymmetric``), else the box's."""
        return 3 if self.domain.axisymmetric else self.domain.dim

    def replace(self, **sections) -> "Scene":
        """A copy with whole sections (or the name) replaced, e.g.
        ``scene.replace(solver=dataclasses.replace(scene.solver, tol=1e-10))``: a frozen-dataclass
        ``replace`` of the top level. For single keys by their dotted names use ``with_overrides``."""
        return dataclasses.replace(self, **sections)

    def with_overrides(self, overrides: "Mapping[str, Any] | Sequence[str]") -> "Scene":
        """A copy with dotted keys set, validated as a scene file is:
        ``scene.with_overrides({"mesh.n": 64, "constraints.reduced_volume": 0.8})``, or the CLI's
        ``["mesh.n=64"]`` (``load``); InputError naming the key when a key or value is refused."""
        from vesicle_opt.scene import resolved  # the writer of the scene's raw table (TOML-free here)
        return from_dict(apply_overrides(resolved.as_dict(self), overrides), name=self.name)


_REQ = REQUIRED  # the name the docs' generator reads the table's required marker by


def _check_penalty(val: dict) -> None:
    """Ranges of the penalty keys (methods penalty, continuation, augmented): ``ranges.check_penalty``."""
    ranges.check_penalty(val["solver.M"], val["solver.M0"], val["solver.M_max"], val["solver.M_factor"])


def _flatten(d: dict, prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if key in SCHEMA:
            out[key] = v
        elif isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _set_dotted(d: dict, key: str, value: Any) -> None:
    parts = key.split(".")
    for p in parts[:-1]:
        d = d.setdefault(p, {})
        if not isinstance(d, dict):
            raise InputError(key, "cannot set a sub-key of a non-table value")
    d[parts[-1]] = value


def apply_overrides(raw: dict, overrides) -> dict:
    """Apply overrides (``override_items``: a mapping or ``KEY=VALUE`` strings; dotted keys) to a
    raw scene dict, refusing unknown keys. Setting ``constraints.reduced_volume`` / ``area``
    replaces a scene's ``alpha`` / ``beta`` / ``target`` (and the other way round), saying so."""
    items = override_items(overrides)
    for key, _ in items:
        if not known(key):
            raise InputError(key or "scene", f"unknown scene key {key!r} (allowed: {', '.join(SCHEMA)})")
    replace_targets(raw, {k for k, _ in items})
    for key, value in items:
        _set_dotted(raw, key, value)
    return raw


def from_dict(raw: dict, name: str = "scene") -> Scene:
    """Validate a raw scene dict (as read from TOML) into a :class:`Scene`."""
    flat = _flatten(raw)
    for key in flat:
        if not known(key):
            raise InputError(key or "scene", f"unknown scene key {key!r} (allowed: {', '.join(SCHEMA)})")
    val: dict[str, Any] = {}
    for key, (kind, default, allowed) in SCHEMA.items():
        if key not in flat:
            if default is REQUIRED:
                raise InputError(key, f"missing (allowed: {allowed})")
            val[key] = default
            continue
        v = flat[key]
        if kind == "str":
            if not isinstance(v, str) or (isinstance(allowed, tuple) and v not in allowed):
                raise InputError(key, f"must be one of {', '.join(allowed)}, got {v!r}"
                                 if isinstance(allowed, tuple) else f"expected a string, got {v!r}")
        elif kind == "bool":
            if not isinstance(v, bool):
                raise InputError(key, f"expected true or false, got {v!r}")
        elif kind == "float/auto" and isinstance(v, str):
            if v != ranges.M_AUTO:
                raise InputError(key, f"allowed {allowed}, got {v!r}")
        elif kind in ("float", "int", "float/auto"):
            v = number(key, v, integer=kind == "int")
            v = int(v) if kind == "int" else float(v)
            if key in POSITIVE and v <= 0:
                raise InputError(key, f"must be > 0, got {v!r}")
            if kind == "int" and v < 1:
                raise InputError(key, f"must be >= 1, got {v!r}")
        val[key] = v
    box_raw = val["domain.box"]
    if (not isinstance(box_raw, list) or len(box_raw) not in (2, 3)
            or not all(isinstance(p, list) and len(p) == 2 for p in box_raw)):
        raise InputError("domain.box", f"expected 2 or 3 [lo, hi] pairs, got {box_raw!r}")
    box = tuple(numbers("domain.box", p, 2) for p in box_raw)
    if any(hi <= lo for lo, hi in box):
        raise InputError("domain.box", f"each pair needs lo < hi, got {[list(p) for p in box]}")
    check_box(val, box)
    dim = len(box)
    n_raw = val["mesh.n"]
    n = (n_raw,) * dim if isinstance(n_raw, int) and not isinstance(n_raw, bool) else n_raw
    if (not isinstance(n, (list, tuple)) or len(n) != dim
            or not all(isinstance(k, int) and not isinstance(k, bool) for k in n)):
        raise InputError("mesh.n", f"expected an integer or {dim} integers, got {n_raw!r}")
    if min(n) < 4:
        raise InputError("mesh.n", f"must be >= 4 cells per side, got {n_raw!r}")
    mirrored = val["mesh.kind"] == "spectral" and val["domain.boundary"] == "natural"
    axisym = val["mesh.kind"] == "axisymmetric"
    domain = Domain(box, val["domain.boundary"], 2**dim if mirrored else 1, axisym)
    dim = 3 if axisym else dim  # the vesicle's: the shapes and the physical targets are 3D
    _check_ranges(val, box, n)
    if val["mesh.kind"] == "fd" and domain.boundary != "periodic":
        raise InputError("domain.boundary", "mesh.kind 'fd' supports only 'periodic'")
    if val["mesh.kind"] == "fd" and val["mesh.mass"] == "consistent":
        raise InputError("mesh.mass", "mesh.kind 'fd' is lumped by construction; use 'lumped'")
    if val["mesh.kind"] == "spectral":  # Fourier pseudo-spectral grids (issue 6); natural: mesh.cosine
        if val["mesh.mass"] == "consistent":
            raise InputError("mesh.mass", "mesh.kind 'spectral' is lumped by construction; use 'lumped'")
    if val["mesh.quadrature"] == "gauss" and val["mesh.kind"] not in ("fem-p1", "axisymmetric"):
        raise InputError("mesh.quadrature", "'gauss' needs mesh.kind = 'fem-p1' or 'axisymmetric'; use 'nodal'")
    if val["mesh.file"] is not None and val["mesh.kind"] != "fem-p1":
        raise InputError("mesh.file", "a mesh file needs mesh.kind = 'fem-p1'")
    mesh = Mesh(val["mesh.kind"], tuple(n), val["mesh.mass"], val["mesh.quadrature"], val["mesh.file"],
                val["mesh.refine"], val["mesh.levels"], val["mesh.band"])
    model = Model(val["model.epsilon"], val["model.c0"], val["model.rigidity"])
    target = None
    if val["constraints.target"] is not None:
        target = parse_axisymmetric_shape("constraints.target", val["constraints.target"], dim, axisym)
    alpha, beta = val["constraints.alpha"], val["constraints.beta"]
    nu, area = val["constraints.reduced_volume"], val["constraints.area"]
    if nu is not None or area is not None:
        alpha, beta = _physical_targets(val, target, dim, domain)
    if target is None and (alpha is None or beta is None):
        raise InputError("constraints.alpha" if alpha is None else "constraints.beta",
                         "missing: give constraints.alpha and constraints.beta, or constraints.target")
    if alpha is not None and val["mesh.file"] is None and not (-domain.volume < alpha < domain.volume):
        raise InputError("constraints.alpha",
                         f"must lie in (-|Omega|, |Omega|) = ({-domain.volume:.6g}, {domain.volume:.6g}), got {alpha!r}")
    constraints = Constraints(alpha, beta, target, nu, area)
    initial = parse_axisymmetric_shape("initial", val["initial"], dim, axisym)
    _check_penalty(val)
    _check_array(val)
    _check_fft(val)
    solver = Solver(val["solver.method"], val["solver.M"], val["solver.tol"], val["solver.max_iter"],
                    val["solver.backend"], second_order=val["solver.second_order"],
                    second_order_max_iter=val["solver.second_order_max_iter"], M0=val["solver.M0"],
                    shape_check=val["solver.shape_check"],
                    M_factor=val["solver.M_factor"], M_max=val["solver.M_max"],
                    max_outer=val["solver.max_outer"], array=val["solver.array"], fft=val["solver.fft"],
                    max_memory_gb=val["solver.max_memory_gb"])
    return Scene(name, domain, mesh, model, constraints, initial, solver, _flow(val))


def _check_array(val: dict) -> None:
    """solver.array = 'jax' (vesicle_opt.nk_jax) needs jax installed and a periodic grid (fd or
    spectral: FFT-applied Laplacians); checked here, before any work."""
    if val["solver.array"] != "jax":
        return
    if val["mesh.kind"] not in ("fd", "spectral"):
        raise InputError("solver.array", f"'jax' needs a periodic grid (mesh.kind 'fd' or 'spectral'), "
                         f"got mesh.kind {val['mesh.kind']!r}")
    if val["domain.boundary"] != "periodic":
        raise InputError("solver.array", "'jax' needs domain.boundary = 'periodic' (the mirror grids of "
                         "spectral + natural run on numpy only), got 'natural'")
    extras.require("jax", "solver.array", "jax")  # installed and loading (a broken jaxlib is refused here)


def _check_fft(val: dict) -> None:
    """solver.fft = 'pyfftw' needs pyFFTW installed (the optional extra ``fftw``); checked before any work."""
    if val["solver.fft"] == "pyfftw":
        extras.require("pyfftw", "solver.fft", "pyfftw")  # installed and loading


def _check_ranges(val: dict, box, n) -> None:
    """solver.tol and model.epsilon within the ranges that mean something (``scene.ranges``)."""
    ranges.check_tol(val["solver.tol"])
    levels = val["mesh.levels"] if val["mesh.refine"] == "interface" else 0
    ranges.check_epsilon(val["model.epsilon"], box, n, val["mesh.file"], levels)


def _physical_targets(val: dict, target, dim: int, domain: Domain) -> tuple[float, float]:
    """(alpha, beta) of ``constraints.reduced_volume`` and ``constraints.area`` (geometry.targets)."""
    nu, area = val["constraints.reduced_volume"], val["constraints.area"]
    for key, other in (("constraints.reduced_volume", "constraints.area"),
                       ("constraints.area", "constraints.reduced_volume")):
        if val[key] is None:
            raise InputError(key, f"missing: {other} needs {key} beside it")
    for key in ("constraints.alpha", "constraints.beta", "constraints.target"):
        if val[key] is not None:
            raise InputError(key, "give either constraints.reduced_volume with constraints.area, or "
                             "constraints.alpha/beta/target, not both")
    if not 0 < nu <= 1:
        raise InputError("constraints.reduced_volume", f"allowed range 0 < reduced_volume <= 1, got {nu!r}")
    alpha, beta = targets(nu, area, dim, domain.volume)
    if not alpha < domain.volume:
        raise InputError("constraints.area", f"the vesicle's volume {volume_of_reduced(nu, area, dim):.6g} "
                         f"must be below the box's |Omega| = {domain.volume:.6g}; choose a smaller area")
    return alpha, beta


def _flow(val: dict) -> Flow:
    """The ``flow.*`` keys, with the checks the generic loop cannot express."""
    if val["flow.steady_tol"] < 0:
        raise InputError("flow.steady_tol", f"must be >= 0, got {val['flow.steady_tol']!r}")
    if val["flow.initial"] == "shape" and val["flow.scheme"] == "lagrange":
        raise InputError("flow.initial", "'lagrange' (17) preserves A and B, so it starts 'projected'")
    if val["flow.dt_min"] > val["flow.dt_max"]:
        raise InputError("flow.dt_min", f"must be <= flow.dt_max = {val['flow.dt_max']!r}")
    return Flow(**{f.name: val[f"flow.{f.name}"] for f in dataclasses.fields(Flow)})


def load(scene: str | Path, overrides: Mapping[str, Any] | Sequence[str] | None = None) -> Scene:
    """Read and validate a scene, given as a TOML path or the name of a bundled scene
    (``scene.bundled``: ``ellipse-2d``), applying overrides: a mapping of dotted keys to values
    (``{"mesh.n": 64}``) or ``--set`` style strings (``["mesh.n=64"]``); InputError otherwise."""
    name, text = resolve_scene(scene)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError("scene", f"{scene} is not valid TOML: {exc}") from None
    return from_dict(apply_overrides(raw, overrides), name=name)
