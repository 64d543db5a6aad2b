"""The package's import structure, from its source alone (``ast``; see ``_imports.py`` for the rules).

Three properties, each failing with the offending modules and lines:

1. no import cycle: the module graph of ``vesicle_opt/`` (every intra-package import, module-level
   and function-local alike; ``from pkg import name`` is an edge to ``pkg.name`` when that is a
   module, else to ``pkg``) has no strongly connected component of more than one module. This is
   stricter than the shared ``import_graph.py`` tool, which forgives components formed with a
   package's ``__init__``: here a submodule importing from its own package's ``__init__`` while that
   ``__init__`` imports it is a cycle too (it works only by import order).
2. privacy: no private name (one leading underscore, not a dunder) is imported from another module
   of the package; a private *module* (``studies/_common.py``) is private to its subpackage and may
   be imported only by modules of that subpackage.
3. function-local intra-package imports are the exception, and each says why. The rule: every one
   has a ``#`` comment, on one of the statement's own lines or on the line just above it, of at
   least three words that is not only a tool pragma (``noqa``, ``type: ignore``, ``pragma``,
   ``pylint``, ``fmt``). The comments are the allow-list, kept next to the code they excuse; the
   failure message lists every import without one.
"""

from __future__ import annotations

import re

import pytest

import _imports as I

PRAGMA = re.compile(r"^\s*(noqa|type:\s*ignore|pragma|pylint|fmt)\b.*$", re.I)


def _private(name: str | None) -> bool:
    return bool(name) and name.startswith("_") and not name.startswith("__")


def _subpackage(module: str) -> str:
    return module.rsplit(".", 1)[0]


def test_the_source_is_found():
    """The graph is built from this checkout's vesicle_opt/, and it is not empty."""
    mods = I.modules()
    assert I.PACKAGE in mods and "vesicle_opt.api" in mods and len(mods) > 20
    assert any(i.target == "vesicle_opt.errors" for i in I.imports())


def test_resolution_rules(tmp_path):
    """The rules of _imports.py on a toy package: relative imports, module-vs-name, locality."""
    pkg = tmp_path / "toy"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from toy.sub import helper\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "helper.py").write_text("from .. import other\nfrom . import VALUE\n")
    (pkg / "other.py").write_text("import toy.sub.helper as h\n\ndef f():\n    from toy.sub import _x  # why\n")
    edges = I.graph(pkg)
    assert edges["toy"] == {"toy.sub.helper"}
    assert edges["toy.sub.helper"] == {"toy.other", "toy.sub"}
    assert edges["toy.other"] == {"toy.sub.helper", "toy.sub"}
    assert I.strongly_connected(edges) == [["toy.other", "toy.sub.helper"]]
    local = [i for i in I.imports(pkg) if i.local]
    assert [(i.module, i.target, i.name, i.line) for i in local] == [("toy.other", "toy.sub", "_x", 4)]


def test_no_import_cycles():
    sccs = I.strongly_connected(I.graph())
    if sccs:
        imps = I.imports()
        lines = []
        for comp in sccs:
            members = set(comp)
            lines.append("cycle: " + ", ".join(comp))
            lines += [f"    {i.where()}: {i.module} -> {i.target}" for i in imps
                      if i.module in members and i.target in members]
        pytest.fail("import cycles inside the package:\n" + "\n".join(lines))


def test_no_private_names_imported_across_modules():
    bad = []
    for i in I.imports():
        if not i.name_is_module and _private(i.name):
            bad.append(f"{i.where()}: {i.module} imports the private name {i.name} from {i.target}")
        # a private module (any private part of the imported module's dotted name: import a._b,
        # from a._b import c, from a import _b) only from inside the package that holds it
        parts = i.target.split(".")
        for k, part in enumerate(parts):
            owner = ".".join(parts[:k])
            if _private(part) and not (i.module == owner or i.module.startswith(owner + ".")):
                bad.append(f"{i.where()}: {i.module} imports the private module "
                           f"{'.'.join(parts[:k + 1])} from outside {owner}")
    assert not bad, "private names imported across modules:\n" + "\n".join(sorted(set(bad)))


def _reason(comments: dict[int, tuple[str, bool]], first: int, last: int) -> str | None:
    """The reason comment of the statement on lines first..last: a comment on one of them, or a
    comment-only line just above (a trailing comment of the code above belongs to that code)."""
    for line in (first - 1, *range(first, last + 1)):
        text, alone = comments.get(line, ("", False))
        if line == first - 1 and not alone:
            continue
        if len(text.split()) >= 3 and not PRAGMA.match(text):
            return text
    return None


def function_local_imports() -> list[tuple[I.Import, str | None]]:
    """(statement, its reason comment or None), one entry per import statement."""
    seen, out, cache = set(), [], {}
    for i in I.imports():
        if not i.local or (i.path, i.line) in seen:
            continue
        seen.add((i.path, i.line))
        comments = cache.setdefault(i.path, I.comments(i.path))
        out.append((i, _reason(comments, i.line, i.end_line)))
    return sorted(out, key=lambda pair: (str(pair[0].path), pair[0].line))


def test_function_local_imports_give_a_reason():
    missing = [f"{i.where()}: {i.path.read_text().splitlines()[i.line - 1].strip()}"
               for i, why in function_local_imports() if why is None]
    assert not missing, (f"{len(missing)} function-local intra-package imports without a reason "
                         "comment (same or previous line; see the module docstring):\n" + "\n".join(missing))


def test_reason_rule(tmp_path):
    """The comment rule itself: previous or same line, three words, pragmas do not count."""
    pkg = tmp_path / "toy"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("")
    (pkg / "b.py").write_text(
        "def f():\n"
        "    # a cycle otherwise: a imports b\n"
        "    from toy import a\n"
        "def g():\n"
        "    from toy import a  # noqa: E402 F401\n"
        "def h():\n"
        "    from toy import (a)  # heavy matplotlib import deferred\n"
        "def k():\n"
        "    s = '# not a comment at all'; from toy import a\n"
        "def m():\n"
        "    x = 1  # the comment of x = 1\n"
        "    from toy import a\n")
    found = []
    for i in I.imports(pkg):
        if i.local:
            found.append(_reason(I.comments(i.path), i.line, i.end_line))
    assert found == ["a cycle otherwise: a imports b", None, "heavy matplotlib import deferred", None, None]
