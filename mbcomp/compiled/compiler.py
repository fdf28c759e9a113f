"""Compilation: model -> topology, parameter layout and generated numeric functions (cached)."""
from __future__ import annotations

import contextlib
import ctypes
import hashlib
import threading
import time
from typing import Any

import numpy as np

from mbcomp.codegen import cache, printer as codegen
from mbcomp.core import c_text
from mbcomp.build import recursive
from mbcomp.build.c_sizes import CSizes
from mbcomp.codegen.backend import (C_FLAGS, COLD_FLAGS, COLD_FUNCTIONS, EAGER_STATEMENTS, EARLY_OUTPUT_STATEMENTS, FUNCTIONS,
                      HALVE_STATEMENTS,
                      OUTPUT_FUNCTIONS, UNIT_STATEMENTS, BackgroundBuild, CBuild, CFunctions,
                      PythonFunctions, c_compiler, c_library, compile_c, load_library_bytes, spare_core)
from mbcomp.spec.components.values import name_of
from mbcomp.build.param_layout import input_layout, parameter_layout, parameter_values
from mbcomp.build.drive_equations import drive_layout
from mbcomp.core.errors import ModelError
from mbcomp.build.layout import OutputLayout
from mbcomp.build.flatten import flatten
from mbcomp.core.params import ParameterSpec

GRAVITY = ParameterSpec("gravity", (3,), "m/s^2", doc="uniform gravity, world frame")
from mbcomp.build.topology import build_topology

#: Held collision features the dae solve has room for, per speed (plus 8): a box resting on
#: another holds four corners on three speeds (planar) or six (free).
HELD_FEATURES_PER_SPEED = 4


def structure_description(model, topology, layout, inputs, drives=None) -> str:
    """Everything that decides the generated code, as text (names included)."""
    parts = [f"gravity|{len(topology.coords)}"]
    for comp in topology.components.values():
        refs = sorted((role, name_of(ref)) for role, ref in comp.references().items())
        parts.append(f"{type(comp).__name__}|{comp.name}|{refs}|{comp.structure()}")
    parts.append("order|" + ",".join(b.name for b in topology.bodies))
    parts.append("coords|" + ",".join(topology.coords))
    parts.append("params|" + ",".join(f"{k}:{v}" for k, v in layout.entries.items()))
    parts.append("inputs|" + ",".join(f"{k}:{v}" for k, v in inputs.items()))
    if drives is not None:
        parts.append(drives.description())
    return "\n".join(parts)


