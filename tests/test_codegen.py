"""Code generation: the expression printer and Python/C agreement (the cache: test_cache.py)."""
from __future__ import annotations

import ctypes
import math
import subprocess

import numpy as np
import pytest
import sympy as sp

import mbcomp as mb
from mbcomp.codegen import printer as codegen
from mbcomp.codegen.backend import FUNCTIONS, PythonFunctions, c_compiler, c_functions
from conftest import arm_model, assert_close

x, y, z, w = SYMBOLS = sp.symbols("x y z w")

# Everything the equation builder emits: sums, differences, products, numeric
# coefficients, integer and half powers, sin and cos (and nestings of them).
EXPRESSIONS = {
    "sum": x + y + z,
    "difference": x - y - 2 * z,
    "negated-sum": -(x + y) * z,
    "product": x * y * z,
    "negative-product": -x * y,
    "coefficient": sp.Float(2.5) * x * y - sp.Rational(1, 3) * z,
    "small-coefficient": sp.Float(1e-7) * x + sp.Float(-3e5) * y,
    "square": (x - y) ** 2,
    "inverse": 1 / (x + y),
    "inverse-square": (y + 2 * z) ** -2,
    "sqrt": sp.sqrt(x * x + y * y + z * z),
    "inverse-sqrt": 1 / sp.sqrt(x + y),
    "cube": x ** 3 - y ** -3,
    "three-halves": (x + z) ** sp.Rational(3, 2),
    "sin-cos": sp.sin(x) * sp.cos(y) - sp.cos(x + y),
    "trig-powers": sp.sin(x) ** 2 + sp.cos(x) ** 2 * w,
    "nested": sp.sin(sp.cos(x * y) + z) / (1 + w ** 2) - sp.sqrt(x) * (y - z) ** 2,
    "rodrigues": sp.cos(x) + y * y * (1 - sp.cos(x)) - z * sp.sin(x),
    "constant": sp.Float(-4.25),
    "symbol": w,
}
IDS = list(EXPRESSIONS)
NAMES = {s: f"v[{i}]" for i, s in enumerate(SYMBOLS)}


def random_values(seed, n=4):
    """Positive values (so that half powers of sums stay real)."""
    return np.random.default_rng(seed).uniform(0.3, 2.0, size=(n, len(SYMBOLS)))


