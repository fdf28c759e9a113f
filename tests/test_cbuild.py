"""The C build: generated code split into translation units compiled in parallel (codegen.c_units,
backend.CBuild), with the same numbers as the single-unit source."""
from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen import backend, printer as codegen
from mbcomp.codegen.backend import C_FLAGS, COLD_FLAGS, COLD_FUNCTIONS, FUNCTIONS, CBuild, c_compiler, c_functions, c_library
from conftest import pendulum_chain, xy_pairs

needs_cc = pytest.mark.skipif(c_compiler() is None, reason="no C compiler")


@pytest.fixture(scope="module")
def chain():
    """A 4-link chain's compiled model (Python backend: the program is built here) and parameters."""
    compiled = pendulum_chain(4).compile(backend="python", cache=False)._compiled
    return compiled, compiled.layout.pack(compiled.default_parameters)


@pytest.fixture(scope="module")
def single_unit(chain):
    """The chain's functions compiled from one unit (the reference of the split builds)."""
    compiled, _ = chain
    return c_functions(codegen.c_source(compiled.program, FUNCTIONS, cold=COLD_FUNCTIONS)
                       + compiled.output_layout.c_defines() + codegen.c_accelerations(compiled.topology.nv),
                       compiled.sizes)


def _states(compiled, seed):
    rng = np.random.default_rng(seed)
    return rng.uniform(-2, 2, compiled.topology.nq), rng.uniform(-3, 3, compiled.topology.nv)


def _split_library(compiled, chunk, unit, jobs=None):
    build = CBuild(c_compiler(), jobs=jobs)
    build.add("templates", codegen.c_prototypes(FUNCTIONS) + compiled.output_layout.c_defines()
              + codegen.c_accelerations(compiled.topology.nv), C_FLAGS)
    units = list(codegen.c_units(compiled.program, FUNCTIONS, cold=COLD_FUNCTIONS, chunk=chunk, unit=unit))
    for u in units:
        build.add(u.name, u.text, C_FLAGS if u.hot else COLD_FLAGS, u.statements)
    return units, c_library(build.finish(), compiled.sizes)


