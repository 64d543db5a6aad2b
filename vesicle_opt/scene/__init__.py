"""Scenes: one equilibrium problem as plain, validated data (Dedalus style: solvers are built from it).

* ``schema``: the frozen sections (domain, mesh, model, constraints, initial, solver, flow), the key
  table ``SCHEMA`` (kept in ``keys``) and validation (``from_dict``, ``load``, ``--set`` overrides);
* ``shape_spec``: shape tables (``initial``, ``constraints.target``); ``shapes``: their phase fields;
* ``bundled``: the scenes shipped inside the package, loaded by name.
"""

from vesicle_opt.scene import bundled
from vesicle_opt.scene.schema import (SCHEMA, Constraints, Domain, Flow, Mesh, Model, Scene, Solver,
                                      apply_overrides, from_dict, load, parse_value)
from vesicle_opt.scene.shape_spec import SHAPE_KEYS, SHAPES, Shape

__all__ = ["SCHEMA", "Constraints", "Domain", "Flow", "Mesh", "Model", "Scene", "Solver", "Shape",
           "SHAPES", "SHAPE_KEYS", "apply_overrides", "bundled", "from_dict", "load", "parse_value"]