class CompiledModel:
    """What compilation produces and every ``System`` of the same structure shares:
    topology, layouts, generated functions (and, lazily, the symbolic program)."""

    def __init__(self, model, *, cache: bool, backend: str, c_snippets: tuple = (), dynamics: str = "auto",
                 formulation: str | None = None):
        """``c_snippets``: callables ``(nv, ng) -> str`` giving the C code the formulations
        add to the library (every registered formulation's, so that one library serves all).
        ``dynamics``: ``"auto"``, ``"dense"`` or ``"recursive"``; with ``formulation`` (its
        name) the automatic choice (``recursive.choose``)."""
        self.c_snippets = tuple(c_snippets)
        self.use_cache = cache  #: whether this model's code goes through the code cache
        model = flatten(model)  # a frozen copy: compiling never changes or keeps the user's objects
        self.model_name = model.name
        self.flat_model = model
        self.topology = build_topology(model)
        self.default_parameters = parameter_values(model)
        self.layout = parameter_layout(self.default_parameters)
        self.inputs = input_layout(self.topology)
        self.drives = drive_layout(self.topology)
        self._check_names()
        from mbcomp.build.constraint_set import ConstraintSet
        self.constraint_set = ConstraintSet(self.topology) if (self.topology.cut_joints or self.topology.constraints) else None
        self.geometric_rows = [] if self.constraint_set is None else self.constraint_set.geometric_rows
        #: The lagrange formulation's reduced loop is compiled in (constraints or contacts, with
        #: quaternions stepped in their chart; drive states after the reduced state: see
        #: formulations/lagrange_c.py).
        from mbcomp.spec.components.collision import Collision
        #: Contact rows in the compiled loops: the model's contacts, or the features of its
        #: collisions (measured in C: codegen/c/collide.c).
        self.contact_rows = bool(self.topology.contacts) or any(
            isinstance(c, Collision) for c in self.topology.components.values())
        self.reduced_loop = self.constraint_set is not None or self.contact_rows
        self.n_inputs = sum(size for _, size in self.inputs.values())
        self.no_inputs = np.zeros(0)
        self.tril = np.tril_indices(self.topology.nv)
        #: How the tree accelerations are computed: "dense" or "recursive" (recursive.py).
        self.dynamics = recursive.choose(dynamics, self.topology, f"Model {self.model_name!r}", formulation)
        #: The C library leaves out the dense dynamics (mass matrix, forces), which the
        #: recursive right-hand side never calls, and builds them on first use (``dense_library``).
        self.lazy_dense = "dynamics" in self._cold_dynamics()
        #: Where each output quantity sits in the generated functions' packed outputs.
        self.output_layout = OutputLayout.of(self.topology.nv, len(self.topology.bodies), len(self.geometric_rows),
                                             len(self.topology.contacts), self.drives.nz)
        #: Everything about the model that decides the generated code (part of the cache key).
        self.description = (structure_description(model, self.topology, self.layout, self.inputs, self.drives)
                            + "\nlayout|" + self.output_layout.description() + f"\ndynamics|{self.dynamics}")
        self.key = ""  # the cache key of the loaded code, set by _load
        self._program = None
        #: The C of the ``OUTPUT_FUNCTIONS`` printed by this compile, its build in the
        #: background, and their library once loaded (``output_library``).
        self._output_source: str | None = None
        self._outputs_build: BackgroundBuild | None = None
        self._outputs = None
        self._outputs_lock = threading.Lock()
        started = time.perf_counter()
        self.cache_hit = False
        self.sizes = {"nq": self.topology.nq, "nv": self.topology.nv, **self.output_layout.sizes()}
        try:
            self.functions = self._load(cache, backend)
        except OSError as exc:  # the build's own files (the cache only costs a rebuild): a full disk
            from mbcomp.codegen.backend import build_failure
            from mbcomp.core.errors import CompileError
            raise CompileError(f"Model {self.model_name!r}", build_failure(exc)) from None
        self.compile_time = time.perf_counter() - started

    def _cold_dynamics(self) -> tuple[str, ...]:
        """``recursive.cold_functions``, none with collision features (whose contact rows the
        compiled loops hold with the dense dynamics, as a model's own contacts)."""
        return () if self.contact_rows else recursive.cold_functions(self.dynamics, self.topology)

    def _check_names(self) -> None:
        """The naming rule (``mbcomp.core.names``): no coordinate, speed column, state or parameter
        shares a name with another or with a column mbcomp adds (a ``CompileError`` naming both)."""
        from mbcomp.core import names
        from mbcomp.core.errors import CompileError
        keys = []
        for key, (_, shape) in self.layout.entries.items():
            keys.extend([key] if not shape else [f"{key}[{i}]" for i in range(shape[0])])
        problems = names.clashes(names.model_entries(self.topology, self.drives, keys))
        if problems:
            raise CompileError(f"Model {self.model_name!r}", problems=problems)

    def parameter_spec(self, key: str):
        """``(owner, ParameterSpec)`` of a ``System.parameters`` key (``"spring.stiffness"``):
        what ``with_parameters`` validates a new value against (None when unknown)."""
        if key == "gravity":
            return f"Model {self.model_name!r}", GRAVITY
        name, _, attr = key.rpartition(".")
        comp = self.topology.components.get(name)
        spec = None if comp is None else type(comp).spec(attr)
        if spec is None:   # a number inside a signal: "component.attribute.field"
            for comp in self.topology.components.values():
                if key.startswith(comp.name + ".") and hasattr(comp, "signal_spec"):
                    spec = comp.signal_spec(key[len(comp.name) + 1:])
                    if spec is not None:
                        break
        return None if spec is None else (comp, spec)

    @property
    def program(self):
        """The symbolic straight-line program (built on demand when code came from the cache)."""
        if self._program is None:
            self._build_program()
        return self._program

    def _build_program(self, ready=None, dense: bool = True):
        """Build the symbolic program (sympy: only when code is generated); ``ready(prog,
        names)``: called with the outputs as they become final (``build_program``), the
        parameter symbols already in place.  ``dense=False``: without the dense dynamics
        (``lazy_dense``), returned and not kept (``program`` is always the whole one)."""
        from mbcomp.build.equations import build_program
        equations = [] if self.constraint_set is None else self.constraint_set.equations
        parameters = [s for key in self.layout.entries for s in _as_list(self.layout.symbols(key))]

        def with_parameters(prog, names):
            prog.p = parameters
            ready(prog, names)

        program = build_program(self.topology, self.layout, self.inputs, equations, self.drives,
                                recursive=self.dynamics == "recursive", factors=bool(self.geometric_rows),
                                ready=with_parameters if ready else None, dense=dense)
        self._check_layout(program)
        program.p = parameters
        if dense:
            self._program = program
        return program

    def _check_layout(self, program) -> None:
        """The program's outputs must fill the output layout exactly (C and Python read them by it)."""
        for function, names in FUNCTIONS.items():
            if not all(name in program.outputs for name in names) and function == "dynamics" and self.lazy_dense:
                continue  # built on first use
            written = sum(len(program.outputs[name]) for name in names)
            if written != self.output_layout.size(function):
                raise ModelError(f"Model {self.model_name!r}", f"internal error: {function} writes {written} values, "
                                 f"its layout has {self.output_layout.size(function)}")

    def _load(self, use_cache: bool, backend: str):
        """The generated functions: from the cache, or generated and compiled (and cached).
        With the cache, the build holds the model's build lock (``cache.building``), so a
        process compiling the same model at the same time waits and then loads this one's."""
        if backend not in ("auto", "c", "python"):
            raise ModelError(f"Model {self.model_name!r}", f"backend must be 'auto', 'c' or 'python', got {backend!r}")
        if not use_cache:
            return self._load_unlocked(False, backend)
        lock = hashlib.sha256(f"{backend}\n{self.description}".encode()).hexdigest()
        with cache.building(f"build-{lock}"):
            return self._load_unlocked(True, backend)

    def _load_unlocked(self, cache: bool, backend: str):
        if backend in ("auto", "c"):
            functions = self._load_c(cache)
            if functions is not None:
                return functions
            if backend == "c":
                raise ModelError(f"Model {self.model_name!r}", "backend 'c' needs a working C compiler (set $CC)")
        return self._load_python(cache)

    def _c_sizes(self) -> CSizes:
        """The model's sizes, offsets and index tables for the C templates (``c_sizes``)."""
        nv, ng = self.topology.nv, len(self.geometric_rows)  # the mass matrix and accelerations are in speed space
        aba, parents = None, ()
        if self.dynamics == "recursive":
            aba, parents = recursive.aba_sizes(self.topology, self.n_inputs, factors=bool(ng))
        features = 0
        if self.contact_rows:  # room for the held collision features of the least-norm friction solve
            from mbcomp.compiled.collision_kernel import shape_features
            # (at most HELD_FEATURES_PER_SPEED a speed: the dae work grows with its rows squared,
            # and a model of many shapes has many more features than can touch at once)
            features = min(len(shape_features(self.topology)[2]), HELD_FEATURES_PER_SPEED * nv + 8)
        return CSizes.of(self.output_layout, nq=nv, ng=ng, state_map=self.topology.state_map, nz=self.drives.nz,
                         drives=bool(self.drives.elements), aba=aba, aba_parents=parents, features=features)

    def _c_templates(self, sizes: CSizes, lazy_dense: bool | None = None, reduced_loop: bool | None = None) -> str:
        """The hand-written C linked into every model: the tree accelerations, the
        formulations' code and the integrators.  Its text depends on the kind of model
        (``sizes.flags``; the formulations; dense or recursive), not on its sizes, which
        ``sizes.header`` declares and the model's own unit (``sizes.unit``) defines: models
        of one kind share one compiled object."""
        from mbcomp.codegen.integrators import c_integrators
        nv, ng = self.topology.nv, len(self.geometric_rows)
        tree = codegen.c_accelerations()
        if self.dynamics == "recursive":  # the tree solve, and the dae KKT solve, by the recursive program
            tree = recursive.c_accelerations(nv, self.n_inputs, tree, factors=bool(ng))
        lazy_dense = self.lazy_dense if lazy_dense is None else lazy_dense
        reduced_loop = self.reduced_loop if reduced_loop is None else reduced_loop
        reduced = "#define REDUCED_LOOP 1\n" if reduced_loop else ""
        if self.constraint_set is not None or self.contact_rows:  # the dae KKT solve (formulations/dae_c.py)
            reduced += "#define DAE_LOOP 1\n"
        return (reduced + sizes.header() + (codegen.c_dense_stub() if lazy_dense else "")
                + codegen.c_output_stubs(OUTPUT_FUNCTIONS) + c_text.read("mbcomp.codegen", "inputs.h") + "\n" + tree + codegen.c_collide()
                + "".join(snippet(nv, ng) for snippet in self.c_snippets)
                + (recursive.c_dae(self.topology, ng) if self.dynamics == "recursive" else "")
                + "\n#ifndef NDAEWORK\n#define NDAEWORK 0\n#endif\n"
                + c_integrators())

    def export_sources(self) -> list[tuple[str, str]]:
        """The C of this model's library as whole translation units ``[(name, text)]`` for
        building it elsewhere (an FMU, ``face/fmu``): the hand-written templates (with the
        dense dynamics built in, without the lagrange formulation's reduced loop, which needs
        Python to choose its partition), the generated functions (but the output functions,
        whose stubs write NaN) and the model's sizes.  The same text the library is compiled
        from: the program is generated again (sympy) when the code came from the cache."""
        sizes = self._c_sizes()
        functions = {f: outs for f, outs in self._functions().items() if f not in OUTPUT_FUNCTIONS}
        templates = codegen.c_prototypes(functions) + self._c_templates(sizes, lazy_dense=False, reduced_loop=False)
        return [("templates", templates), ("model", self._export_model_source(functions)), ("sizes", sizes.unit())]

    def _export_model_source(self, functions: dict) -> str:
        """The generated C of ``functions`` in one unit: printed from the program when it is in
        memory (this compile generated the code), else from the code cache (an earlier export
        of this model), else generated (sympy) and then cached, where the compile used the cache."""
        tools = cache.toolchain()
        key = cache.entry_key(self.description + "\nexport sources", self.key + codegen.generator_text(), tools)
        text = cache.read_text(key, ".c", tools) if self._program is None and self.use_cache else None
        if text is None:
            text = codegen.c_source(self.program, functions)
            if self.use_cache:
                cache.store(key, ".c", text.encode(), tools)
        return text

    def _load_c(self, use_cache: bool):
        compiler = c_compiler()
        if compiler is None:
            return None
        sizes = self._c_sizes()
        templates, sizes_unit = self._c_templates(sizes), sizes.unit()
        tools = cache.toolchain(compiler, C_FLAGS)
        plan = (f"cold units {' '.join(COLD_FLAGS)}; {UNIT_STATEMENTS} statements per unit, "
                f"packs of {EAGER_STATEMENTS} compiled as soon as their functions are final, "
                f"hot functions of more than {HALVE_STATEMENTS} in two halves, "
                "the sizes with the last cold unit")  # how the C is built
        self.key = cache.entry_key(self.description, templates + sizes_unit + plan + codegen.generator_text(), tools)
        if use_cache:
            path = cache.verified(self.key, ".so", tools)
            if path is not None:
                try:
                    functions = CFunctions(path, self.sizes)
                    self.cache_hit = True
                    return self._with_late_loaders(functions, compiler, use_cache)
                except (OSError, AttributeError):
                    cache.discard(self.key, ".so")  # loads but is not ours to use: rebuild it
        # Built apart, later: the dense dynamics of lazy_dense and the output functions.
        apart = OUTPUT_FUNCTIONS + (("dynamics",) if self.lazy_dense else ())
        functions = {f: outs for f, outs in self._functions().items() if f not in apart}
        cold = COLD_FUNCTIONS + self._cold_dynamics()
        build = CBuild(compiler)
        try:
            # The templates compile on another core while sympy generates the program; each
            # generated unit starts compiling as soon as it is printed.
            # Linked after the generated code, as in one unit: the layout of the integrators'
            # loops changes their speed by up to 15 % (N = 5 chain).
            build.add("templates", codegen.c_prototypes(functions) + templates, C_FLAGS, last=True,
                      shared=tools if use_cache else None, beside=True)
            # A size in an #if would read as 0: checked while the templates compile (16 ms of
            # regular expressions), before anything is linked; the build is cancelled if it fails.
            sizes.check_generic(templates)
            digest = hashlib.sha256((templates + sizes_unit).encode())

            def compile_units(units):
                for unit in units:
                    build.add(unit.name, unit.text, C_FLAGS if unit.hot else COLD_FLAGS, unit.statements)
                    digest.update(unit.text.encode())

            # Each function's units are printed and start compiling as soon as its outputs are
            # final, on the other core while sympy builds the rest of the program.
            stream, done, final, outputs_printed = None, set(), set(), False

            def print_outputs():
                """The output functions' C, printed once their outputs are final and cached with
                the model; compiled in the background (not waited for): at once, on a core the
                model's compilers and sympy leave idle, when small, else once the model's
                library is built (EARLY_OUTPUT_STATEMENTS)."""
                nonlocal outputs_printed
                outputs_printed = True
                texts, statements = zip(*(stream.apart(name, FUNCTIONS[name]) for name in OUTPUT_FUNCTIONS))
                self._output_source = "\n".join(texts)
                if use_cache:
                    key, tools_out = self._output_key(compiler)
                    cache.store(key, ".c", self._output_source.encode(), tools_out)
                if sum(statements) <= EARLY_OUTPUT_STATEMENTS:
                    self._build_outputs(compiler, use_cache)

            def ready(prog, names):
                nonlocal stream
                if stream is None:
                    stream = codegen.UnitStream(prog, cold=cold, unit=UNIT_STATEMENTS, eager=EAGER_STATEMENTS,
                                                 halve=HALVE_STATEMENTS)
                final.update(names)
                now = {f: outs for f, outs in functions.items() if f not in done and set(outs) <= final}
                done.update(now)
                compile_units(stream.add(now))
                if not outputs_printed and all(set(FUNCTIONS[name]) <= final for name in OUTPUT_FUNCTIONS):
                    print_outputs()

            program = self._program
            if program is None:
                program = self._build_program(ready, dense=not self.lazy_dense)
            if stream is None:
                stream = codegen.UnitStream(program, cold=cold, unit=UNIT_STATEMENTS, eager=EAGER_STATEMENTS,
                                            halve=HALVE_STATEMENTS)
            compile_units(stream.add({f: outs for f, outs in functions.items() if f not in done}))
            compile_units(codegen.with_unit_text(stream.flush(), "sizes", sizes_unit))
            if not outputs_printed:
                print_outputs()
        except BaseException:
            build.cancel()
            raise
        inputs = {**tools, "cold_flags": list(COLD_FLAGS), "source_sha256": digest.hexdigest()}
        functions = c_library(build.finish(), self.sizes, key=self.key if use_cache else None, inputs=inputs)
        if functions is None:
            return None
        if self._outputs_build is None:
            self._build_outputs(compiler, use_cache)
        return self._with_late_loaders(functions, compiler, use_cache)

    def _build_outputs(self, compiler: str, use_cache: bool) -> None:
        """Start compiling the output functions' library in the background, at a low priority
        (``BACKGROUND_NICE``), beside the model's own compilers or after them
        (``EARLY_OUTPUT_STATEMENTS``): the compile returns without waiting for it, the first
        ``energy``/``body_state`` waits for what is left, and it is stored in this compile's
        cache directory.  Not while every core is busy (``spare_core``): the library may never
        be asked for (in the test suite, two builds in three were not), and the first
        ``energy``/``body_state`` builds it then."""
        if not spare_core():
            return
        key, tools = self._output_key(compiler)
        inputs = {**tools, "source_sha256": hashlib.sha256(self._output_source.encode()).hexdigest()}
        store = None
        if use_cache:
            directory = cache.cache_dir()
            store = lambda data: cache.store(key, ".so", data, inputs, directory=directory)  # noqa: E731
        self._outputs_build = BackgroundBuild(self._output_source, compiler, COLD_FLAGS, store)

    def wait_for_background(self) -> None:
        """Wait until the output functions' library being built in the background is done
        (it is then cached; for tests and benchmarks that look at the cache)."""
        build = self._outputs_build
        if build is not None:
            build.result()

    def _with_late_loaders(self, functions: CFunctions, compiler: str, use_cache: bool) -> CFunctions:
        """Give the library the means to build what it leaves out on first use: the output
        functions, and the dense dynamics of ``lazy_dense``."""
        for name in OUTPUT_FUNCTIONS:
            functions.late[name] = (lambda: self.output_library(compiler, use_cache), f"set_{name}_impl", name)
        if self.lazy_dense:
            functions.late["dynamics"] = (lambda: self.dense_library(compiler, use_cache), "set_dense_dynamics",
                                          "dynamics_dense")
        return functions

    def _output_key(self, compiler: str) -> tuple[str, dict]:
        """The cache key of the output functions' library and of their C, with the toolchain."""
        tools = cache.toolchain(compiler, COLD_FLAGS)
        key = cache.entry_key(self.description + "\noutput functions", self.key + codegen.generator_text(), tools)
        return key, tools

    def output_library(self, compiler: str, use_cache: bool = True):
        """The library of the ``OUTPUT_FUNCTIONS`` (energy, body kinematics), loaded when one
        of them is first called, once: the one this compile built in the background, else the
        cached one, else compiled from the C the compile printed or the cache kept (no sympy),
        else generated again from the program."""
        with self._outputs_lock:
            if self._outputs is None:
                self._outputs = self._background_outputs()
            if self._outputs is None:
                key, tools = self._output_key(compiler)

                def source() -> str:
                    text = self._output_source or (cache.read_text(key, ".c", tools) if use_cache else None)
                    return text or codegen.c_source(self.program, {name: FUNCTIONS[name] for name in OUTPUT_FUNCTIONS})
                self._outputs = self._side_library(key, tools, source, "the output functions", use_cache)
            return self._outputs

    def _background_outputs(self):
        """The output functions' library built in the background by this compile (waiting
        for it), or None (none started, it failed, or this is a forked child)."""
        build, self._outputs_build = self._outputs_build, None
        data, path = build.result() if build is not None else (None, None)
        if data is None:
            return None
        if path is not None:
            try:
                return ctypes.CDLL(str(path))
            except OSError:
                pass
        return load_library_bytes(data)

    def dense_library(self, compiler: str, use_cache: bool = True):
        """The dense dynamics (``dynamics_dense``: mass matrix and forces) of a model whose
        library leaves them out (``lazy_dense``), as a library of their own: from the cache, or
        generated (sympy) and compiled now, once; its own cache entry, keyed by the model's."""
        tools = cache.toolchain(compiler, COLD_FLAGS)
        key = cache.entry_key(self.description + "\ndense dynamics", self.key + codegen.generator_text(), tools)
        source = lambda: codegen.c_source(self.program, {"dynamics_dense": FUNCTIONS["dynamics"]})  # noqa: E731
        return self._side_library(key, tools, source, "the dense dynamics", use_cache)

    def _side_library(self, key: str, tools: dict, source, what: str, use_cache: bool):
        """A library of its own beside the model's (``CFunctions.late``), compiled without
        optimisation from ``source()`` unless the cache has it (entry ``key``), once."""
        compiler = tools["compiler"]
        with cache.building(f"build-{key}") if use_cache else contextlib.nullcontext():
            path = cache.verified(key, ".so", tools) if use_cache else None
            if path is not None:
                try:
                    return ctypes.CDLL(str(path))
                except OSError:
                    cache.discard(key, ".so")
            text = source()
            data = compile_c(text, compiler, COLD_FLAGS)
            if data is None:
                raise ModelError(f"Model {self.model_name!r}", f"the C compiler failed on {what}")
            inputs = {**tools, "source_sha256": hashlib.sha256(text.encode()).hexdigest()}
            path = cache.store(key, ".so", data, inputs) if use_cache else None
            if path is not None:
                return ctypes.CDLL(str(path))
            return load_library_bytes(data)

    def _load_python(self, use_cache: bool):
        tools = cache.toolchain()
        self.key = cache.entry_key(self.description, codegen.generator_text(), tools)
        source = cache.read_text(self.key, ".py", tools) if use_cache else None
        if source is not None:
            self.cache_hit = True
        else:
            source = codegen.python_source(self.program, self._functions())
            if use_cache:
                inputs = {**tools, "source_sha256": hashlib.sha256(source.encode()).hexdigest()}
                cache.store(self.key, ".py", source.encode(), inputs)
        functions = PythonFunctions(source, self.key, self.sizes)
        if self.dynamics == "recursive":  # the generated aba replaces numpy's dense solve
            solve = recursive.PythonAccelerations(codegen.load_python(source, self.key)["aba"], self.topology.nv)
            functions.accelerations, functions.bind_parameters = solve, solve.bind_parameters
        return functions

    def _functions(self) -> dict:
        """The generated functions ``{name: [output names]}``: the recursive program adds ``aba``."""
        return {**FUNCTIONS, "aba": ["aba"]} if self.dynamics == "recursive" else FUNCTIONS


def _as_list(x):
    return x if isinstance(x, list) else [x]
