"""Branches of equilibria and energy diagrams (issue: energy diagrams), above the front door.

    import vesicle_opt as vo
    scene = vo.load_scene("my-2d.toml")                    # constraints.reduced_volume + area
    b = vo.branch(scene, param="reduced_volume", to=0.5, step=-0.0175, out="out/branch")
    for r in b.points(): print(r["reduced_volume"], r["reduced_energy"], r["second_order"])

* ``params``: the parameters (reduced volume at fixed area, c0) and their envelope terms;
* ``arclength``: predictor (secant), corrector (natural / pseudo-arclength), step control; generic;
* ``corrector``: the fixed-p IPOPT corrector built once per branch (parametric NLP, one solver,
  warm multipliers, the matrix-free second-order check with the rotation removed on FD grids);
* ``bordered``: Newton on the KKT system bordered by the arclength equation, p free (passes folds),
  or at fixed p (the IPOPT corrector's fallback);
* ``store``: branch.csv, the snapshots and the resume after a kill;
* ``run``: ``branch(...)`` and its frozen result ``Branch``;
* ``events``: index changes along a branch located (Illinois in p, or on the chord with p free) and
  classified (fold or branch point); ``switch``: the first point of a bifurcating branch and the
  recognition of a known branch (``symmetry``: the grid's images of a field); ``deflation``: other
  roots at the same parameter (Farrell et al. 2015); ``detour``: a disconnected branch reached by a
  detour in a second parameter (out until unstable, a push along the critical mode, back);
  ``emanate``: a bifurcating branch followed from its branch point by pseudo-arclength to a target p
  (switch on the amplitude hyperplane, a guard per point); ``tree``: the recursive diagram, on a
  ``problem`` (``problem``: the rows side; ``vesicle``: the vesicle's correctors); ``lines``: fold
  lines in a second parameter by sweeps of diagrams; ``symmetric_fold`` (a symmetric turn) and
  ``ordinary_fold`` (a fold by its index change; ``ordinary_fold_vesicle.from_branch(b, second,
  values, kind=)`` picks either for a walked run): a fold continued in a second parameter;
* ``crossing``: where two branches cross (cubic splines) and its eps -> 0 extrapolation;
* ``transition``: that crossing continued in a second parameter (a first-order transition line,
  e.g. prolate/oblate in (v, c0)); ``transition_store``: its CSV and fields, resumed;
  ``transition_vesicle``: ``transition_line(scene_a, scene_b, "c0", values, to=, step=, out=)``;
  ``refined_corrector``: its points on interface-refined meridian meshes, the band following each;
  ``phase_figure``: the (v, c0) phase-diagram PNG;
* ``diagram``: the energy-diagram PNG (matplotlib is imported there only).
"""

import sys as _sys
import types as _types

from vesicle_opt.branch.params import PARAMS
from vesicle_opt.branch.run import Branch, branch
from vesicle_opt.branch.store import COLUMNS
from vesicle_opt.branch.transition_vesicle import Line, transition_line

__all__ = ["PARAMS", "COLUMNS", "Branch", "branch", "Line", "transition_line"]


def _submodule(package, name: str, value) -> bool:
    return isinstance(value, _types.ModuleType) and value.__name__ == f"{package.__name__}.{name}"


class _Package(_types.ModuleType):
    """This package: ``vesicle_opt.branch`` is the ``branch`` function (``vesicle_opt._Package``), and
    ``import vesicle_opt.branch.run as r`` takes ``run`` as an attribute of that (Python's
    ``import a.b.c as d`` walks attributes from ``a``), so each submodule bound here is bound on the
    function too."""

    def __setattr__(self, name, value):
        super().__setattr__(name, value)
        if _submodule(self, name, value):
            setattr(branch, name, value)


for _name, _value in list(vars(_sys.modules[__name__]).items()):  # those loaded above, before the class
    if _submodule(_sys.modules[__name__], _name, _value):
        setattr(branch, _name, _value)
_sys.modules[__name__].__class__ = _Package
