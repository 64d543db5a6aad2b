"""vesicle_opt: equilibrium vesicle shapes with the phase-field bending model as constrained
minimisation (energy (3)/(6), constraints (4)-(5)/(7)-(8) of the reference paper).

    from vesicle_opt import load_scene, build_nlp
    from vesicle_opt.solve import solve
    scene = load_scene("problems/ellipse-2d.toml", ["mesh.n=64"])
    result = solve(build_nlp(scene))
"""

from .errors import InfeasibleError, InputError, SolverError, VesicleError
from .nlp import NLP, build_nlp
from .result import Result
from .scene import Scene, load as load_scene
from .solve import IpoptOptions  # the function solve stays in vesicle_opt.solve (module name)

__all__ = ["load_scene", "Scene", "build_nlp", "NLP", "IpoptOptions", "Result",
           "VesicleError", "InputError", "InfeasibleError", "SolverError"]
