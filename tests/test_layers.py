"""The layer rule (docs/architecture.md): a module imports only from lower layers (lazily or
not), never another module's private names, and never reads ``obj._attr`` of an object
defined elsewhere.  A new module gets its layer here."""
from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "mbcomp"
#: Layer of each folder of the package (docs/architecture.md): a module imports only from the
#: folders of lower layers, and freely from its own folder.  The root holds only ``__init__``.
LAYERS = {
    "core": 0,          # plain data and helpers without model knowledge: errors, rotations, params, Result
    "spec": 1,          # what users write: components, the model builder, sub-models, shapes
    "build": 2,         # spec -> flat model -> topology -> symbolic program; layouts
    "files": 3,         # model files (TOML, URDF) <-> models; the library
    "codegen": 4,       # printers, C templates, compilers, the cache
    "compiled": 5,      # the compiled model and its numeric kernel
    "formulations": 6,  # how constraints and contacts enter (lagrange, dae, impacts)
    "run": 7,           # time stepping, events, sweeps, derived series
    "analysis": 8,      # equilibrium, linearisation, modes, Jacobians, inverse dynamics
    "api": 9,           # the public System facade
    "face": 10,         # user-facing output: command line, plots, the 3D viewer
    "__init__": 11,     # the package: re-exports everything and registers the services
}
#: Private names of a third-party library that a module reads on purpose: ``(file, name)``.
#: Not a layering matter (the rule is about mbcomp's own modules); each is pinned by tests.
THIRD_PARTY: dict[tuple[str, str], str] = {
    ("mbcomp/core/symbolic.py", "_from_args"): "sympy's constructor from canonical arguments "
    "(sympy.core.operations.AssocOp._from_args, which sympy's own code uses for this); "
    "tests/test_symbolic_build.py compares every such construction with sympy's result",
}
#: Known breaches being removed: ``(file, problem)``.  Do not add to this list.
KNOWN: set[tuple[str, str]] = {
    ('mbcomp/build/constraint_set.py', 'reads ._equations, a private name of another module'),
    ('mbcomp/build/equations.py', 'reads ._gap_equation, a private name of another module'),
    ('mbcomp/build/equations.py', 'reads ._loads, a private name of another module'),
    ('mbcomp/build/equations.py', 'reads ._potential, a private name of another module'),
    ('mbcomp/spec/model.py', 'imports mbcomp.build.flatten (layer 2) from layer 1'),
}


def modules() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__" and len(parts) > 1:
            parts.pop()
        out[".".join(parts)] = path
    return out


def layer(name: str) -> int:
    """The layer of module ``name`` (below mbcomp): the layer of its top folder."""
    folder = "__init__" if name == "__main__" else name.split(".")[0]
    if folder not in LAYERS or (folder != "__init__" and "." not in name and not (ROOT / folder).is_dir()):
        raise AssertionError(f"module mbcomp.{name} is in no layer folder: move it into one of {sorted(LAYERS)} "
                             "(tests/test_layers.py)")
    return LAYERS[folder]


@lru_cache(maxsize=None)
def syntax_tree(path: Path) -> ast.Module:
    """The parsed module (each file is parsed once per run: both checks walk it)."""
    return ast.parse(path.read_text(encoding="utf-8"))


def imports(name: str, path: Path, known) -> list[tuple[str, list[str], int]]:
    """``(module, imported names, line)`` for every import of an mbcomp module."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    if name == "__init__":
        package = []
    found = []
    for node in ast.walk(syntax_tree(path)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            elif (node.module or "").startswith("mbcomp"):
                target = node.module[len("mbcomp."):] if node.module != "mbcomp" else ""
            else:
                continue
            names = [a.name for a in node.names]
            for n in names:  # "from . import codegen" imports the module mbcomp.codegen.printer
                sub = f"{target}.{n}" if target else n
                if sub in known:
                    found.append((sub, [], node.lineno))
            if target in known:
                found.append((target, [n for n in names if f"{target}.{n}" not in known], node.lineno))
        elif isinstance(node, ast.Import):
            found += [(a.name[len("mbcomp."):], [], node.lineno) for a in node.names if a.name.startswith("mbcomp.")]
    return found


def own_private_names(tree: ast.AST) -> set[str]:
    """Private names this module defines: functions, classes, assignments, ``self._x = ...``."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "__setattr__" and len(node.args) > 1 \
                and isinstance(node.args[1], ast.Constant):
            names.add(node.args[1].value)  # object.__setattr__(self, "_x", ...) in frozen classes
    return {n for n in names if isinstance(n, str) and n.startswith("_")}


