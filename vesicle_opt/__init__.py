"""vesicle_opt: equilibrium vesicle shapes with the phase-field bending model as constrained
minimisation (energy (3)/(6), constraints (4)-(5)/(7)-(8) of the reference paper).

    import vesicle_opt as vo
    scene = vo.load_scene("ellipse-2d", ["mesh.n=64"])     # a bundled scene, or a TOML path
    result = vo.solve(scene)                               # the one front door; certified Result
    print(result.converged, result.outcome, result.energy)
    run = vo.flow(scene)                                   # a gradient flow (17)/(18)/(23) in memory
    print(run.status, run.steps, run.t, run.energy)

``solve`` dispatches to the IPOPT backend (``vesicle_opt.nlp``) or the matrix-free Newton-Krylov
backend (``vesicle_opt.nk``); ``build_nlp(scene).as_dict()`` is the raw CasADi NLP. ``flow`` runs
``scene.flow`` with trackers for output, progress, checkpoints and stop criteria
(``vesicle_opt.flows.trackers``); ``run_study(name, out, quick)`` runs one of the studies
(``vesicle_opt.studies.STUDIES``); ``branch(scene, param=, to=, step=, out=)`` follows a branch of
equilibria in the reduced volume or c0 (``vesicle_opt.branch``). ``write_result(result, out)``
writes a solve's files as the CLI does, and ``load(dir)`` (``load_result``, ``load_flow``,
``load_branch``, ``load_study``) reads any verb's output directory back (``vesicle_opt.readback``).
"""

from vesicle_opt.api import solve
from vesicle_opt.branch import Branch, branch
from vesicle_opt.io.files import package_version
from vesicle_opt.errors import InfeasibleError, InputError, NotSupported, SolverError, VesicleError
from vesicle_opt.nk.options import NewtonKrylovOptions
from vesicle_opt.nlp import NLP, IpoptOptions, build_nlp
from vesicle_opt.result import Result, Status
from vesicle_opt.scene import Scene, load as load_scene
from vesicle_opt.studies import run_study

__version__ = package_version()

# ``flow`` and ``FlowResult`` load the flows package with their first use (PEP 562): a solve does
# not need it (0.02-0.03 s of every CLI run's start-up, measured). ``branch`` stays eager: its
# name is also the subpackage's, which an import would rebind on this module.
_LAZY = {"flow": "vesicle_opt.flows.api", "FlowResult": "vesicle_opt.flows.api",
         # output directories read back, and a solve's files written from Python (readback)
         "load": "vesicle_opt.readback", "load_result": "vesicle_opt.readback",
         "load_flow": "vesicle_opt.readback", "load_branch": "vesicle_opt.readback",
         "load_study": "vesicle_opt.readback", "write_result": "vesicle_opt.readback",
         "FlowRecord": "vesicle_opt.readback", "StudyRecord": "vesicle_opt.readback"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib  # the lazy attributes above only
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'vesicle_opt' has no attribute {name!r}")

__all__ = ["__version__", "solve", "branch", "Branch", "flow", "FlowResult", "run_study", "load_scene", "Scene", "build_nlp", "NLP",
           "IpoptOptions", "NewtonKrylovOptions", "Result", "Status", "VesicleError", "InputError",
           "InfeasibleError", "NotSupported", "SolverError", "load", "load_result", "load_flow",
           "load_branch", "load_study", "write_result", "FlowRecord", "StudyRecord"]


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
