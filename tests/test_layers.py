"""The layer order of the package is a test (from the source, ``ast``: see ``_imports.py``).

Bottom to top (a unit is a top-level module or subpackage of ``vesicle_opt``):

    0  errors, result,       the vocabulary every layer speaks (extras: whether the optional
       extras,               extras load, errors only)
       geometry, sharp,      (geometry: volume, area, reduced volume <-> alpha, beta; sharp: the
       blas, sums            sharp-interface references, which import nothing of the package;
                             blas: in-place vector updates of the hot loops, numpy/scipy only;
                             sums: compensated sums of fields, numpy only)
    1  scene                 TOML scenes, validated
    2  mesh                  discretisations
    3  model                 functionals, penalty, feasibility on a discretisation
    4  verify, resources     certification, KKT, second order, topology | the memory guard
    5  nlp | nk | nk_jax     the two solver backends; neither imports the other (nk_jax: nk's
                             arrays on JAX, imports nk's options/setup, nk never imports it)
    6  flows                 gradient flows (may use a backend's NLP pieces)
    7  api, backends         the front door and its backend table (api -> backends only)
    8  branch                branches of equilibria (continuation over the front door), energy diagrams
    9  studies, readback     the studies and their registry | output directories read back
   10  cli                   the command line (argparse; the study verb uses the registry)
   11  vesicle_opt           the package's public namespace (__init__); nothing inside imports it
   12  __main__              ``python -m vesicle_opt`` (the CLI's main)

``io`` stands aside: anyone may import it, and it imports nothing of the package but errors and
result. Every intra-package import (module-level and function-local; ``cli``'s
studies' registry ``importlib.import_module`` of a study is dynamic and not seen, and points
sideways within ``studies``) must point strictly down, or sideways within one unit (``nlp.solve`` -> ``nlp.exact``). An
import that breaks the order and cannot be fixed at once goes into ``ALLOWED`` with its reason, so
the list shows what remains to fix; an entry that no longer occurs fails too.
"""

from __future__ import annotations

import _imports as I

LAYERS = {
    "errors": 0, "result": 0, "extras": 0, "geometry": 0, "sharp": 0, "blas": 0, "sums": 0,
    "scene": 1,
    "mesh": 2,
    "model": 3,
    "verify": 4, "resources": 4,
    "nlp": 5, "nk": 5, "nk_jax": 5,
    "flows": 6,
    "api": 7, "backends": 7,
    "branch": 8,
    "studies": 9, "readback": 9, "cli": 10,
    "": 11,  # vesicle_opt/__init__.py
    "__main__": 12,  # python -m vesicle_opt: runs the CLI
}
FREE = "io"  # imported by anyone; imports only errors and result
IO_MAY_IMPORT = {"errors", "result"}
# (importing module, imported module) -> why it is still there. None at main 6e1c74d.
ALLOWED: dict[tuple[str, str], str] = {}
# units of one layer that may import each other, one way (otherwise one layer means independent)
SIDEWAYS = {("api", "backends"): "the front door consults its own support table",
            ("nk_jax", "nk"): "the JAX arrays reuse nk's options, setup and constants (never back)",
            ("extras", "errors"): "an extra that does not load is refused with the package's InputError"}


def unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def violation(src: str, dst: str) -> str | None:
    """Why the import src -> dst breaks the order (None when it does not)."""
    a, b = unit(src), unit(dst)
    if a == b:
        return None  # sideways within a unit
    if a == FREE:
        return None if b in IO_MAY_IMPORT else f"io imports only {', '.join(sorted(IO_MAY_IMPORT))}"
    if b == FREE:
        return None
    if (a, b) in SIDEWAYS:
        return None
    la, lb = LAYERS[a], LAYERS[b]
    if lb < la:
        return None
    return (f"'{a or 'vesicle_opt'}' (layer {la}) imports '{b or 'vesicle_opt'}' (layer {lb}): "
            + ("sideways across units of one layer" if la == lb else "upwards"))


def test_every_unit_has_a_layer():
    units = {unit(m) for m in I.modules()}
    assert units <= set(LAYERS) | {FREE}, f"place these in LAYERS: {sorted(units - set(LAYERS) - {FREE})}"
    assert {"errors", "result", "scene", "mesh", "model", "verify", "nlp", "nk", "flows", "api", "io",
            "branch", "studies", "cli"} <= units


def test_the_rule():
    """The order itself, on a few edges (so a broken rule does not pass everything)."""
    P = "vesicle_opt."
    assert violation(P + "nlp.solve", P + "verify.certify") is None  # down
    assert violation(P + "nlp.solve", P + "nlp.exact") is None  # sideways within nlp
    assert violation(P + "mesh.fd", P + "io.output") is None  # io by anyone
    assert violation(P + "verify.kkt", P + "nlp.exact")  # up
    assert violation(P + "nk.solve", P + "nlp.ipopt")  # nlp | nk
    assert violation(P + "nlp.solve", P + "nk.solve")
    assert violation(P + "nk_jax.solver", P + "nk.setup") is None and violation(P + "nk.solve", P + "nk_jax.ops")
    assert violation(P + "nk_jax.solver", P + "nlp.exact")
    assert violation(P + "studies.table1", P + "cli")  # cli on top of studies
    assert violation(P + "branch.run", P + "api") is None and violation(P + "api", P + "branch.run")
    assert violation(P + "studies.energy_diagram", P + "branch") is None
    assert violation(P + "branch.run", P + "studies.runner")  # branch below the studies
    assert violation(P + "cli", P + "studies") is None
    assert violation(P + "io.output", P + "scene.schema")  # io imports only errors, result
    assert violation(P + "io.output", P + "result") is None
    assert violation(P + "cli", "vesicle_opt")  # the public namespace is on top
    assert violation("vesicle_opt", P + "api") is None
    assert violation(P + "api", P + "backends") is None and violation(P + "backends", P + "api")


def test_imports_point_down():
    found: dict[tuple[str, str], list[str]] = {}
    bad = []
    for i in I.imports():
        why = violation(i.module, i.target)
        if why is None:
            continue
        found.setdefault((i.module, i.target), []).append(i.where())
        if (i.module, i.target) not in ALLOWED:
            bad.append(f"{i.where()}: {i.module} -> {i.target}: {why}")
    stale = [f"{edge}: {reason}" for edge, reason in ALLOWED.items() if edge not in found]
    assert not bad, "imports against the layer order (module docstring):\n" + "\n".join(sorted(set(bad)))
    assert not stale, "ALLOWED entries that no longer occur (remove them):\n" + "\n".join(stale)


def test_nlp_and_nk_are_independent():
    """Restated on its own, since it is the point of having two backends."""
    edges = [(i.where(), i.module, i.target) for i in I.imports()
             if {unit(i.module), unit(i.target)} in ({"nlp", "nk"}, {"nlp", "nk_jax"})]
    assert not edges, edges


def test_sharp_references_share_no_code_with_the_phase_field_path():
    """vesicle_opt.sharp imports nothing of the package (not even layer 0), so its references are
    independent of everything they check."""
    edges = [(i.where(), i.target) for i in I.imports() if unit(i.module) == "sharp" and unit(i.target) != "sharp"]
    assert not edges, edges
    assert "sharp" in {unit(m) for m in I.modules()}  # the check sees the unit