def private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def violations() -> list[tuple[str, int, str]]:
    """``(file, line, problem)`` for every breach of the layer rule."""
    known = modules()
    problems = []
    for name, path in sorted(known.items()):
        where = f"mbcomp/{path.relative_to(ROOT)}"
        tree = syntax_tree(path)
        for target, names, line in imports(name, path, known):
            mine, theirs = layer(name), layer(target)
            if theirs > mine:
                problems.append((where, line, f"imports mbcomp.{target} (layer {theirs}) from layer {mine}"))
            outside = not target.startswith(name.rpartition(".")[0] + ".") or "." not in name
            if any(private(part) for part in target.split(".")) and outside:
                problems.append((where, line, f"imports the private module mbcomp.{target}"))
            problems += [(where, line, f"imports the private name {n} of mbcomp.{target}") for n in names if private(n)]
        mine = own_private_names(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and private(node.attr) and node.attr not in mine \
                    and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")) \
                    and (where, node.attr) not in THIRD_PARTY:
                problems.append((where, node.lineno, f"reads .{node.attr}, a private name of another module"))
    return problems


def test_every_module_has_a_layer():
    for name in modules():
        layer(name)


def test_no_upward_import_and_no_private_access():
    problems = violations()
    new = sorted(f"{f}:{line} {what}" for f, line, what in problems if (f, what) not in KNOWN)
    assert not new, "layer rule broken:\n" + "\n".join(new)
    fixed = KNOWN - {(f, what) for f, _, what in problems}
    assert not fixed, f"fixed: remove from KNOWN in tests/test_layers.py: {sorted(fixed)}"


@pytest.mark.parametrize("source, expected", [
    ("from ..api.system import System", "imports mbcomp.api.system (layer 9) from layer 0"),
    ("from .errors import _hidden", "private name _hidden"),
    ("def f(x):\n    return x._secret", "reads ._secret"),
])
def test_the_checker_catches(tmp_path, monkeypatch, source, expected):
    """The checker itself: a planted upward import, private import and private read are found."""
    package = tmp_path / "mbcomp"
    for folder in ("core", "api"):
        (package / folder).mkdir(parents=True)
        (package / folder / "__init__.py").write_text("")
    (package / "core" / "errors.py").write_text("x = 1\n")
    (package / "api" / "system.py").write_text("y = 2\n")
    (package / "core" / "rotations.py").write_text(source + "\n")
    monkeypatch.setitem(globals(), "ROOT", package)
    assert any(expected in what for _, _, what in violations())


def test_a_module_outside_the_layer_folders_is_refused(tmp_path, monkeypatch):
    """A new module at the package root has no layer: the root holds only ``__init__``."""
    package = tmp_path / "mbcomp"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "helpers.py").write_text("")
    monkeypatch.setitem(globals(), "ROOT", package)
    with pytest.raises(AssertionError, match="mbcomp.helpers is in no layer folder"):
        for name in modules():
            layer(name)


def test_the_root_holds_at_most_a_dozen_modules():
    root_modules = [p.name for p in ROOT.glob("*.py")]
    assert len(root_modules) <= 12, root_modules


def test_the_contributor_page_shows_the_layer_map():
    """docs/architecture.md's table lists every folder with its layer and every module in it."""
    page = (ROOT.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    rows = {}
    for line in page.splitlines():
        if line.startswith("| ") and "`" in line and line.split("|")[1].strip().isdigit():
            cells = [c.strip() for c in line.split("|")[1:-1]]
            folder = cells[1].strip("`/") if cells[1].startswith("`") else "__init__"
            rows[folder] = (int(cells[0]), cells[2])
    assert {folder: number for folder, (number, _) in rows.items()} == LAYERS
    for name in modules():
        folder, _, rest = name.partition(".")
        if folder != "__init__" and rest:
            leaf = rest.split(".")[-1]
            assert f"`{leaf}`" in rows[folder][1], f"docs/architecture.md: mbcomp.{name} is missing from {folder}/'s row"
