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

import sys as _sys
import types as _types

# Every public name loads its module with its first use (PEP 562), so ``import vesicle_opt`` (and the
# CLI's entry, which installs its interrupt handling first: ``cli.run``) costs no numpy, scipy or
# solver import: it was 0.6 s, inside which a Ctrl-C printed a KeyboardInterrupt traceback.
_LAZY = {"solve": "vesicle_opt.api", "Branch": "vesicle_opt.branch", "branch": "vesicle_opt.branch",
         "package_version": "vesicle_opt.io.files",
         **dict.fromkeys(("InfeasibleError", "InputError", "NotSupported", "SolverError", "VesicleError"),
                         "vesicle_opt.errors"),
         "NewtonKrylovOptions": "vesicle_opt.nk.options",
         **dict.fromkeys(("NLP", "IpoptOptions", "build_nlp"), "vesicle_opt.nlp"),
         "Result": "vesicle_opt.result", "Status": "vesicle_opt.result",
         "Scene": "vesicle_opt.scene", "load_scene": "vesicle_opt.scene", "run_study": "vesicle_opt.studies",
         "flow": "vesicle_opt.flows.api", "FlowResult": "vesicle_opt.flows.api",
         # output directories read back, and a solve's files written from Python (readback)
         **dict.fromkeys(("load", "load_result", "load_flow", "load_branch", "load_study", "write_result",
                          "FlowRecord", "StudyRecord"), "vesicle_opt.readback")}
_SOURCE_NAME = {"load_scene": "load"}  # the name in its module, where it differs


def __getattr__(name: str):
    if name == "__version__":
        value = __getattr__("package_version")()
    elif name in _LAZY:
        import importlib  # the lazy attributes above only
        value = getattr(importlib.import_module(_LAZY[name]), _SOURCE_NAME.get(name, name))
    else:
        raise AttributeError(f"module 'vesicle_opt' has no attribute {name!r}")
    globals()[name] = value
    return value


class _Package(_types.ModuleType):
    """``vesicle_opt`` itself: the import system binds each loaded subpackage on its parent, and would
    bind the ``branch`` subpackage over the ``branch`` function; that one binding is dropped, so
    ``vesicle_opt.branch`` is the function whatever was imported first (``vesicle_opt.branch.run``
    and ``from vesicle_opt.branch import ...`` read ``sys.modules`` and still work)."""

    def __setattr__(self, name, value):
        if name == "branch" and isinstance(value, _types.ModuleType):
            return
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package

__all__ = ["__version__", "solve", "branch", "Branch", "flow", "FlowResult", "run_study", "load_scene", "Scene", "build_nlp", "NLP",
           "IpoptOptions", "NewtonKrylovOptions", "Result", "Status", "VesicleError", "InputError",
           "InfeasibleError", "NotSupported", "SolverError", "load", "load_result", "load_flow",
           "load_branch", "load_study", "write_result", "FlowRecord", "StudyRecord"]


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | {"__version__"})
