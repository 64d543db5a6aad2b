"""The method ``exact`` taken on to a minimum where it ends on a saddle: what a user of ``exact`` does to
get the certified minimum that the penalty methods reach (``bench_methods``' like-for-like cost).

``solve_escaping``: the exact solve; while it ends converged on a second-order **saddle**, a push along
the check's least eigenvector (``history['second_order_mode']``, M-normalised) by ``PUSH`` times the
field's M-norm (the push ``branch.deflation`` uses for its starts) and another exact solve from
there, each certified and second-order checked as the first. Along that mode the energy drops like
1/2 mu a^2 (mu < 0), so the new start lies below the saddle's basin boundary for a push large enough
to leave the quadratic region; either sign does (the two sides are mirror images on the symmetric
saddles seen here), the + side is taken.

``python -m vesicle_opt.studies._escape SCENE OUT`` runs it as one process and writes OUT as
``vesicle-opt solve --out`` does (``io.output.write_result``: summary.json and the fields), with
``escape_rounds`` and ``escape_energies`` (each solve's energy, the saddles first) in the summary.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import warnings
from pathlib import Path

import numpy as np

from vesicle_opt.api import solve
from vesicle_opt.scene import load

PUSH = 0.2  # the push, in units of the field's M-norm (branch.deflation's)
ROUNDS = 3  # pushes at most (one on the Table-1 torus)


def solve_escaping(scene, push: float = PUSH, rounds: int = ROUNDS):
    """(the last result, the energies of every solve, the pushes made); module docstring."""
    r = solve(scene)
    energies, k = [r.energy], 0
    while k < rounds and r.converged and r.extra.get("second_order") == "saddle" \
            and r.history.get("second_order_mode") is not None:
        mode = np.asarray(r.history["second_order_mode"], float)
        scale = math.sqrt(float(np.dot(r.disc.weights, r.phi * r.phi)))
        r = solve(scene, x0=r.phi + push * scale * mode)
        energies.append(r.energy)
        k += 1
    return r, energies, k


def main(name: str, out: str) -> int:
    """One process: load the scene, ``solve_escaping``, write OUT; exit 0 when certified (as the CLI)."""
    from vesicle_opt.io.output import write_result  # the writers (matplotlib, meshio): only when writing
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the scene's near-bound / resolution warnings: its documented state
        scene = load(name)
        r, energies, k = solve_escaping(scene)
    r = dataclasses.replace(r, extra={**r.extra, "escape_rounds": k,
                                      "escape_energies": " ".join(f"{e:.12g}" for e in energies)})
    summary = write_result(Path(out), scene, r.disc, r)
    return 0 if summary.get("converged") else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
