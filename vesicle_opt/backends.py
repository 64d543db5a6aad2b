"""What each backend supports, in one table, and the choice of backend (``solver.backend``).

* ``ipopt``: the exact-Hessian CasADi/IPOPT NLP (``vesicle_opt.nlp``); 2D and small 3D. A
  ``spectral`` mesh has a dense Laplacian, so it is not supported there.
* ``newton-krylov``: the matrix-free backend (``vesicle_opt.nk``); needs lumped mass and nodal
  quadrature (its products use Delta_h = -M_L^{-1} K): ``mesh.base.LUMPED``, the setting that
  ``mesh.base.require_lumped`` guards in the matrix-free model itself.
* ``solver.array``: ``numpy`` (default) or ``jax`` (``vesicle_opt.nk_jax``: the newton-krylov
  backend's operators and loop on JAX devices, periodic grids, methods exact and penalty).
* ``auto``: newton-krylov for spectral meshes and for 3D lumped/nodal meshes above ``AUTO_3D_NODES``
  (the sparse factorisation of the bi-Laplacian fills in beyond that: ~24 s per IPOPT iteration
  at 32^3 was measured), IPOPT otherwise.

Both backends run every ``solver.method`` (exact, penalty, continuation, augmented) with the same
meaning; an unsupported combination raises :class:`~vesicle_opt.errors.NotSupported` naming the key
and what is supported, before any work.
"""

from __future__ import annotations

import math

from vesicle_opt.errors import InputError, NotSupported
from vesicle_opt.mesh.base import LUMPED

AUTO_3D_NODES = 20**3
BACKENDS = ("ipopt", "newton-krylov")
METHODS = ("exact", "penalty", "continuation", "augmented")
SUPPORT = {
    "ipopt": {"mesh.kind": ("fem-p1", "fd", "axisymmetric"), "mesh.mass": ("lumped", "consistent"),
              "mesh.quadrature": ("nodal", "gauss"), "solver.method": METHODS},
    "newton-krylov": {"mesh.kind": ("fem-p1", "fd", "spectral", "axisymmetric"), "mesh.mass": (LUMPED["mesh.mass"],),
                      "mesh.quadrature": (LUMPED["mesh.quadrature"],), "solver.method": METHODS},
}
_WHY = {("ipopt", "mesh.kind"): "its Laplacian is dense; use 'newton-krylov' or 'auto'",
        ("newton-krylov", "mesh.mass"): "its products need Delta_h = -M_L^-1 K; use 'ipopt'",
        ("newton-krylov", "mesh.quadrature"): "its products need nodal quadrature; use 'ipopt'"}


def _value(scene, key: str) -> str:
    section, name = key.split(".")
    return getattr(getattr(scene, section), name)


def _unsupported(scene, backend: str):
    """The first (key, value, allowed) of the scene that ``backend`` does not support, or None."""
    return next(((key, _value(scene, key), allowed) for key, allowed in SUPPORT[backend].items()
                 if _value(scene, key) not in allowed), None)


def supports(scene, backend: str) -> bool:
    return _unsupported(scene, backend) is None


def check_supported(scene, backend: str) -> None:
    """NotSupported (key ``solver.backend``, one line) when ``backend`` cannot run ``scene``."""
    bad = _unsupported(scene, backend)
    if bad is not None:
        key, value, allowed = bad
        why = _WHY.get((backend, key), "")
        raise NotSupported("solver.backend", f"'{backend}' does not support {key} = {value!r} "
                           f"(supported: {', '.join(allowed)}){'; ' + why if why else ''}")


def reason(scene, chosen: str, backend: str | None = None) -> str:
    """Why ``scene`` runs on ``chosen`` (the log line of a solve): forced by the caller or the scene,
    or which rule of ``auto`` picked it."""
    b = backend or scene.solver.backend
    if b != "auto":
        return f"solver.backend = {b!r}" if backend is None else f"backend={b!r}"
    if chosen == "newton-krylov":
        return ("auto: a spectral mesh has a dense Laplacian" if scene.mesh.kind == "spectral" else
                f"auto: 3D above {AUTO_3D_NODES} nodes, where the exact Hessian's factorisation fills in")
    return "auto: 2D or a small 3D mesh" if supports(scene, "newton-krylov") else \
        f"auto: {scene.mesh.mass} mass / {scene.mesh.quadrature} quadrature need IPOPT"


def check_array(scene, chosen: str) -> None:
    """``solver.array = 'jax'`` (``vesicle_opt.nk_jax``) is the newton-krylov backend's second array
    library: InputError when the scene runs on IPOPT (the schema checks jax and the grid)."""
    if scene.solver.array == "jax" and chosen != "newton-krylov":
        raise InputError("solver.array", f"'jax' runs the newton-krylov backend, not {chosen!r}; set "
                         "solver.backend = 'newton-krylov' (or 'auto' on a spectral mesh)")


def choose_backend(scene, backend: str | None = None) -> str:
    """The backend a scene runs on (``backend`` overrides ``solver.backend``), validated."""
    chosen = _choose(scene, backend)
    check_array(scene, chosen)
    return chosen


def _choose(scene, backend: str | None) -> str:
    b = backend or scene.solver.backend
    if b == "auto":
        n_nodes = math.prod(scene.mesh.n)
        big_3d = scene.domain.dim == 3 and n_nodes > AUTO_3D_NODES and supports(scene, "newton-krylov")
        chosen = "newton-krylov" if scene.mesh.kind == "spectral" or big_3d else "ipopt"
        check_supported(scene, chosen)  # e.g. a method the chosen backend does not run
        return chosen
    if b not in BACKENDS:
        raise NotSupported("solver.backend", f"must be one of {', '.join(BACKENDS)}, auto; got {b!r}")
    check_supported(scene, b)
    return b
