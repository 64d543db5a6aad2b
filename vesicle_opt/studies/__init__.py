"""The studies: reproducible numerical experiments, each a module with ``main(out, quick)``.

    import vesicle_opt as vo
    vo.run_study("table1", "out/table1", quick=True)       # == vesicle-opt study table1 --out ... --quick

``STUDIES`` is the registry (the names ``vesicle-opt study --list`` prints); ``study(name)`` imports
one (``-`` or ``_`` in the name), ``run_study`` runs it. The other modules here serve the studies
and are not studies: ``runner`` (one resumable CSV writer over any executor), ``_common`` and
``_flowkit`` (shared helpers), ``bare_casadi`` (the hand-written CasADi baseline of the benchmarks).
Studies are imported by name on demand, so importing ``vesicle_opt`` loads none of them.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from types import ModuleType

from vesicle_opt.errors import InputError

STUDIES = ("bench_3d", "bench_certificate", "bench_equilibrium", "bench_overhead", "diagonal", "energy_decay", "flow_vs_nlp",
           "h_refinement", "penalty_continuation", "penalty_vs_exact", "stress", "table1",
           "time_step_convergence", "torus_section5")
NOT_STUDIES = ("_common", "_flowkit", "runner", "bare_casadi")


def study(name: str) -> ModuleType:
    """The module of a registered study (``-`` and ``_`` are the same); InputError naming ``study``
    and the allowed names otherwise."""
    key = str(name).replace("-", "_")
    if key not in STUDIES:
        raise InputError("study", f"unknown study {name!r}; one of {', '.join(STUDIES)}")
    return importlib.import_module(f"{__name__}.{key}")


def run_study(name: str, out, quick: bool = False, **kwargs) -> int:
    """Run a study into the directory ``out``: ``main(out, quick, **kwargs)`` of ``study(name)``
    (some take more keywords, e.g. ``executor=``); returns its status (0: every check passed)."""
    return int(study(name).main(Path(out), quick=quick, **kwargs) or 0)
