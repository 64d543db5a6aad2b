"""The ranges of the scene's keys, checked wherever a scene section is built or replaced.

Every frozen section of ``scene.schema`` (``Domain``, ``Mesh``, ``Model``, ``Constraints``,
``Solver``, ``Flow``) calls its ``check_*`` here from ``__post_init__``, and ``Scene`` the checks
across sections (epsilon against h and the box, alpha against |Omega|, the mesh kind's boundary
and mass): so ``scene.load`` (the CLI), ``Scene.replace`` and ``dataclasses.replace(scene.solver,
tol=1.0)`` refuse the same inputs with the same :class:`~vesicle_opt.errors.InputError` (the key
and the allowed range). ``scene.schema.from_dict`` checks types and the TOML layout first and uses
the same messages.

``resolution_warning``: eps / h below ``EPS_PER_H_RECOMMENDED`` (the README's "keep eps/h >= 2":
at eps/h = 1 the energy is 7 % off the fine-mesh one, at 0.5 a different shape) is allowed down to
``EPS_PER_H_MIN`` but warned about before the solve.
"""

from __future__ import annotations

import importlib.util
import math
from numbers import Integral, Real

from vesicle_opt.errors import InputError

M_LIMIT = 1e12  # largest penalty constant accepted (double precision: M |A - alpha| loses digits beyond)
M_AUTO = "auto"  # solver.M's default: the penalty method picks M (model.penalty.penalty_retry)
M_DEFAULT = 1e4  # the M that 'auto' starts at (the paper's Table 1 value) and the flows' penalty constant;
# 'auto' lowers it, warm, to the certifiable M where its floor reaches tol, a number is solved as given
# solver.tol: the certificate accepts kkt_dual (the relative residual in the natural norm,
# verify.kkt) <= 100 tol, so above 1e-4 a point 1% away from stationarity would pass (tol = 1
# certified a saddle with kkt 0.2); below 1e-14 no grid can certify: the natural-norm floor (the
# round-off of phi through the bulk Hessian, ~ eps_mach h^-2, relative to the terms apart) is 1.7e-14
# at the coarsest bundled grid (torus 16^3) and 3e-13 ... 7e-11 on ellipse-2d 64^2 ... 1024^2 (measured)
TOL_RANGE = (1e-14, 1e-4)
SQUARE_TOL = 1e-9  # relative: mesh.refine's square cells, their sides equal to round-off
# model.epsilon: below h/10 the tanh profile jumps from -1 to +1 between neighbouring nodes to
# within 1e-6 (no node sees the diffuse interface); above half the box's shortest side the
# interface is as wide as the box (no vesicle fits)
EPS_PER_H_MIN, EPS_PER_BOX_MAX = 0.1, 0.5
# mesh.band (units of eps): the band about the interface where mesh.refine = "interface" keeps the fine
# cells. A solution whose phi = 0 curve comes within BAND_MIN of a coarser element is not certified
# (verify.band): with the start's band at 3 eps the tanh prolate's E_h, A, B differ from the uniform
# fine mesh's by 3.6e-4, 5e-6, 2.5e-6 (relative; 4 eps: 2e-5, 1.6e-6, 1.5e-7), below the h = eps/4
# discretisation error of E_h (2.4e-3); so a band needs more than BAND_MIN (room to move). BAND_MAX:
# beyond 20 eps the field is +-1 to 1e-12 and refining further buys nothing.
BAND_MIN, BAND_MAX = 3.0, 20.0
LEVELS_MAX = 8  # 2^8 = 256 halvings of the box's cells: beyond, the box's cells are too coarse to carry the bulk
EPS_PER_H_RECOMMENDED = 2.0  # the README's resolution table: ε/h = 1 is 7.3 % off, 0.5 another shape
CHOICES = {  # the one list of each choice key's values (scene.keys.SCHEMA shows these)
    "domain.boundary": ("periodic", "natural"),
    "mesh.kind": ("fem-p1", "fd", "spectral", "axisymmetric"),
    "mesh.mass": ("lumped", "consistent"),
    "mesh.quadrature": ("nodal", "gauss"),
    "mesh.refine": ("none", "interface"),
    "solver.method": ("exact", "penalty", "continuation", "augmented"),
    "solver.backend": ("ipopt", "newton-krylov", "auto"),
    "solver.array": ("numpy", "jax"),
    "solver.fft": ("auto", "scipy", "pyfftw"),
    "flow.scheme": ("penalty", "lagrange", "backward-euler"),
    "flow.stepping": ("constant", "adaptive"),
    "flow.initial": ("projected", "shape"),
}