class TestPrinter:
    @pytest.mark.parametrize("name", IDS)
    def test_printed_python_matches_lambdify(self, name):
        expr = EXPRESSIONS[name]
        source = codegen.Printer(NAMES, "python")(expr)
        reference = sp.lambdify(SYMBOLS, expr, "math")
        for values in random_values(IDS.index(name)):
            got = eval(source, {"sin": math.sin, "cos": math.cos, "sqrt": math.sqrt, "v": list(values)})
            assert got == pytest.approx(reference(*values), rel=1e-13, abs=1e-15), source

    @pytest.mark.parametrize("name", ["sum", "difference", "negated-sum", "product", "coefficient", "square",
                                      "cube", "sin-cos", "nested", "rodrigues"])
    def test_printed_python_handles_negative_values(self, name):
        expr = EXPRESSIONS[name]
        source = codegen.Printer(NAMES, "python")(expr)
        reference = sp.lambdify(SYMBOLS, expr, "math")
        values = [-1.3, 0.7, -0.4, 1.9]
        if name == "nested":
            values[0] = 1.3                                  # sqrt(x)
        got = eval(source, {"sin": math.sin, "cos": math.cos, "sqrt": math.sqrt, "v": values})
        assert got == pytest.approx(reference(*values), rel=1e-13, abs=1e-15), source

    def test_printed_c_matches_lambdify(self, tmp_path):
        compiler = c_compiler()
        if compiler is None:
            pytest.skip("no C compiler")
        printer = codegen.Printer(NAMES, "c")
        body = ["#include <math.h>", ""]
        for i, name in enumerate(IDS):
            body.append(f"double f{i}(const double *v) {{ return {printer(EXPRESSIONS[name])}; }}")
        src, lib = tmp_path / "printed.c", tmp_path / "printed.so"
        src.write_text("\n".join(body) + "\n")
        subprocess.run([compiler, "-O1", "-shared", "-fPIC", str(src), "-o", str(lib), "-lm"], check=True,
                       capture_output=True)
        library = ctypes.CDLL(str(lib))
        for i, name in enumerate(IDS):
            fn = getattr(library, f"f{i}")
            fn.argtypes, fn.restype = [ctypes.POINTER(ctypes.c_double)], ctypes.c_double
            reference = sp.lambdify(SYMBOLS, EXPRESSIONS[name], "math")
            for values in random_values(i):
                arr = (ctypes.c_double * 4)(*values)
                assert fn(arr) == pytest.approx(reference(*values), rel=1e-13, abs=1e-15), name

    def test_generated_units_declare_what_they_call_and_compile_as_with_math_h(self, tmp_path):
        """Generated units declare the libm functions the printer emits (``C_MATH``) instead of
        including <math.h>: every function the printer can print is declared (an undeclared
        call is an error here), and the object code is the same as with the header."""
        compiler = c_compiler()
        if compiler is None:
            pytest.skip("no C compiler")
        printer = codegen.Printer(NAMES, "c")
        every = [EXPRESSIONS["nested"], EXPRESSIONS["three-halves"], sp.tanh(x) * y, sp.Min(x, y) + sp.Max(z, w),
                 x ** sp.Rational(-1, 2), x ** sp.Float(1.5)]
        body = "".join(f"double f{i}(const double *v) {{ return {printer(e)}; }}\n" for i, e in enumerate(every))
        from mbcomp.codegen.backend import C_FLAGS, COLD_FLAGS
        objects = []
        for header in (codegen.C_MATH, "#include <math.h>\n"):
            folder = tmp_path / str(len(objects))
            folder.mkdir()
            (folder / "unit.c").write_text(header + body)
            for k, flags in enumerate((COLD_FLAGS, C_FLAGS)):  # the flags of cold and hot units
                subprocess.run([compiler, *flags, "-c", "unit.c", "-o", f"unit{k}.o"], check=True,
                               capture_output=True, cwd=folder)
            objects.append([(folder / f"unit{k}.o").read_bytes() for k in range(2)])
        assert objects[0] == objects[1]
        for name in ("sqrt", "pow", "sin", "cos", "tanh", "fmin", "fmax"):
            assert f" {name}(" in codegen.C_MATH, name

    def test_the_templates_declarations_compile_as_the_c_library_headers(self, tmp_path):
        """``C_TEMPLATE_LIBC`` stands for <stdlib.h>, <string.h> and <math.h> in the
        hand-written C: code that uses every name it declares compiles to the same object as
        with the headers, and a call it does not declare is an error under ``C_FLAGS``."""
        from mbcomp.codegen.backend import C_FLAGS
        compiler = c_compiler()
        if compiler is None:
            pytest.skip("no C compiler")
        body = """
double use(const double *v, double *w, long n) {
    double *a = malloc(sizeof(double) * n), *b = calloc(n, sizeof(double));
    if (!a || !b) return NAN;
    memcpy(a, v, sizeof(double) * n); memmove(b, a, sizeof(double) * n); memset(w, 0, sizeof(double) * n);
    double s = sqrt(a[0]) + pow(a[1], 1.5) + sin(a[2]) * cos(a[3]) + tanh(a[4]) + fmin(a[0], a[1])
        + fmax(a[2], a[3]) + fabs(b[0]) + exp(b[1]) + log(b[2]) + nextafter(b[3], INFINITY);
    if (!isfinite(s) || isnan(s) || signbit(s)) s = -DBL_EPSILON * (double)clock() / CLOCKS_PER_SEC;
    free(a); free(b);
    return s;
}
"""
        headers = "#include <stdlib.h>\n#include <string.h>\n#include <math.h>\n#include <float.h>\n#include <time.h>\n"
        objects = []
        for k, header in enumerate((codegen.C_TEMPLATE_LIBC, headers)):
            folder = tmp_path / str(k)
            folder.mkdir()
            (folder / "unit.c").write_text(header + body)
            subprocess.run([compiler, *C_FLAGS, "-c", "unit.c", "-o", "unit.o"], check=True, capture_output=True,
                           cwd=folder)
            objects.append((folder / "unit.o").read_bytes())
        assert objects[0] == objects[1]
        (tmp_path / "bad.c").write_text(codegen.C_TEMPLATE_LIBC + "double f(double x) { return erf(x); }\n")
        failed = subprocess.run([compiler, *C_FLAGS, "-c", "bad.c", "-o", "bad.o"], capture_output=True, text=True,
                                cwd=tmp_path)
        assert failed.returncode != 0 and "erf" in failed.stderr

    def test_numbers_are_printed_as_floats(self):
        printer = codegen.Printer(NAMES, "c")
        assert printer(sp.Integer(3)) == "3.0"
        assert printer(sp.Rational(1, 4)) == "0.25"
        assert printer(sp.Integer(-2)) == "(-2.0)"          # parenthesised: safe after any operator
        assert printer(x / 2) == "0.5*v[0]"

    def test_half_powers_use_sqrt(self):
        printer = codegen.Printer(NAMES, "python")
        assert printer(sp.sqrt(x)) == "sqrt(v[0])"
        assert printer(1 / sp.sqrt(x)) == "(1.0/sqrt(v[0]))"
        assert printer(x ** 2) == "(v[0]*v[0])"

    @pytest.mark.parametrize("expr", [sp.exp(x), sp.tan(x), sp.pi * x, sp.Abs(x)], ids=["exp", "tan", "pi", "abs"])
    def test_unsupported_expressions_raise(self, expr):
        with pytest.raises(TypeError, match="cannot print"):
            codegen.Printer(NAMES, "python")(expr)


