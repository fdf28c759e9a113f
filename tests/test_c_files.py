"""The hand-written C lives in .c/.h files of the package (core/c_text.py), compiles without
warnings, shares its tolerances with Python, and no C is left in Python strings."""
from __future__ import annotations

import ast
import re
import subprocess
import sysconfig
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen import printer as codegen
from mbcomp.codegen import fastcall
from mbcomp.codegen.backend import c_compiler
from mbcomp.core import c_text, tolerances

ROOT = Path(mb.__file__).resolve().parent
LIBRARY = ROOT.parent / "library"
#: Python files that still hold a C block in a string, to be moved into a .c file.
NOT_YET_MOVED: set[str] = set()
#: A line that reads as C (the same test as the house metrics).
C_LINE = re.compile(r";\s*$|^\s*[{}]\s*$|\bdouble\b|\bint\s+\w+\s*[=(;]")
WARNINGS = ("-std=gnu99", "-Wall", "-Wextra", "-Werror")
#: (library model, formulation, dynamics): a tree, a tree by the recursive program, a loop
#: stepped by the lagrange loop (REDUCED_LOOP), a loop by the dae KKT solve on the recursive
#: program, contacts, a quaternion joint, a motor, colliding shapes (the lagrange loop holding them).
MODELS = [("double_pendulum", "lagrange", "dense"), ("five_link_pendulum", "lagrange", "recursive"),
          ("four_bar", "lagrange", "auto"), ("four_bar", "dae", "recursive"), ("bouncing_ball", "dae", "auto"),
          ("spinning_top", "lagrange", "auto"), ("double_pendulum_motor", "dae", "auto"),
          ("newtons_cradle", "lagrange", "auto")]


def c_blocks(path: Path) -> list[tuple[int, int]]:
    """(line, length) of each string constant of more than 40 lines, 30 % of them C."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            lines = node.value.splitlines()
            if len(lines) > 40 and sum(bool(C_LINE.search(x)) for x in lines) > 0.3 * len(lines):
                out.append((node.lineno, len(lines)))
    return out


def test_no_c_block_in_python_strings():
    found = {str(p.relative_to(ROOT)): c_blocks(p) for p in ROOT.rglob("*.py")}
    found = {k: v for k, v in found.items() if v}
    assert set(found) <= NOT_YET_MOVED, f"C in Python strings (move it into a c/ folder): {found}"


def test_the_scan_finds_c_in_a_string(tmp_path):
    """The scan itself: a C function in a string is found, prose is not."""
    body = "\n".join(f"    s += x[{i}] * y[{i}];" for i in range(45))
    path = tmp_path / "m.py"
    path.write_text(f'C = """\ndouble dot(const double *x, const double *y) {{\n    double s = 0.0;\n{body}\n    return s;\n}}\n"""\n'
                    f'DOC = """{"A line of prose." * 3}\n""" + "x"\n')
    assert c_blocks(path) == [(1, 50)]
    path.write_text('DOC = """' + "\n".join("prose, no code" for _ in range(60)) + '"""\n')
    assert c_blocks(path) == []


def test_c_files_ship_and_compose():
    names = {f"{package.split('.')[-1]}/{name}" for package, name in c_text.files()}
    assert {"codegen/accelerations.c", "codegen/brentq.h", "codegen/fastcall.c", "codegen/integrators.c",
            "formulations/dae.c", "build/recursive_dae.c"} <= names
    dae = c_text.read("mbcomp.formulations", "dae.c")
    assert '#include "' not in dae and "static double mb_brentq(" in dae and "mb_program(" in dae
    assert c_text.raw("mbcomp.codegen", "brentq.h") in c_text.all_text()
    with pytest.raises(KeyError, match="missing values for \\['RUN'\\]"):
        c_text.fill(c_text.read("mbcomp.codegen", "dop853_loop.c"), INIT="f")
    with pytest.raises(KeyError, match="no placeholder for \\['EXTRA'\\]"):
        c_text.fill("int @NAME@;", NAME="x", EXTRA=1)
    assert c_text.fill("int @NAME@_many = @NAME@;", NAME="x") == "int x_many = x;"


def test_tolerances_are_the_c_defines():
    """The C reads the Python constants: the defines are the same doubles."""
    defines = dict(re.findall(r"#define (MB_\w+) (\S+)", tolerances.c_defines()))
    assert {k: float(v) for k, v in defines.items()} == tolerances.C_NAMES
    assert tolerances.C_NAMES["MB_PIVOT_TOLERANCE"] == tolerances.PIVOT_TOLERANCE == 1e-13
    assert tolerances.RANK_TOLERANCE == 1e-9
    text = codegen.c_accelerations()
    assert "MB_PIVOT_TOLERANCE" in text and "1e-13" in text


def _compile(source: str, *flags: str) -> subprocess.CompletedProcess:
    return subprocess.run([c_compiler(), *WARNINGS, *flags, "-x", "c", "-", "-o", "/dev/null"],
                          input=source.encode(), capture_output=True, timeout=300)


@pytest.mark.skipif(c_compiler() is None, reason="no C compiler")
def test_the_templates_compile_with_warnings_as_errors():
    """Every model kind's hand-written C unit (as the backend compiles it) gives no warning at
    -Wall -Wextra, and together the units hold every line of every C file of the package."""
    units = []
    for name, formulation, dynamics in MODELS:
        system = mb.load(LIBRARY / f"{name}.toml").compile(formulation, dynamics=dynamics)
        compiled = system._compiled
        source = (codegen.c_prototypes(compiled._functions())
                  + compiled._c_templates(compiled._c_sizes()))
        if source in units:
            continue  # the same unit as an earlier kind's (compiled once: 8 kinds give 4 texts)
        done = _compile(source, "-c")
        assert done.returncode == 0, f"{name} ({formulation}, {dynamics}):\n{done.stderr.decode()[:4000]}"
        units.append(source)
    include = [sysconfig.get_paths()["include"], np.get_include()]
    if (Path(include[0]) / "Python.h").is_file():
        done = _compile(fastcall.SOURCE, "-fsyntax-only", *(f"-I{d}" for d in include))
        assert done.returncode == 0, done.stderr.decode()[:4000]
        units.append(fastcall.SOURCE)
    compiled_text = "\n".join(units)
    for package, file in c_text.files():
        for line in c_text.raw(package, file).splitlines():
            if line.strip() and "@" not in line and not re.match(r'\s*#\s*include\s+"', line):
                assert line in compiled_text, f"{package}/c/{file}: not compiled by this test: {line!r}"