def choice(key: str, v) -> None:
    if not isinstance(v, str) or v not in CHOICES[key]:
        raise InputError(key, f"must be one of {', '.join(CHOICES[key])}, got {v!r}")


def real(key: str, v, *, positive: bool = False, nonnegative: bool = False, optional: bool = False) -> None:
    """A finite real number (not a bool), > 0 with ``positive``, >= 0 with ``nonnegative``."""
    if v is None and optional:
        return
    if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v):
        raise InputError(key, f"expected a finite number, got {v!r}")
    if positive and not v > 0:
        raise InputError(key, f"must be > 0, got {v!r}")
    if nonnegative and not v >= 0:
        raise InputError(key, f"must be >= 0, got {v!r}")


def count(key: str, v, least: int = 1) -> None:
    if isinstance(v, bool) or not isinstance(v, Integral):
        raise InputError(key, f"expected an integer, got {v!r}")
    if v < least:
        raise InputError(key, f"must be >= {least}, got {v!r}")


def check_tol(tol) -> None:
    lo, hi = TOL_RANGE
    real("solver.tol", tol, positive=True)
    if not lo <= tol <= hi:
        raise InputError("solver.tol", f"allowed range {lo:g} <= tol <= {hi:g} (the certificate accepts "
                         f"kkt_dual <= 100 tol), got {tol!r}")


def penalty_M(M) -> float:
    """The number solver.M stands for: ``M_DEFAULT`` for 'auto' (``M_AUTO``), else M itself."""
    return M_DEFAULT if M == M_AUTO else float(M)


def check_penalty(M, M0, M_max, M_factor) -> None:
    """Ranges of the penalty keys (methods penalty, continuation, augmented); solver.M may be 'auto'."""
    if isinstance(M, str) and M != M_AUTO:
        raise InputError("solver.M", f"allowed {M_AUTO!r} or 0 < M <= {M_LIMIT:g}, got {M!r}")
    for key, v in (("solver.M", M), ("solver.M0", M0), ("solver.M_max", M_max)):
        if key == "solver.M" and M == M_AUTO:
            continue
        real(key, v, positive=True)
        if v > M_LIMIT:
            rng = {"solver.M": f"0 < M <= {M_LIMIT:g}", "solver.M0": f"0 < M0 <= M_max <= {M_LIMIT:g}",
                   "solver.M_max": f"M0 <= M_max <= {M_LIMIT:g}"}[key]
            raise InputError(key, f"allowed range {rng}, got {v!r}")
    real("solver.M_factor", M_factor)
    if M_factor <= 1:
        raise InputError("solver.M_factor", f"allowed range > 1, got {M_factor!r}")
    if M0 > M_max:
        raise InputError("solver.M0", f"allowed range 0 < M0 <= M_max <= {M_LIMIT:g}, got M0 = "
                         f"{M0!r} > M_max = {M_max!r}")


def spacing(box, n) -> float:
    """h: the largest cell side of a box with n cells per axis."""
    return max((b - a) / k for (a, b), k in zip(box, n))


def check_epsilon(eps, box, n, mesh_file, levels: int = 0) -> None:
    """model.epsilon within h / 10 .. half the shortest box side (module docstring); ``levels``: the
    halvings of ``mesh.refine = "interface"`` (h is the band's spacing)."""
    lengths = [b - a for a, b in box]
    if not all(math.isfinite(L) for L in lengths):
        raise InputError("domain.box", f"side lengths must be finite, got {lengths}")
    top = EPS_PER_BOX_MAX * min(lengths)
    h = spacing(box, n) / 2**levels
    bottom = EPS_PER_H_MIN * h if mesh_file is None else 0.0  # a mesh file: h unknown here
    if not bottom <= eps <= top:
        raise InputError("model.epsilon", f"allowed range {bottom:.3g} <= epsilon <= {top:.3g} "
                         f"(h/{1 / EPS_PER_H_MIN:g} with h = {h:.3g}, and {EPS_PER_BOX_MAX:g} x the shortest "
                         f"box side), got {eps!r}")


def check_domain(d) -> None:
    box = d.box
    if (not isinstance(box, (list, tuple)) or len(box) not in (2, 3)
            or not all(isinstance(p, (list, tuple)) and len(p) == 2 for p in box)):
        raise InputError("domain.box", f"expected 2 or 3 [lo, hi] pairs, got {box!r}")
    for p in box:
        for v in p:
            real("domain.box", v)
    if any(hi <= lo for lo, hi in box):
        raise InputError("domain.box", f"each pair needs lo < hi, got {[list(p) for p in box]}")
    choice("domain.boundary", d.boundary)


