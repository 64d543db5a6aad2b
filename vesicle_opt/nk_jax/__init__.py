"""The matrix-free Newton-Krylov path on JAX (``solver.array = 'jax'``): one code for CPU, GPU and
grids split across devices, a thin second implementation of ``nk`` tested line for line against it.

* ``ops``: E_h, A, B, gradients, Hessian-vector products and the Fourier preconditioner (jitted);
* ``layout``: one device, or the field split along the first grid axis (``jax.sharding``);
* ``reduce``: the sums (E, A, B, inner products) in a fixed order whatever the split, so one and
  several devices compute the same bits;
* ``krylov``: projected preconditioned CG as one compiled ``lax.while_loop``;
* ``newton``: Newton-CG with the line search of ``nk.newton_cg``; ``solver``: every method (exact
  with nk's outer decision, the stage methods by nk's own stage loop), nested iteration, the one
  certified Result (numpy ``verify.certify``).

JAX is an optional extra (``pip install 'vesicle_opt[jax]'``): importing this package does not
import jax; ``solve`` does, on first use (``available`` says whether it can).
"""

from __future__ import annotations

import importlib.util


def available() -> bool:
    """Is jax installed (the optional extra)?"""
    return importlib.util.find_spec("jax") is not None


def solve(scene, disc=None, **kwargs):
    """``nk_jax.solver.solve`` (see there). Imported here, on first use, because jax is optional:
    the package and its front door import without it."""
    # imported on first use: jax is an optional dependency and the front door imports this package
    from vesicle_opt.nk_jax import solver as _solver
    return _solver.solve(scene, disc, **kwargs)
