"""The resource guard: a scene's memory estimate against the memory available, before any work.

    estimate = nodes x bytes per node (of the chosen backend / flow scheme, mesh and dimension;
               an interface-refined mesh's nodes estimated from its band about the start shape)
             + the feasibility bound's radial grid (``model.feasibility``: max(N_RADIAL, 20 r_out / eps)
               points per candidate, each an IPOPT solve on CasADi SX)

and ``check`` refuses, with one line naming ``mesh.n`` and the estimate, a scene whose estimate
exceeds ``solver.max_memory_gb`` (default: the memory available now, ``psutil``). A larger
``solver.max_memory_gb`` raises the limit (e.g. for a machine with swap).

The bytes per node are peak RSS above the interpreter with the package imported, divided by the
nodes, measured at the largest size that fits a 2-core test machine (two iterations, no second-order
check), rounded up (``BYTES_PER_NODE``). IPOPT's exact Hessian is factorised by MUMPS; in 3D its
fill grows like N^(4/3) (nested dissection), so the 3D figure grows like (N / N_ref)^(1/3) from the
one measured at N_ref = 20^3. The estimate is a guard against certain failure (a 74.5 GiB array,
a machine driven into swap), not a prediction; solves below the limit may still be slow.
"""

from __future__ import annotations

import math

import psutil

from vesicle_opt.errors import InputError
from vesicle_opt.model.feasibility import N_RADIAL

GB = 1e9
# (path, dim) -> bytes per node, measured (module docstring); "ipopt-3d" grows like (N / IPOPT_3D_REF)^(1/3)
BYTES_PER_NODE = {
    ("ipopt", 2): 5_000,  # FD / P1 lumped nodal, exact or penalty: 4.8e3 at 192^2, 6.1e3 at 96^2
    ("ipopt-consistent", 2): 13_000,  # P1 consistent mass (phi, w): 12.9e3 at 96^2
    ("ipopt-gauss", 2): 24_000,  # P1 Gauss quadrature: 23.4e3 at 96^2
    ("ipopt", 3): 30_000,  # FD 3D: 20.8e3 at 16^3, 28.9e3 at 20^3 (grows, see IPOPT_3D_REF)
    ("newton-krylov", 2): 600,  # Fourier grids (spectral, FD by FFT): 296 at 512^2, 463 at 256^2
    ("newton-krylov", 3): 600,  # 554 at 48^3 (spectral)
    ("newton-krylov-fem", 2): 10_000,  # P1 meshes: the sparse preconditioner (LU / pyamg)
    ("newton-krylov-fem", 3): 10_000,  # 9.3e3 at 24^3
    ("flow", 2): 3_000,
    ("flow", 3): 3_000,
    ("flow-backward-euler", 2): 6_000,
}
# solver.array = "jax": the device buffers of the Newton-CG program on top of the numpy footprint
# (on CPU devices they live in host memory): nk_jax.ops.memory_bytes_per_node on one device, 232.8 B
# in 3D (XLA's memory analysis; 216.8 in 2D), rounded up; a test ties the two figures
JAX_DEVICE_BYTES_PER_NODE = {2: 240, 3: 240}
IPOPT_3D_REF = 20**3
BYTES_PER_RADIAL_POINT = 20_000  # the feasibility bound's 1D IPOPT (CasADi SX graph of n points)


def _nodes(scene) -> int | None:
    """Grid nodes of a box mesh (None for a mesh file: its size is known only once it is read); an
    interface-refined meridian mesh's from its band about the start shape (``mesh.refine.estimate_nodes``:
    mesh.n counts only its coarse cells, 648 of the bundled oblate's 10.5 k nodes)."""
    if scene.mesh.file is not None:
        return None
    if getattr(scene.mesh, "refine", None) == "interface":
        from vesicle_opt import mesh  # the start's distance (scene.shapes); only refined scenes pay it
        from vesicle_opt.mesh import refine  # scikit-fem: as the mesh it estimates, loaded only here

        return refine.estimate_nodes(scene.domain.box, scene.mesh.n, mesh.initial_distance(scene),
                                     scene.mesh.band * scene.model.epsilon, scene.mesh.levels)
    return math.prod(scene.mesh.n)