def check_mesh(m) -> None:
    choice("mesh.kind", m.kind)
    if not isinstance(m.n, (list, tuple)) or not all(isinstance(k, Integral) and not isinstance(k, bool) for k in m.n):
        raise InputError("mesh.n", f"expected an integer or one per dimension, got {m.n!r}")
    if min(m.n) < 4:
        raise InputError("mesh.n", f"must be >= 4 cells per side, got {m.n!r}")
    choice("mesh.mass", m.mass)
    choice("mesh.quadrature", m.quadrature)
    choice("mesh.refine", m.refine)
    count("mesh.levels", m.levels)
    if m.levels > LEVELS_MAX:
        raise InputError("mesh.levels", f"allowed range 1 <= levels <= {LEVELS_MAX}, got {m.levels!r}")
    real("mesh.band", m.band, positive=True)
    if not BAND_MIN + 1 <= m.band <= BAND_MAX:
        raise InputError("mesh.band", f"allowed range {BAND_MIN + 1:g} <= band <= {BAND_MAX:g} (units of "
                         f"model.epsilon; a solution must stay {BAND_MIN:g} from the coarse cells), got {m.band!r}")


def check_model(m) -> None:
    real("model.epsilon", m.epsilon, positive=True)
    real("model.c0", m.c0)
    real("model.rigidity", m.rigidity, positive=True)


def check_constraints(c) -> None:
    real("constraints.alpha", c.alpha, optional=True)
    real("constraints.beta", c.beta, positive=True, optional=True)
    real("constraints.area", c.area, positive=True, optional=True)
    real("constraints.reduced_volume", c.reduced_volume, optional=True)
    if c.reduced_volume is not None and not 0 < c.reduced_volume <= 1:
        raise InputError("constraints.reduced_volume", f"allowed range 0 < reduced_volume <= 1, got {c.reduced_volume!r}")


def check_solver(s) -> None:
    for key in ("method", "backend", "array", "fft"):
        choice(f"solver.{key}", getattr(s, key))
    check_tol(s.tol)
    for key in ("max_iter", "second_order_max_iter", "max_outer"):
        count(f"solver.{key}", getattr(s, key))
    for key in ("second_order", "shape_check"):
        if not isinstance(getattr(s, key), bool):
            raise InputError(f"solver.{key}", f"expected true or false, got {getattr(s, key)!r}")
    real("solver.max_memory_gb", s.max_memory_gb, positive=True, optional=True)
    check_penalty(s.M, s.M0, s.M_max, s.M_factor)


def check_flow(f) -> None:
    for key in ("scheme", "stepping", "initial"):
        choice(f"flow.{key}", getattr(f, key))
    for key in ("gamma", "dt", "t_end", "dt_min", "dt_max", "law_tol"):
        real(f"flow.{key}", getattr(f, key), positive=True)
    real("flow.steady_tol", f.steady_tol, nonnegative=True)
    for key in ("steps", "frames", "checkpoint_every"):
        count(f"flow.{key}", getattr(f, key))
    if f.initial == "shape" and f.scheme == "lagrange":
        raise InputError("flow.initial", "'lagrange' (17) preserves A and B, so it starts 'projected'")
    if f.dt_min > f.dt_max:
        raise InputError("flow.dt_min", f"must be <= flow.dt_max = {f.dt_max!r}")


def check_scene(sc) -> None:
    """The checks across sections (module docstring)."""
    d, m = sc.domain, sc.mesh
    if len(m.n) != d.dim:
        raise InputError("mesh.n", f"expected an integer or {d.dim} integers, got {m.n!r}")
    check_epsilon(sc.model.epsilon, d.box, m.n, m.file, fine_levels(m))
    if m.refine == "interface":
        check_refine(m.kind, d.box, m.n, sc.initial)
    if m.kind == "fd" and d.boundary != "periodic":
        raise InputError("domain.boundary", "mesh.kind 'fd' supports only 'periodic'")
    if m.kind in ("fd", "spectral") and m.mass == "consistent":
        raise InputError("mesh.mass", f"mesh.kind {m.kind!r} is lumped by construction; use 'lumped'")
    if m.quadrature == "gauss" and m.kind != "fem-p1":
        raise InputError("mesh.quadrature", "'gauss' needs mesh.kind = 'fem-p1'; use 'nodal'")
    if m.file is not None and m.kind != "fem-p1":
        raise InputError("mesh.file", "a mesh file needs mesh.kind = 'fem-p1'")
    check_physical_targets(sc)
    alpha = sc.constraints.alpha
    if alpha is not None and m.file is None and not (-d.volume < alpha < d.volume):
        raise InputError("constraints.alpha",
                         f"must lie in (-|Omega|, |Omega|) = ({-d.volume:.6g}, {d.volume:.6g}), got {alpha!r}")
    if sc.solver.array == "jax":
        if m.kind not in ("fd", "spectral"):
            raise InputError("solver.array", f"'jax' needs a periodic grid (mesh.kind 'fd' or 'spectral'), "
                             f"got mesh.kind {m.kind!r}")
        if d.boundary != "periodic":
            raise InputError("solver.array", "'jax' needs domain.boundary = 'periodic' (the mirror grids of "
                             "spectral + natural run on numpy only), got 'natural'")
        if importlib.util.find_spec("jax") is None:
            raise InputError("solver.array", "'jax' needs the optional extra: pip install 'vesicle_opt[jax]'")
    if sc.solver.fft == "pyfftw" and importlib.util.find_spec("pyfftw") is None:
        raise InputError("solver.fft", "'pyfftw' needs the optional extra: pip install 'vesicle_opt[fftw]'")


