"""The layer rule (docs/architecture.md): a module imports only from lower layers (lazily or
not), never another module's private names, and never reads ``obj._attr`` of an object
defined elsewhere.  A new module gets its layer here."""
from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "mbcomp"
#: Layer of each module or package prefix (the longest matching prefix wins).
LAYERS = {
    # 0 foundation
    "errors": 0, "services": 0,
    # 1 core: plain data and helpers without model knowledge
    "rotations": 1, "expressions": 1, "result": 1, "checks": 1, "library": 1, "params": 1, "shapes": 1, "progress": 1,
    "statemap": 1, "small_linalg": 1, "expressions_c": 1, "events_c": 1, "symbolic": 1, "normal_form": 1,
    "components.primitives": 1, "components.expr": 1, "components._values": 1,
    # 2 spec: components and the model builder
    "components": 2, "model": 2, "compose": 2, "servo": 2,
    # 3 build: flattening, topology, symbolic program, layouts; files <-> models
    "flatten": 3, "topology": 3, "constraint_set": 3, "equations": 3, "layout": 3, "io": 3,
    "fileform": 3, "c_sizes": 3,
    "urdf": 3, "drive_equations": 3, "param_layout": 3, "recursive": 3,
    # 4 generated code: printers, C templates, compilers, cache
    "codegen": 4, "backend": 4, "cache": 4, "integrators": 4, "formulations.dae_c": 4,
    "formulations.lagrange_c": 4, "fastcall": 4, "expressions_c": 4,
    # 5 the compiled model and its numeric kernel
    "compiler": 5, "kernel": 5,
    # 6 formulations: how constraints and contacts enter
    "formulations": 6, "impact": 6,
    # 7 running: time stepping, events, sweeps, derived series, analyses
    "simulate": 7, "drive_runtime": 7, "events": 7, "batch": 7, "post": 7, "analysis": 7, "scene": 7,
    # 8 the public facade
    "system": 8,
    # 9 user-facing output
    "cli": 9, "cli_analyse": 9, "plotting": 9, "viewer": 9,
    # 10 the package: re-exports everything and registers the services
    "__init__": 10,
}
#: Same-layer imports that are allowed (a package's own modules may always import each other).
SAME_LAYER = {("kernel", "compiler"), ("backend", "codegen"), ("cache", "codegen"), ("backend", "cache"),
              ("fastcall", "backend"), ("fastcall", "cache"),
              ("formulations.base", "impact"), ("simulate", "events"), ("model", "components"),
              ("compose", "components"), ("compose", "model"), ("model", "compose"), ("io", "topology"), ("io", "fileform"),
              ("equations", "drive_equations"), ("equations", "param_layout"), ("equations", "recursive"),
              ("simulate", "drive_runtime"),
              ("servo", "components"), ("servo", "compose"), ("components._values", "params"), ("statemap", "rotations"), ("statemap", "small_linalg"),
              ("cli", "cli_analyse"),
              ("formulations.lagrange_c", "integrators"), ("formulations.lagrange_c", "expressions_c"),
              ("formulations.dae_c", "expressions_c")}
#: Private names of a third-party library that a module reads on purpose: ``(file, name)``.
#: Not a layering matter (the rule is about mbcomp's own modules); each is pinned by tests.
THIRD_PARTY: dict[tuple[str, str], str] = {
    ("mbcomp/symbolic.py", "_from_args"): "sympy's constructor from canonical arguments "
    "(sympy.core.operations.AssocOp._from_args, which sympy's own code uses for this); "
    "tests/test_symbolic_build.py compares every such construction with sympy's result",
}
#: Known breaches being removed: ``(file, problem)``.  Do not add to this list.
KNOWN: set[tuple[str, str]] = {
    ('mbcomp/compiler.py', 'imports the private module mbcomp.components._values'),
    ('mbcomp/constraint_set.py', 'imports the private module mbcomp.components._values'),
    ('mbcomp/constraint_set.py', 'reads ._equations, a private name of another module'),
    ('mbcomp/equations.py', 'imports the private module mbcomp.components._values'),
    ('mbcomp/equations.py', 'reads ._gap_equation, a private name of another module'),
    ('mbcomp/equations.py', 'reads ._loads, a private name of another module'),
    ('mbcomp/equations.py', 'reads ._potential, a private name of another module'),
    ('mbcomp/flatten.py', 'imports the private module mbcomp.components._values'),
    ('mbcomp/model.py', 'imports mbcomp.flatten (layer 3) from layer 2'),
    ('mbcomp/model.py', 'imports the private module mbcomp.components._values'),
    ('mbcomp/system.py', 'imports the private module mbcomp.components._values'),
    ('mbcomp/topology.py', 'imports the private module mbcomp.components._values'),
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
    for prefix in sorted(LAYERS, key=len, reverse=True):
        if name == prefix or name.startswith(prefix + "."):
            return LAYERS[prefix]
    raise AssertionError(f"module mbcomp.{name} has no layer: add it to LAYERS in tests/test_layers.py")


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
            for n in names:  # "from . import codegen" imports the module mbcomp.codegen
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
            same_package = target.rpartition(".")[0] == name.rpartition(".")[0] != "" or target.startswith(name + ".")
            listed = any(name == a and (target == b or target.startswith(b + ".")) for a, b in SAME_LAYER)
            if theirs > mine or (theirs == mine and not same_package and not listed):
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
    ("from .system import System", "imports mbcomp.system (layer 8) from layer 1"),
    ("from .errors import _hidden", "private name _hidden"),
    ("def f(x):\n    return x._secret", "reads ._secret"),
])
def test_the_checker_catches(tmp_path, monkeypatch, source, expected):
    """The checker itself: a planted upward import, private import and private read are found."""
    package = tmp_path / "mbcomp"
    package.mkdir()
    (package / "errors.py").write_text("x = 1\n")
    (package / "system.py").write_text("y = 2\n")
    (package / "rotations.py").write_text(source + "\n")
    monkeypatch.setitem(globals(), "ROOT", package)
    assert any(expected in what for _, _, what in violations())