# ----------------------------------------------------------------------------------
# Whole programs: Python and C agree
# ----------------------------------------------------------------------------------
def driven_arm():
    """The arm plus run-time inputs (callable force and torque) and a spring."""
    m = arm_model()
    m.add(mb.Force("push", "lower", point=(0, 0.3, 0), force=lambda t, q, qd: (0.0, 0.0, 0.0)))
    m.add(mb.JointTorque("drive", "shoulder", lambda t, q, qd: (0.0, 0.0)))
    m.add(mb.Spring("tendon", a=("ground", (0.1, 0.2, 0.3)), b=("lower", (0, 0.2, 0)), stiffness=50.0,
                    rest_length=0.1, damping=0.5))
    return m


@pytest.fixture
def compiled(tmp_path, monkeypatch):
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(tmp_path))
    sys = driven_arm().compile(backend="python", cache=False)
    return sys._compiled, sys._p


def _random_inputs(compiled, p, seed):
    rng = np.random.default_rng(seed)
    nq = compiled.topology.nq
    return rng.uniform(-1, 1, nq), rng.normal(size=nq), p, rng.normal(size=compiled.n_inputs)


class TestGeneratedPrograms:
    def test_inputs_are_wired(self, compiled):
        compiled, _ = compiled
        assert compiled.n_inputs == 3 + 2

    @pytest.mark.parametrize("chunk", [300, 7, 1], ids=["one-part", "chunks-of-7", "chunks-of-1"])
    def test_generated_c_and_python_agree(self, compiled, chunk):
        compiled, p = compiled
        if c_compiler() is None:
            pytest.skip("no C compiler")
        program = compiled.program
        python = PythonFunctions(codegen.python_source(program, FUNCTIONS), "test")
        source = (codegen.c_source(program, FUNCTIONS, chunk=chunk) + compiled.output_layout.c_defines()
                  + codegen.c_accelerations(compiled.topology.nq))
        c = c_functions(source, compiled.sizes)
        for seed in range(3):
            args = _random_inputs(compiled, p, seed)
            for name in FUNCTIONS:
                expected = python(name, *args)
                assert expected.shape == (compiled.sizes[name],)
                assert_close(c(name, *args), expected, rtol=1e-13, atol=1e-13, name=f"{name} (chunk={chunk})")

    def test_c_accelerations_solve_the_python_equations(self, compiled):
        """The C Cholesky solve of ``M qdd = f + tau`` against numpy on the Python outputs."""
        compiled, p = compiled
        if c_compiler() is None:
            pytest.skip("no C compiler")
        program, nq = compiled.program, compiled.topology.nq
        python = PythonFunctions(codegen.python_source(program, FUNCTIONS), "test")
        source = codegen.c_source(program, FUNCTIONS) + compiled.output_layout.c_defines() + codegen.c_accelerations(nq)
        c = c_functions(source, compiled.sizes)
        rng = np.random.default_rng(3)
        for seed in range(3):
            q, qd, p, u = _random_inputs(compiled, p, seed)
            out = python("dynamics", q, qd, p, u)
            M = np.zeros((nq, nq))
            M[np.tril_indices(nq)] = out[: nq * (nq + 1) // 2]
            M = M + np.tril(M, -1).T
            f = out[nq * (nq + 1) // 2:]
            for tau in (None, rng.normal(size=nq)):
                status, qdd = c.accelerations(q, qd, c.bind_parameters(p), u, tau)
                assert status == 0
                expected = np.linalg.solve(M, f if tau is None else f + tau)
                assert_close(qdd, expected, rtol=1e-11, atol=1e-12, name="C accelerations")

    def test_c_accelerations_report_a_singular_mass_matrix(self, tmp_path, monkeypatch):
        if c_compiler() is None:
            pytest.skip("no C compiler")
        monkeypatch.setenv("MBCOMP_CACHE_DIR", str(tmp_path))
        m = mb.Model("gimbal")
        b = m.add(mb.Body("b", mass=1.0, com=(0.1, 0.2, -0.5), inertia=(0.1, 0.2, 0.25)))
        m.add(mb.Spherical("wrist", m.ground, b, sequence="zxz"))
        compiled = m.compile(backend="python", cache=False)._compiled
        source = (codegen.c_source(compiled.program, FUNCTIONS) + compiled.output_layout.c_defines()
                  + codegen.c_accelerations(3))
        c = c_functions(source, compiled.sizes)
        p = compiled.layout.pack(compiled.default_parameters)
        pointer = c.bind_parameters(p)
        status, _ = c.accelerations(np.array([0.3, 0.0, -0.4]), np.zeros(3), pointer, np.zeros(0), None)
        assert status == 3                       # pivot 3: the third axis repeats the first
        assert c.accelerations(np.array([0.3, 0.5, -0.4]), np.zeros(3), pointer, np.zeros(0), None)[0] == 0

    def test_python_program_matches_the_symbolic_outputs(self, compiled):
        """The generated function evaluates the straight-line program exactly as sympy does."""
        compiled, p = compiled
        program = compiled.program
        python = PythonFunctions(codegen.python_source(program, FUNCTIONS), "test")
        q, qd, p, u = _random_inputs(compiled, p, 7)
        values = {s: v for s, v in zip(program.q, q)}
        values.update({s: v for s, v in zip(program.qd, qd)})
        values.update({s: v for s, v in zip(program.p, p)})
        values.update({s: v for s, v in zip(program.u, u)})
        for symbol, expr in program.assignments:
            values[symbol] = float(expr.xreplace(values))
        expected = [float(sp.sympify(e).xreplace(values)) for e in program.outputs["energy"]]
        assert_close(python("energy", q, qd, p, u), expected, rtol=1e-12, name="energy")

    def test_each_function_keeps_only_the_assignments_it_needs(self, compiled):
        compiled, _ = compiled
        program = compiled.program
        energy, dynamics = program.needed(["energy"]), program.needed(["mass_matrix", "forces"])
        assert 0 < len(energy) < len(program.assignments)
        assert len(dynamics) < len(program.assignments)
        defined = {s for s, _ in energy} | set(program.q) | set(program.qd) | set(program.p) | set(program.u)
        for _, expr in energy:
            assert expr.free_symbols <= defined
        order = {s: i for i, (s, _) in enumerate(program.assignments)}
        assert [order[s] for s, _ in energy] == sorted(order[s] for s, _ in energy)

    def test_python_source_is_valid_and_self_contained(self, compiled):
        compiled, _ = compiled
        source = codegen.python_source(compiled.program, FUNCTIONS)
        namespace = codegen.load_python(source, "test")
        assert set(FUNCTIONS) <= set(namespace)
        assert "import" in source.splitlines()[0] and "mbcomp" not in source


def test_with_unit_text_joins_the_last_cold_unit_or_makes_its_own():
    from mbcomp.codegen.printer import CUnit, with_unit_text
    hot, cold = CUnit("functions0", "int h;\n", True, 40), CUnit("functions1", "int c;\n", False, 3)
    joined = with_unit_text([hot, cold], "sizes", "int s;\n")
    assert [u.name for u in joined] == ["functions0", "functions1"]
    assert joined[1].text == "int s;\nint c;\n" and not joined[1].hot and joined[0] == hot
    alone = with_unit_text([hot], "sizes", "int s;\n")
    assert alone[1] == CUnit("sizes", "int s;\n", False, 0) and alone[0] == hot
