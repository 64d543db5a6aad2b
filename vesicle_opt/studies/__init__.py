"""The studies: reproducible numerical experiments, each a module with ``main(out, quick)``.

    import vesicle_opt as vo
    vo.run_study("table1", "out/table1", quick=True)       # == vesicle-opt study table1 --out ... --quick

``STUDIES`` is the registry (the names ``vesicle-opt study --list`` prints, with the one-line
``DESCRIPTIONS``); ``study(name)`` imports
one (``-`` or ``_`` in the name), ``run_study`` runs it. The other modules here serve the studies
and are not studies: ``runner`` (one resumable CSV writer over any executor), ``_common`` and
``_flowkit`` (shared helpers), ``_meridian``, ``_stomatocyte``, ``_hlevel`` and ``_pd_figure`` (the cases, h-levels and figure of ``phase_diagram``), ``bare_casadi`` (the hand-written CasADi baseline of the benchmarks).
Studies are imported by name on demand, so importing ``vesicle_opt`` loads none of them.
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path
from types import ModuleType

from vesicle_opt.errors import InputError
from vesicle_opt.io import outdir

# one line each for ``vesicle-opt study --list`` (the module docstring is the long form: ``study NAME --help``)
DESCRIPTIONS = {
    "bench_axisymmetric": "warm branch points on a refined meridian mesh: CPU and wall per point, old against new",
    "bench_branch_3d": "a warm 3D branch point's cost against the grid (octant mirror grids, eps ~ h): CPU, DCTs, Newton/GMRES, check",
    "bench_3d": "large-3D path: time, memory, Newton and CG counts against n (torus, NK backend)",
    "bench_jax": "the Newton-Krylov path on JAX: numpy against one and two devices (and a GPU if any)",
    "bench_methods": "every solver.method in its defaults on every bundled scene: exit, outcome, cost against exact",
    "bench_certificate": "the second-order certificate against the solve: time, memory, verdict (torus, NK)",
    "bench_equilibrium": "IPOPT exact solve: iterations, time, Hessian nnz, memory against mesh size",
    "bench_stationarity": "the stationarity certificate against n: L2 and natural-norm floors and residuals (NK)",
    "bench_overhead": "cost of the abstractions: bare CasADi model against build_nlp + solve",
    "crossing_3d": "3D prolate/oblate crossing on mirror (octant) grids: v and reduced energy per eps, eps -> 0",
    "diagonal": "Theorem 3.4: h -> 0 and M -> inf together; the rule M(h)",
    "energy_decay": "Figure 3 analogue: log(E_M - E_min) against t for k and k/2 (scheme (18))",
    "energy_diagram": "branches of equilibria in reduced volume: 2D elastica, 3D prolate/oblate, their crossing",
    "flow_vs_nlp": "flows (17), (18), (23) against the NLP: time to reach the equilibrium",
    "h_refinement": "Theorem 3.3 / Corollary 3.2: convergence of the minimisers as h -> 0",
    "phase_diagram": "spontaneous-curvature diagram on the meridian: c0 = 0 prolate/oblate per eps, crossing, eps -> 0",
    "penalty_continuation": "Theorem 3.2: penalty minimisers approach the constrained one as M -> inf",
    "penalty_vs_exact": "work-precision: exact, penalty, continuation, augmented, SCP baseline",
    "sharp_limit": "the eps -> 0 limit: 2D reduced energies at eps, eps/2, eps/4 against the sharp elastica",
    "stress": "stiff and extreme cases: each a verified solution or an honest failure",
    "table1": "Table 1 of the paper: the Section 5 torus on 16^3 ... 64^3 spectral grids",
    "time_step_convergence": "Theorems 4.2-4.4: observed orders of the flows in the time step k",
    "torus_section5": "Section 5 by the gradient flow: a flat disk pinches into a torus (Figures 1-2)",
}
STUDIES = tuple(sorted(DESCRIPTIONS))  # the registry: a study is registered by its description
NOT_STUDIES = ("_common", "_escape", "_flowkit", "_hlevel", "_landing", "_meridian", "_pd_figure", "_pear",
               "_same_state", "_stomatocyte", "runner", "bare_casadi")


def study(name: str) -> ModuleType:
    """The module of a registered study (``-`` and ``_`` are the same); InputError naming ``study``
    and the allowed names otherwise."""
    key = str(name).replace("-", "_")
    if key not in STUDIES:
        raise InputError("study", f"unknown study {name!r}; one of {', '.join(STUDIES)}")
    return importlib.import_module(f"{__name__}.{key}")


def docstring(name: str) -> str:
    """The long description of a study (its module docstring), for ``vesicle-opt study NAME --help``."""
    return (study(name).__doc__ or DESCRIPTIONS[str(name).replace("-", "_")]).strip()


def takes(name: str, keyword: str) -> bool:
    """Whether the study's ``main`` takes ``keyword`` (``workers``: its cases run on a local pool of
    that many processes; ``executor``: on any ``concurrent.futures.Executor``)."""
    return keyword in inspect.signature(study(name).main).parameters


def check_workers(name: str, workers, key: str = "workers") -> int:
    """``workers`` as an int >= 1 for a study whose cases run in parallel; InputError (``key``)
    otherwise, before any work."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(key, f"allowed: an integer >= 1 (local worker processes), got {workers!r}")
    if workers > 1 and not takes(name, "workers"):
        names = ", ".join(n for n in STUDIES if takes(n, "workers"))
        raise InputError(key, f"the study {name} runs in one process; parallel studies: {names}")
    return workers


def run_study(name: str, out: str | Path, quick: bool = False, workers: int | None = None,
              scheduler: str | None = None, **kwargs) -> int:
    """Run a study into the directory ``out``: ``main(out, quick, **kwargs)`` of ``study(name)``
    (some take more keywords, e.g. ``executor=``); returns its status (0: every check passed).
    ``workers``: local worker processes for a study whose cases run in parallel (``check_workers``);
    ``scheduler``: a dask scheduler's address (the ``dask`` extra), whose workers run the cases
    (``runner.dask_executor``; for a study that takes an ``executor``). An ``out`` that cannot be a
    directory (``io.outdir.check``), a bad ``workers`` or ``scheduler`` is an InputError before any work."""
    mod = study(name)  # an unknown name is refused before the directory is made
    if not isinstance(quick, bool):
        raise InputError("quick", f"expected True or False, got {type(quick).__name__}")
    if workers is not None:
        kwargs["workers"] = check_workers(name, workers)
        if not takes(name, "workers"):  # workers = 1: what the study does anyway
            del kwargs["workers"]
    if scheduler is None:
        return int(mod.main(outdir.check(out, "out"), quick=quick, **kwargs) or 0)
    from vesicle_opt.studies.runner import dask_executor  # the runner loads with the studies that run cases

    if not takes(name, "executor") or "executor" in kwargs or workers not in (None, 1):
        raise InputError("scheduler", f"the study {name} takes no executor" if not takes(name, "executor")
                         else "give a scheduler or an executor / workers, not both")
    target = outdir.check(out, "out")
    with dask_executor(scheduler) as executor:
        return int(mod.main(target, quick=quick, executor=executor, **kwargs) or 0)
