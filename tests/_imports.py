"""The package's own import statements, read from its source with ``ast`` (nothing is imported or run).

Used by ``test_import_cycles.py`` and ``test_layers.py``. The package is found next to this file
(``../vesicle_opt``), so the tests need nothing outside the repository.

Resolution rules (those of the shared ``import_graph.py`` tool, restated so the tests do not
depend on it):

* a module's name is its dotted path; ``pkg/__init__.py`` is ``pkg``;
* ``import a.b.c`` imports the module ``a.b.c``;
* ``from a.b import name`` imports ``a.b.name`` when that is a module of the package, else ``a.b``;
  relative imports are resolved against the importing module;
* only targets that are modules of the package are kept (an intra-package import), and a module
  importing itself is dropped;
* an import is *function-local* when it sits anywhere inside a ``def`` (nested blocks included).

Implicit imports of parent packages (importing ``a.b.c`` runs ``a/__init__`` and ``a/b/__init__``)
are not edges: they would put every package ``__init__`` that imports its submodules on a cycle.
"""

from __future__ import annotations

import ast
import io
import tokenize
from dataclasses import dataclass
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent.parent / "vesicle_opt"
PACKAGE = PACKAGE_DIR.name


@dataclass(frozen=True)
class Import:
    module: str  # the importing module
    path: Path
    line: int  # first line of the statement
    end_line: int
    target: str  # the imported module of the package
    name: str | None  # for ``from X import name``: the name as written; None for ``import X``
    name_is_module: bool  # ``from X import name`` where X.name is a module
    local: bool  # inside a function body

    def where(self) -> str:
        return f"{self.path.relative_to(PACKAGE_DIR.parent)}:{self.line}"


def modules(package_dir: Path = PACKAGE_DIR) -> dict[str, Path]:
    out = {}
    for f in sorted(package_dir.rglob("*.py")):
        parts = list(f.relative_to(package_dir.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


def _resolve(module: str, is_pkg: bool, level: int, name: str | None) -> str:
    if level == 0:
        return name or ""
    base = module.split(".") if is_pkg else module.split(".")[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def _function_nodes(tree: ast.AST) -> set[int]:
    inside: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            inside.update(id(sub) for sub in ast.walk(node) if sub is not node)
    return inside


def imports(package_dir: Path = PACKAGE_DIR) -> list[Import]:
    """Every intra-package import of the package (one entry per imported module and name)."""
    mods = modules(package_dir)
    out: list[Import] = []
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        local = _function_nodes(tree)
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(tree):
            found: list[tuple[str, str | None, bool]] = []
            if isinstance(node, ast.Import):
                found = [(a.name, None, False) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(mod, is_pkg, node.level, node.module)
                for a in node.names:
                    cand = f"{base}.{a.name}"
                    found.append((cand, a.name, True) if cand in mods else (base, a.name, False))
            for target, name, name_is_module in found:
                if target in mods and target != mod:
                    out.append(Import(mod, path, node.lineno, node.end_lineno or node.lineno, target,
                                      name, name_is_module, id(node) in local))
    return out


def graph(package_dir: Path = PACKAGE_DIR) -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {m: set() for m in modules(package_dir)}
    for imp in imports(package_dir):
        edges[imp.module].add(imp.target)
    return edges


def strongly_connected(edges: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative), those with more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    comps: list[list[str]] = []
    counter = 0
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            advanced = False
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges[w]))))
                    advanced = True
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    comps.append(sorted(comp))
    return comps


def comments(path: Path) -> dict[int, tuple[str, bool]]:
    """line -> (the text of the ``#`` comment on that line, whether the line is that comment alone);
    from tokenize, so a '#' inside a string is no comment."""
    out: dict[int, tuple[str, bool]] = {}
    for tok in tokenize.generate_tokens(io.StringIO(path.read_text()).readline):
        if tok.type == tokenize.COMMENT:
            alone = tok.line[: tok.start[1]].strip() == ""
            out[tok.start[0]] = (tok.string.lstrip("#").strip(), alone)
    return out