class TestUnits:
    def test_units_cover_each_function_once_and_split_long_ones(self, chain):
        compiled, _ = chain
        units = list(codegen.c_units(compiled.program, FUNCTIONS, cold=COLD_FUNCTIONS, chunk=10, unit=40))
        names = [u.name for u in units]
        assert len(names) == len(set(names))
        for fname in FUNCTIONS:  # every function defined exactly once
            head = f"void {fname}(const double *q, const double *qd, const double *p, const double *u, double *out) {{"
            defining = [u for u in units if head in u.text]
            assert len(defining) == 1, fname
            if fname in COLD_FUNCTIONS or defining[0].hot:
                assert defining[0].hot == (fname not in COLD_FUNCTIONS), fname
            else:  # a hot function in a tiny pack (the empty constraints of a chain) goes cold
                needed = compiled.program.needed(FUNCTIONS[fname], codegen._free_symbols(compiled.program))
                assert len(needed) <= codegen.UnitStream.TINY_HOT, fname
        dynamics = [u for u in units if u.name.startswith("dynamics")]
        needed = len(compiled.program.needed(FUNCTIONS["dynamics"]))
        assert len(dynamics) == -(-needed // 40)  # chunks of 10 statements, 4 to a unit
        assert sum(u.statements for u in dynamics) == needed
        assert all(u.statements <= 40 for u in dynamics) and all(u.hot for u in dynamics)

    def test_a_small_model_is_a_hot_and_a_cold_unit(self, chain):
        """Short functions are packed: two compilers for the whole generated program."""
        compiled, _ = chain
        units = list(codegen.c_units(compiled.program, FUNCTIONS, cold=COLD_FUNCTIONS))
        assert [(u.name, u.hot) for u in units] == [("functions0", True), ("functions1", False)]
        for u in units:
            names = [f for f in FUNCTIONS if (f in COLD_FUNCTIONS) != u.hot]
            assert u.statements == sum(len(compiled.program.needed(FUNCTIONS[f])) for f in names)

    @needs_cc
    @pytest.mark.parametrize("chunk, unit, jobs", [(300, 1500, None), (7, 30, None), (7, 30, 1)],
                             ids=["one-unit-each", "many-units", "many-units-one-job"])
    def test_split_units_give_the_numbers_of_one_unit(self, chain, single_unit, chunk, unit, jobs):
        compiled, p = chain
        single = single_unit
        units, split = _split_library(compiled, chunk, unit, jobs)
        assert len(units) == 2 if unit == 1500 else len(units) > len(FUNCTIONS)
        u = np.zeros(0)
        for seed in range(3):
            q, qd = _states(compiled, seed)
            for name in FUNCTIONS:
                a, b = single(name, q, qd, p, u), split(name, q, qd, p, u)
                assert a.shape == (compiled.sizes[name],)
                assert np.array_equal(a, b), f"{name} differs between one unit and {len(units)}"
            s1, qdd1 = single.accelerations(q, qd, single.bind_parameters(p), u, None)
            s2, qdd2 = split.accelerations(q, qd, split.bind_parameters(p), u, None)
            assert s1 == s2 == 0 and np.array_equal(qdd1, qdd2)
            M = np.zeros((4, 4))
            out = single("dynamics", q, qd, p, u)
            M[np.tril_indices(4)] = out[:10]
            M = M + np.tril(M, -1).T
            np.testing.assert_allclose(qdd2, np.linalg.solve(M, out[10:]), rtol=1e-10, atol=1e-12)


class TestBuild:
    @needs_cc
    def test_a_failing_unit_warns_stops_the_others_and_leaves_nothing(self, tmp_path, monkeypatch):
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        build = CBuild(c_compiler(), jobs=1)
        build.add("good", "double f(double x) { return 2.0 * x; }\n", C_FLAGS, 10)
        build.add("bad", "this is not C\n", C_FLAGS, 5)
        build.add("waiting", "double g(double x) { return x; }\n", C_FLAGS, 1)
        with pytest.warns(RuntimeWarning, match="compiler failed"):
            assert build.finish() is None
        assert list(tmp_path.iterdir()) == []

    @needs_cc
    def test_a_cancelled_build_leaves_nothing(self, tmp_path, monkeypatch):
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        build = CBuild(c_compiler())
        build.add("a", "double f(double x) { return 2.0 * x; }\n", C_FLAGS)
        build.cancel()
        assert list(tmp_path.iterdir()) == []

    def test_compile_jobs_is_a_small_positive_count(self):
        assert 1 <= backend.compile_jobs() <= 4


@needs_cc
def test_the_cache_entry_records_both_flag_sets_and_cold_flags_change_the_key(primed_cache_dir, monkeypatch):
    from mbcomp.compiled import compiler
    first = pendulum_chain(2).compile(backend="c")._compiled
    manifest = json.loads((primed_cache_dir / f"{first.key}.so.json").read_text())
    assert manifest["inputs"]["flags"] == list(C_FLAGS) and manifest["inputs"]["cold_flags"] == list(COLD_FLAGS)
    monkeypatch.setattr(compiler, "COLD_FLAGS", ("-O1", "-fPIC", "-fno-math-errno"))
    second = pendulum_chain(2).compile(backend="c")._compiled
    assert second.key != first.key and not second.cache_hit


def _chain_about(axes: str) -> mb.Model:
    """A chain of pendulum_chain's links whose joints turn about ``axes``."""
    m = pendulum_chain(len(axes))
    for joint, axis in zip((c for c in m.components.values() if isinstance(c, mb.Revolute)), axes):
        joint.axis = axis
    return m


@needs_cc
class TestSharedUnits:
    """The hand-written templates of one model structure compile once: later models with the
    same sizes link the cached object (signed like every cache entry)."""

    def _count_compiles(self, monkeypatch):
        calls = []
        real = backend.subprocess.Popen

        def popen(cmd, *args, **kwargs):
            calls.append(cmd)
            return real(cmd, *args, **kwargs)
        monkeypatch.setattr(backend.subprocess, "Popen", popen)
        return calls

    def test_a_second_model_of_the_same_sizes_reuses_the_templates_object(self, tmp_path, monkeypatch):
        monkeypatch.setenv("MBCOMP_CACHE_DIR", str(tmp_path))
        calls = self._count_compiles(monkeypatch)
        first = pendulum_chain(3).compile(backend="c")
        assert any("templates.c" in " ".join(c) for c in calls)
        assert len(list(tmp_path.glob("*.o"))) == 1
        calls.clear()
        heavier = _chain_about("zxz")  # the same sizes, other equations: a new model entry
        second = heavier.compile(backend="c")
        assert calls and not any("templates.c" in " ".join(c) for c in calls)
        q, qd = np.array([0.3, -0.2, 0.5]), np.array([0.1, 0.0, -0.4])
        reference = pendulum_chain(3).compile(backend="python", cache=False)
        np.testing.assert_allclose(first.accelerations(q, qd), reference.accelerations(q, qd), rtol=1e-12)
        moon = heavier.compile(backend="python", cache=False)
        np.testing.assert_allclose(second.accelerations(q, qd), moon.accelerations(q, qd), rtol=1e-12)

    def test_models_of_other_sizes_link_the_same_templates_object(self, tmp_path, monkeypatch):
        """The templates read the model's sizes from its own unit (c_sizes): a chain of 4
        links, 2 links on xy Euler-angle joints (the same state length, other layouts) and a
        chain of 3 links (another state length) link one object, and each simulates as its
        scipy-stepped Python twin."""
        monkeypatch.setenv("MBCOMP_CACHE_DIR", str(tmp_path))
        calls = self._count_compiles(monkeypatch)
        chain = pendulum_chain(4).compile(backend="c")
        calls.clear()
        pairs = xy_pairs().compile(backend="c")
        shorter = pendulum_chain(3).compile(backend="c")
        assert calls and not any("templates.c" in " ".join(c) for c in calls)
        assert len(list(tmp_path.glob("*.o"))) == 1
        q0 = np.array([0.4, -0.3, 0.2, 0.1])
        for system, model in ((chain, pendulum_chain(4)), (pairs, xy_pairs()), (shorter, pendulum_chain(3))):
            q0 = q0[:len(system.coords)]
            compiled = system.simulate(1.0, q0, rtol=1e-10, atol=1e-12)
            stepped = model.compile(backend="python", cache=False).simulate(1.0, q0, rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(compiled.q[-1], stepped.q[-1], atol=1e-7)
            assert compiled.t.size > 5

    def test_the_empty_functions_of_a_tree_share_one_unoptimised_run_with_the_sizes(self, primed_cache_dir,
                                                                                     monkeypatch):
        """A chain has no constraints, contacts or drives: those empty functions join the cold
        unit (UnitStream.TINY_HOT), which also holds the model's sizes (one compiler run,
        none of them optimised); the output functions are not in the model's units at all."""
        units, real_add = [], CBuild.add

        def add(self, name, text, flags, *args, **kwargs):
            units.append((name, text, tuple(flags)))
            return real_add(self, name, text, flags, *args, **kwargs)
        monkeypatch.setattr(CBuild, "add", add)
        system = pendulum_chain(6).compile(backend="c")
        head = "void {}(const double *q, const double *qd, const double *p, const double *u, double *out) {{"
        (cold,) = [(name, text) for name, text, flags in units if flags == COLD_FLAGS]
        for fname in ("constraints", "contacts", "drives"):
            assert head.format(fname) in cold[1], fname
        assert "const int mb_NQ = 6;" in cold[1]                # the model's sizes (c_sizes.CSizes.unit)
        generated = [text for name, text, _ in units if name != "templates"]
        for fname in ("energy", "kinematics"):   # (the templates hold their stubs)
            assert not any(head.format(fname) in text for text in generated)
        assert all(head.format("dynamics") not in text or flags == C_FLAGS for _, text, flags in units)
        q, qd = np.linspace(0.3, -0.2, 6), np.linspace(0.1, -0.4, 6)
        assert system.kernel.call("constraints", q, qd).size == 0
        np.testing.assert_allclose(system.accelerations(q, qd),
                                   pendulum_chain(6).compile(backend="python", cache=False).accelerations(q, qd),
                                   rtol=1e-12)

    def test_a_damaged_object_is_rebuilt_not_linked(self, tmp_path, monkeypatch):
        monkeypatch.setenv("MBCOMP_CACHE_DIR", str(tmp_path))
        pendulum_chain(2).compile(backend="c")
        (obj,) = tmp_path.glob("*.o")
        obj.write_bytes(obj.read_bytes()[:100])
        calls = self._count_compiles(monkeypatch)
        other = _chain_about("zz")
        system = other.compile(backend="c")
        assert any("templates.c" in " ".join(c) for c in calls)
        q, qd = np.array([0.3, -0.2]), np.array([0.1, 0.4])
        np.testing.assert_allclose(system.accelerations(q, qd),
                                   other.compile(backend="python", cache=False).accelerations(q, qd), rtol=1e-12)


class TestStreamedUnits:
    """Units printed while the program is built (``build_program(ready=...)`` and
    ``codegen.UnitStream``): the same functions, each defined once, as the whole-program units."""

    def test_ready_outputs_are_final_when_announced(self):
        from mbcomp.build.equations import build_program
        compiled = pendulum_chain(3).compile(backend="python", cache=False)._compiled
        seen = []

        def ready(prog, names):  # a snapshot of each output and of the program's length then
            seen.append((tuple(names), {n: list(prog.outputs[n]) for n in names}, len(prog.assignments)))

        prog = build_program(compiled.topology, compiled.layout, compiled.inputs, recursive=True, ready=ready)
        assert [names for names, _, _ in seen] == [("kinematics",), ("mass_matrix", "forces"), ("energy",), ("aba",)]
        for names, outputs, length in seen:
            for name in names:
                assert outputs[name] == prog.outputs[name]  # never changed afterwards
                before = {s for s, _ in prog.assignments[:length]}
                assert {s for s, _ in prog.needed([name])} <= before  # needs nothing assigned later
        lengths = [length for _, _, length in seen]
        assert lengths == sorted(lengths) and lengths[0] < lengths[-1]

    @pytest.mark.parametrize("eager", [None, 1, 10_000])
    def test_a_stream_defines_every_function_once(self, chain, eager):
        compiled, _ = chain
        stream = codegen.UnitStream(compiled.program, cold=COLD_FUNCTIONS, chunk=10, unit=40, eager=eager)
        units = []
        for fname, outputs in FUNCTIONS.items():
            units += stream.add({fname: outputs})
        units += stream.flush()
        assert len({u.name for u in units}) == len(units)
        for fname in FUNCTIONS:
            head = f"void {fname}(const double *q, const double *qd, const double *p, const double *u, double *out) {{"
            assert len([u for u in units if head in u.text]) == 1, fname
        total = sum(len(compiled.program.needed(FUNCTIONS[f])) for f in FUNCTIONS)
        assert sum(u.statements for u in units) == total
        if eager is None:  # exactly the units of c_units
            assert [(u.name, u.text) for u in units] == [
                (u.name, u.text) for u in codegen.c_units(compiled.program, FUNCTIONS, cold=COLD_FUNCTIONS, chunk=10,
                                                          unit=40)]

    @needs_cc
    def test_waiting_units_start_without_another_add(self):
        """One job slot, three units: the watcher starts the second and third while the caller
        does something else (builds the program), not at the next ``add`` or ``finish``."""
        import time
        build = CBuild(c_compiler(), jobs=1)
        try:
            for k in range(3):
                build.add(f"u{k}", f"double f{k}(double x) {{ return {k + 1}.0 * x; }}\n", C_FLAGS, 10)
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                with build._lock:
                    if not build._waiting and not build._running:
                        break
                time.sleep(0.01)
            with build._lock:
                assert not build._waiting and not build._running
            assert build._failure is None
            assert all((build._tmp / f"u{k}.o").stat().st_size > 0 for k in range(3))
            library = build.finish()
            assert library  # linked: the bytes of a shared library
        finally:
            build.cancel()

    def test_a_unit_beside_the_build_takes_no_job_slot(self):
        """One job slot: a unit added ``beside`` (the templates) and a generated unit compile at
        once; a second generated unit waits for the slot; all are linked."""
        build = CBuild(c_compiler(), jobs=1)
        try:
            build.add("templates", "double t(double x) { return 2.0 * x; }\n", C_FLAGS, 10, last=True, beside=True)
            build.add("u0", "double f0(double x) { return x; }\n", C_FLAGS, 5)
            build.add("u1", "double f1(double x) { return x; }\n", C_FLAGS, 5)
            with build._lock:  # checked at once: a compiler run takes tens of milliseconds
                running = {name for _, name in build._running}
                waiting = [name for _, name, _ in build._waiting]
            assert running == {"templates", "u0"} and waiting == ["u1"]
            library = build.finish()
            assert library
        finally:
            build.cancel()


@needs_cc
def test_a_hot_function_is_compiled_in_two_halves_with_the_same_numbers(chain):
    """``halve``: the hot dynamics of the 4-link chain as two units of half its statements each,
    linked into the numbers of the whole-function unit."""
    compiled, p = chain
    needed = len(compiled.program.needed(FUNCTIONS["dynamics"]))
    stream = codegen.UnitStream(compiled.program, cold=COLD_FUNCTIONS, halve=needed - 1)
    units = stream.add(dict(FUNCTIONS)) + stream.flush()
    halves = [u for u in units if u.name.startswith("dynamics")]
    assert [u.statements for u in halves] == [-(-needed // 2), needed // 2] and all(u.hot for u in halves)
    build = CBuild(c_compiler())
    build.add("templates", codegen.c_prototypes(FUNCTIONS) + compiled.output_layout.c_defines()
              + codegen.c_accelerations(compiled.topology.nv), C_FLAGS)
    for u in units:
        build.add(u.name, u.text, C_FLAGS if u.hot else COLD_FLAGS, u.statements)
    split = c_library(build.finish(), compiled.sizes)
    whole = c_functions(codegen.c_source(compiled.program, FUNCTIONS, cold=COLD_FUNCTIONS)
                        + compiled.output_layout.c_defines() + codegen.c_accelerations(compiled.topology.nv),
                        compiled.sizes)
    for seed in range(3):
        q, qd = _states(compiled, seed)
        assert np.array_equal(split("dynamics", q, qd, p, np.zeros(0)), whole("dynamics", q, qd, p, np.zeros(0)))


class TestBackgroundBuild:
    @pytest.mark.skipif(c_compiler() is None, reason="no C compiler")
    def test_a_background_build_runs_niced_and_gives_a_loadable_library(self, monkeypatch):
        import ctypes
        import shutil
        import subprocess
        commands, real_run = [], subprocess.run

        def run(command, *args, **kwargs):
            commands.append(list(command))
            return real_run(command, *args, **kwargs)
        monkeypatch.setattr(subprocess, "run", run)
        stored = []
        build = backend.BackgroundBuild("double twice(double x) { return 2.0 * x; }\n", c_compiler(), COLD_FLAGS,
                                        store=lambda data: stored.append(len(data)) or "stored")
        data, kept = build.result()
        assert kept == "stored" and stored == [len(data)]
        if shutil.which("nice"):
            assert commands[0][1:3] == ["-n", str(backend.BACKGROUND_NICE)]
        library = backend.load_library_bytes(data)
        library.twice.restype, library.twice.argtypes = ctypes.c_double, [ctypes.c_double]
        assert library.twice(1.25) == 2.5

    @pytest.mark.skipif(c_compiler() is None, reason="no C compiler")
    def test_a_failed_background_build_gives_nothing_and_warns(self):
        with pytest.warns(RuntimeWarning, match="compiler failed"):
            build = backend.BackgroundBuild("this is not C\n", c_compiler(), COLD_FLAGS)
            assert build.result() == (None, None)


@needs_cc
def test_the_templates_state_copy_copies_every_byte_and_nothing_more():
    """``mb_copy`` (codegen.C_TEMPLATE_LIBC), the compiled loops' memcpy: whole words when
    the length and both addresses allow, bytes otherwise; the bytes around stay as they were."""
    import ctypes
    source = (codegen.C_TEMPLATE_LIBC
              + "void copy(unsigned char *to, const unsigned char *from, long n) { mb_copy(to, from, (mb_size_t)n); }\n")
    library = backend.load_library_bytes(backend.compile_c(source, c_compiler()))
    rng = np.random.default_rng(3)
    source_bytes = rng.integers(0, 256, 200, dtype=np.uint8)
    for start, offset, n in [(0, 0, 160), (8, 16, 64), (1, 0, 40), (0, 3, 17), (5, 7, 0), (0, 0, 8)]:
        target = np.full(200, 0xAB, dtype=np.uint8)
        library.copy(ctypes.c_void_p(target.ctypes.data + offset), ctypes.c_void_p(source_bytes.ctypes.data + start),
                     ctypes.c_long(n))
        expected = np.full(200, 0xAB, dtype=np.uint8)
        expected[offset:offset + n] = source_bytes[start:start + n]
        assert np.array_equal(target, expected), (start, offset, n)