def fine_levels(m) -> int:
    """The halvings of the band's cells: ``mesh.levels`` under ``mesh.refine = "interface"``, else 0."""
    return m.levels if m.refine == "interface" else 0


def check_square(box, n) -> float:
    """h_0 of square tensor cells (``mesh.refine = "interface"``: right isosceles triangles stay right
    isosceles under refinement, so no angle is obtuse); InputError naming ``mesh.n`` otherwise."""
    (r0, r1), (z0, z1) = box
    hr, hz = (r1 - r0) / n[0], (z1 - z0) / n[1]
    if abs(hr - hz) > SQUARE_TOL * max(hr, hz):
        raise InputError("mesh.n", f"mesh.refine = 'interface' needs square cells (right isosceles triangles: "
                         f"no obtuse angle after refinement), got {hr:.6g} x {hz:.6g} from n = {list(n)} (n = "
                         f"{[n[0], max(4, round((z1 - z0) / hr))]} is square when the box's z side is a "
                         f"multiple of {hr:.6g})")
    return hr


def check_refine(kind: str, box, n, initial) -> None:
    """mesh.refine = "interface": the meridian mesh (mesh.kind 'axisymmetric'), square cells, and a
    start shape with an interface to refine about (not 'constant', 'noise' or a 'file' field)."""
    if kind != "axisymmetric":
        raise InputError("mesh.refine", f"'interface' needs mesh.kind = 'axisymmetric', got {kind!r}")
    check_square(box, n)
    if initial is not None and initial.shape in ("constant", "noise", "file"):
        raise InputError("mesh.refine", f"'interface' refines about the initial shape's interface; initial "
                         f"shape {initial.shape!r} has none (give a shape, or build the mesh about a field: "
                         f"vesicle_opt.mesh.discretize(scene, interface=...))")


def resolution_warning(sc) -> str | None:
    """One line when eps / h is below the recommended resolution (None otherwise, and for mesh files)."""
    if sc.mesh.file is not None:
        return None
    ratio = sc.model.epsilon / (spacing(sc.domain.box, sc.mesh.n) / 2 ** fine_levels(sc.mesh))
    if ratio >= EPS_PER_H_RECOMMENDED * (1 - 1e-9):  # the box's float division: 0.03 / 0.015 read 1.9999999
        return None
    return (f"{sc.name}: epsilon / h = {ratio:.2g} is below the recommended {EPS_PER_H_RECOMMENDED:g} (the "
            f"diffuse interface spans under {EPS_PER_H_RECOMMENDED:g} cells: energies off by several %, "
            f"below 1 possibly another shape); raise mesh.n or epsilon")


def check_physical_targets(sc) -> None:
    """A scene whose ``constraints.reduced_volume`` / ``area`` no longer give its alpha and beta (a
    ``Scene.replace`` of the physical targets alone, which left the derived alpha, beta behind and
    solved at the old volume without a word) is refused, naming the key and the way that re-derives
    them (``with_overrides``)."""
    c = sc.constraints
    if c.reduced_volume is None or c.area is None or c.alpha is None or c.beta is None:
        return
    from vesicle_opt.geometry import targets  # the one formula from_dict uses (geometry is below scene)
    alpha, beta = targets(c.reduced_volume, c.area, sc.dim, sc.domain.volume)
    scale = max(1.0, abs(alpha), abs(beta))
    if abs(alpha - c.alpha) > 1e-12 * scale or abs(beta - c.beta) > 1e-12 * scale:  # round-off of one evaluation
        raise InputError("constraints.reduced_volume",
                         f"reduced_volume {c.reduced_volume!r} with area {c.area!r} give alpha {alpha:.9g}, "
                         f"beta {beta:.9g}, but the scene holds alpha {c.alpha:.9g}, beta {c.beta:.9g}; set "
                         f"physical targets with scene.with_overrides({{'constraints.reduced_volume': ...}})")