def bytes_per_node(scene, path: str) -> float:
    """The measured figure for ``path`` = a backend ("ipopt", "newton-krylov") or "flow"."""
    dim = scene.domain.dim  # the mesh's (2 on the meridian half-plane of an axisymmetric scene)
    if path == "ipopt":
        base = BYTES_PER_NODE[("ipopt", dim)]
        if scene.mesh.mass == "consistent":  # the 2D ratios, applied in 3D too (not measured there)
            base *= BYTES_PER_NODE[("ipopt-consistent", 2)] / BYTES_PER_NODE[("ipopt", 2)]
        elif scene.mesh.quadrature == "gauss":
            base *= BYTES_PER_NODE[("ipopt-gauss", 2)] / BYTES_PER_NODE[("ipopt", 2)]
        if dim == 3:
            n = _nodes(scene) or IPOPT_3D_REF
            base *= max(1.0, (n / IPOPT_3D_REF) ** (1 / 3))
        return base
    if path == "newton-krylov" and getattr(scene.solver, "array", "numpy") == "jax":
        return BYTES_PER_NODE[("newton-krylov", dim)] + JAX_DEVICE_BYTES_PER_NODE[dim]
    if path == "newton-krylov" and scene.mesh.kind == "fem-p1":
        return BYTES_PER_NODE[("newton-krylov-fem", dim)]
    if path == "flow" and scene.flow.scheme == "backward-euler":
        return BYTES_PER_NODE.get(("flow-backward-euler", dim), BYTES_PER_NODE[("ipopt", dim)])
    return BYTES_PER_NODE[(path, dim)]


def feasibility_points(scene) -> int:
    """The largest radial grid of ``model.feasibility.radial_minimum`` for this scene (its r_out is at
    least the box's half side, or its side for natural boundaries)."""
    r_box = max(b - a for a, b in scene.domain.box) * (1.0 if scene.domain.boundary == "natural" else 0.5)
    r_out = r_box + 12 * scene.model.epsilon  # an upper bound of max(R + 12 eps, r_box)
    points = 20 * r_out / scene.model.epsilon
    return int(min(max(N_RADIAL, points), 1e300))


def estimate_bytes(scene, path: str) -> tuple[float, str]:
    """(bytes, how) of a run of ``scene`` on ``path`` (module docstring)."""
    nodes = _nodes(scene)
    radial = feasibility_points(scene)
    total = radial * BYTES_PER_RADIAL_POINT
    how = f"feasibility grid {radial:.3g} points x {BYTES_PER_RADIAL_POINT} B"
    if nodes is not None:
        bpn = bytes_per_node(scene, path)
        total += nodes * bpn
        how = f"{nodes:.4g} nodes x {bpn:.3g} B per node ({path}) + " + how
    return total, how


def limit_bytes(scene) -> tuple[float, str]:
    """(bytes, where it comes from): ``solver.max_memory_gb``, else the memory available now."""
    if scene.solver.max_memory_gb is not None:
        return scene.solver.max_memory_gb * GB, "solver.max_memory_gb"
    return float(psutil.virtual_memory().available), "available memory"


def check(scene, path: str) -> float:
    """Refuse ``scene`` on ``path`` when its estimate exceeds the limit (module docstring);
    returns the estimate in bytes."""
    need, how = estimate_bytes(scene, path)
    limit, source = limit_bytes(scene)
    if need > limit:
        grid = feasibility_points(scene) * BYTES_PER_RADIAL_POINT
        fix = "a larger model.epsilon" if grid > need / 2 else "a smaller mesh.n"
        raise InputError("mesh.n", f"mesh.n = {list(scene.mesh.n)} needs about {need / GB:.3g} GB "
                         f"({how}), above the {limit / GB:.3g} GB of {source}; use {fix}, or raise "
                         f"solver.max_memory_gb")
    return need
