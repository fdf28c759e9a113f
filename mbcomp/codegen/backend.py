"""Numeric backends for the generated program: plain Python, or C compiled and loaded with ctypes."""
from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import shutil
import subprocess
import sysconfig
import tempfile
import threading
import time
import warnings
from pathlib import Path

import numpy as np

from mbcomp.codegen import cache, printer as codegen

FUNCTIONS = {
    "dynamics": ["mass_matrix", "forces"],
    "energy": ["energy"],
    "kinematics": ["kinematics"],
    "constraints": ["constraints"],
    "contacts": ["contacts"],
    "drives": ["drive_forces", "state_rates"],
}
#: Called per output sample or step, not per right-hand side: compiled without optimisation.
COLD_FUNCTIONS = ("energy", "kinematics", "contacts")
#: Evaluated on results (energies, body states), never while stepping: compiled into a library
#: of their own in the background, at a low priority (``CompiledModel.output_library``),
#: so a compile returns once the right-hand side is ready.  The model's library calls them
#: through ``codegen.c_output_stubs``.
OUTPUT_FUNCTIONS = ("energy", "kinematics")


#: errno values of a full disk (or a full quota).
DISK_FULL = (errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC))


def write_file(path: Path, data: str | bytes) -> None:
    """Write ``data`` to ``path``; an ``OSError`` raised while writing (a full disk raises at
    the write or the close, where Python leaves the file name out) names ``path``."""
    try:
        with open(path, "wb") as fh:
            fh.write(data.encode() if isinstance(data, str) else data)
    except OSError as exc:
        if exc.filename is None:
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise


def build_failure(exc: OSError) -> str:
    """What a compile that could not write its files says: that the disk is full and where."""
    where = exc.filename or tempfile.gettempdir()
    if exc.errno in DISK_FULL:
        return (f"the disk is full: cannot write {where} ({exc.strerror or exc}); free space there, or point "
                f"TMPDIR (build files) and MBCOMP_CACHE_DIR (the code cache) at a disk with room")
    return f"cannot write the build files: {where}: {exc.strerror or exc}"


class PythonFunctions:
    """Generated Python functions ``f(q, qd, p, u) -> ndarray``."""

    name = "python"

    def __init__(self, source: str, key: str, sizes: dict | None = None):
        self.source = source
        self.sizes = sizes or {}
        ns = codegen.load_python(source, key)
        self._fns = {name: ns[name] for name in FUNCTIONS}

    def __call__(self, name: str, q, qd, p, u) -> np.ndarray:
        try:
            return np.array(self._fns[name](q.tolist(), qd.tolist(), p.tolist(), u.tolist()), dtype=float)
        except (ZeroDivisionError, OverflowError, ValueError):
            # Python raises where C gives inf/NaN (1/0, sqrt of a negative): behave like C
            # so that the System's checks name the cause.
            return np.full(self.sizes[name], np.nan)

    accelerations = None  # the System solves M qdd = f with numpy

    def many(self, name: str, q: np.ndarray, qd: np.ndarray, p: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``name`` at every row of ``q``, ``qd`` (``u``: one row for all) -> (m, size)."""
        return np.array([self(name, qi, qdi, p, u) for qi, qdi in zip(q, qd)]).reshape(len(q), self.sizes[name])


def c_compiler() -> str | None:
    """Path of a working C compiler (``$CC``, cc, gcc, clang) or None."""
    for candidate in (os.environ.get("CC"), sysconfig.get_config_var("CC"), "cc", "gcc", "clang"):
        if not candidate:
            continue
        exe = shutil.which(candidate.split()[0])
        if exe:
            return exe
    return None


class CFunctions:
    """The same functions compiled from generated C, called through ctypes.

    On the hot path (``accelerations``) pointers are bound once, per thread and per
    System: converting arrays to ctypes pointers costs about a microsecond per argument
    and call, copying a state into a bound buffer a tenth of that.
    """

    name = "c"

    def __init__(self, library_path: Path, sizes: dict):
        self.lib = ctypes.CDLL(str(library_path))
        self.path = library_path
        self.sizes = sizes
        self.nq = sizes["nq"]
        self.nv = sizes.get("nv", self.nq)
        void = ctypes.c_void_p
        self._fns = {}
        for name in FUNCTIONS:
            fn = getattr(self.lib, name)
            fn.argtypes = [void] * 5
            fn.restype = None
            self._fns[name] = fn
        self._accelerations = self.lib.accelerations  # called with bound pointer objects only
        self._accelerations.restype = ctypes.c_int
        self._empty = np.zeros(1)
        self._local = threading.local()
        #: Functions this library calls through a stub until their own library is loaded
        #: (``codegen.c_late_stub``): ``{name: (loader, setter, symbol)}``, the loader giving
        #: the library that defines ``symbol``, called on the first call of ``name`` (the
        #: stub writes NaN until then): the dense dynamics of ``CompiledModel.lazy_dense``
        #: and the ``OUTPUT_FUNCTIONS``.
        self.late: dict = {}
        #: The late functions loaded so far: ``{name: library}``.
        self.loaded: dict = {}
        self._late_lock = threading.Lock()

    def ensure(self, name: str) -> None:
        """Load the library of the late function ``name`` (once) and point this library's
        stub at it; nothing for a function of this library."""
        if name not in self.late or name in self.loaded:
            return
        with self._late_lock:
            if name not in self.loaded:
                loader, setter_name, symbol = self.late[name]
                library = loader()
                setter = getattr(self.lib, setter_name)
                setter.argtypes, setter.restype = [ctypes.c_void_p], None
                setter(ctypes.cast(getattr(library, symbol), ctypes.c_void_p))
                self.loaded[name] = library  # (kept loaded while this library is)

    def __call__(self, name: str, q, qd, p, u) -> np.ndarray:
        """The packed output of generated function ``name`` at ``(q, qd)`` with parameters ``p``
        and inputs ``u`` (a new array).  The arguments are copied into this thread's buffers,
        whose pointers are bound once: taking an array's pointer costs 1.6 us, a copy 0.3 us."""
        if name in self.late:
            self.ensure(name)
        local = self._local
        calls = getattr(local, "calls", None)
        if calls is None:
            calls = local.calls = {}
            local.p = (None, None)
        bound = calls.get(name)
        if bound is None or len(bound[2]) < len(u):
            arrays = (np.empty(self.nq), np.empty(self.nv), np.zeros(max(len(u), 1)), np.empty(self.sizes[name]))
            bound = calls[name] = (*arrays, [ctypes.c_void_p(a.ctypes.data) for a in arrays])
        q_in, qd_in, u_in, out, pointers = bound
        q_in[:] = q
        qd_in[:] = qd
        if len(u):
            u_in[:len(u)] = u
        if local.p[0] is not p:  # the kernel's parameter vector: the same object call after call
            local.p = (p, ctypes.c_void_p(p.ctypes.data))
        self._fns[name](pointers[0], pointers[1], local.p[1], pointers[2], pointers[3])
        return out.copy()

    def many(self, name: str, q: np.ndarray, qd: np.ndarray, p: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``name`` at every row of ``q``, ``qd`` in one call of the compiled code (``u``: one
        row for all) -> (m, size).  A Python loop over ``__call__`` costs ~20 us per row."""
        if name in self.late:
            self.ensure(name)
        q = np.ascontiguousarray(q, dtype=float)
        qd = np.ascontiguousarray(qd, dtype=float)
        m = len(q)
        out = np.empty((m, self.sizes[name]))
        if m == 0:
            return out
        u = np.ascontiguousarray(u if len(u) else self._empty, dtype=float)
        fn = getattr(self.lib, f"{name}_many")
        fn.restype = None
        long, void = ctypes.c_long, ctypes.c_void_p
        fn.argtypes = [long, void, long, void, long, void, void, long, void]
        fn(m, q.ctypes.data, q.shape[1], qd.ctypes.data, qd.shape[1], p.ctypes.data, u.ctypes.data, 0,
           out.ctypes.data)
        return out

    def bind_parameters(self, p: np.ndarray):
        """A pointer object for a System's parameter vector, built once per System."""
        return ctypes.c_void_p(p.ctypes.data)

    def _buffers(self, n_inputs: int):
        """This thread's input/output buffers and their bound pointers."""
        buffers = getattr(self._local, "buffers", None)
        if buffers is None or len(buffers[0]["u"]) < n_inputs:
            n = self.nv  # speeds: the mass matrix, forces and accelerations are nv-sized
            arrays = {"q": np.empty(self.nq), "qd": np.empty(n), "u": np.zeros(max(n_inputs, 1)), "tau": np.empty(n),
                      "out": np.empty(n), "work": np.empty(n * (n + 1) // 2 + n)}
            pointers = {k: ctypes.c_void_p(v.ctypes.data) for k, v in arrays.items()}
            buffers = self._local.buffers = (arrays, pointers)
        return buffers

    def accelerations(self, q, qd, p_pointer, u, tau) -> tuple[int, np.ndarray]:
        """Tree accelerations ``(status, qdd)`` (status 0 = ok) from the compiled code."""
        arrays, pointers = self._buffers(len(u))
        arrays["q"][:] = q
        arrays["qd"][:] = qd
        if len(u):
            arrays["u"][: len(u)] = u
        if tau is not None:
            arrays["tau"][:] = tau
        status = self._accelerations(pointers["q"], pointers["qd"], p_pointer, pointers["u"],
                                     None if tau is None else pointers["tau"], pointers["out"], pointers["work"])
        return status, arrays["out"].copy()


#: Flags of the hot code (the generated right-hand side, the solves and the integrators);
#: chosen by measurement (bench/compile_startup.py): -O1 runs the right-hand side 2.5-4.5x
#: faster than -O0 for twice the compile time, -O2 is no faster than -O1 and compiles 1.3-1.8x
#: longer.  Part of the cache key, with ``COLD_FLAGS`` and the unit plan.  The C declares the
#: C library functions it calls itself (``codegen.C_MATH``, ``codegen.C_TEMPLATE_LIBC``): a call
#: it does not declare is an error, never an implicit ``int`` function.
C_FLAGS = ("-O1", "-fPIC", "-fno-math-errno", "-Werror=implicit-function-declaration")
#: Flags of the cold units (functions called per output sample, not per step).
COLD_FLAGS = ("-O0", "-fPIC", "-fno-math-errno", "-Werror=implicit-function-declaration")
#: Output functions of at most this many statements start compiling in the background as soon
#: as they are printed, beside the model's own compilers (an unoptimised compiler of a unit
#: this size holds little memory); longer ones once the model's library is built: at N = 50
#: (3,448 statements) started early they raised the peak memory from 195-225 to 250-285 MiB.
EARLY_OUTPUT_STATEMENTS = 1500
#: Statements per generated translation unit (``codegen.c_units``).
UNIT_STATEMENTS = 1500
#: Short functions packed into one unit: a pack of this many statements starts compiling as soon
#: as its functions are final instead of waiting for more (``codegen.UnitStream``).
EAGER_STATEMENTS = 300
#: A hot function longer than this (and shorter than a unit) is compiled as two halves side
#: by side (``codegen.UnitStream``): measured on the chain, -O1 takes 0.22 s for the 354
#: statements of N = 5 in one unit, 0.07 + 0.10 s in two; 0.52 s for N = 10 (804), 0.17 + 0.25 s.
HALVE_STATEMENTS = 300


def compile_jobs() -> int:
    """How many compilers run at once: the cores this process may use (at most 4: each
    compiler of a large unit holds ~100 MiB)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(cores, 4))


class CBuild:
    """A shared library built from C units compiled in parallel in a private temporary
    directory (removed on every path), then linked.

    Units start compiling as they are added (the longest waiting first when every job
    slot is busy), so a caller can add the hand-written templates before it generates the
    model's code and compile them meanwhile.  ``finish`` links and returns the library's
    bytes, or None (with a warning) when a compiler fails.
    """

    TIMEOUT = 600

    def __init__(self, compiler: str, jobs: int | None = None):
        self.compiler = compiler
        self.jobs = jobs or compile_jobs()
        self._tmp = Path(tempfile.mkdtemp(prefix="mbcomp-build-"))
        self._waiting: list = []   # (statements, name, flags)
        self._running: list = []   # (process, name)
        self._beside: set[str] = set()  # units whose compiler takes no job slot (``add(beside=True)``)
        self._objects: list[str] = []
        self._linked_last: list[str] = []
        self._failure: str | None = None
        self._shared: list = []    # (object path, cache key, toolchain inputs) to store once compiled
        self._held = contextlib.ExitStack()  # build locks of the shared units this build compiles
        self._deferred: list = []  # shared units another process is compiling: (add's arguments, key)
        # Each compiler has a thread that waits for it (no polling) and then reaps it and starts
        # the next waiting unit, also while the caller is busy building the rest of the program
        # in Python: a free core never waits for the next ``add``, nor for a timer.
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)  # notified when a compiler ends
        self._stop = threading.Event()

    def add(self, name: str, text: str, flags: tuple[str, ...], statements: int = 0, last: bool = False,
            shared: dict | None = None, beside: bool = False) -> None:
        """Queue ``text`` as unit ``name`` (a file stem, unique in this build), compiled with
        ``flags``; ``last``: linked after the units without it (the library's layout).

        ``beside``: its compiler starts at once and takes none of the ``jobs`` slots (the
        hand-written templates, added before the program exists: a generated unit printed
        while they compile starts too instead of waiting for them, which at N = 5 put the
        second half of the dynamics 0.1-0.15 s later on the build's critical path).

        ``shared``: the toolchain inputs of the code cache (``cache.toolchain``) for a unit
        many models have in common (the hand-written templates of one model structure): its
        object file is taken from the cache when a signed copy is there, and stored after
        compiling otherwise, so models of the same kind compile it once.  While one process
        compiles it (under its build lock), another leaves it to the end of its own build
        (``finish``) and then links the first one's object."""
        obj = self._tmp / f"{name}.o"
        (self._linked_last if last else self._objects).append(str(obj))  # link order
        if shared is not None:
            key = cache.entry_key(f"object {name}", text + " ".join(flags), shared)
            if self._copy_cached(key, shared, obj):
                return
            if not self._held.enter_context(cache.building(f"object-{key}", wait=0)):
                self._deferred.append(((name, text, flags, statements, shared), key))
                return
            self._shared.append((obj, key, shared))
        if beside:
            self._beside.add(name)
        self._queue(name, text, flags, statements)

    @staticmethod
    def _copy_cached(key: str, shared: dict, obj: Path) -> bool:
        """Copy the signed cached object ``key`` to ``obj``; False when there is none."""
        path = cache.verified(key, ".o", shared)
        if path is None:
            return False
        try:
            shutil.copyfile(path, obj)
            return True
        except OSError:
            return False

    def _queue(self, name: str, text: str, flags: tuple[str, ...], statements: int) -> None:
        """Write unit ``name`` and queue it for a free compiler slot."""
        write_file(self._tmp / f"{name}.c", text)
        with self._lock:
            self._waiting.append((statements, name, tuple(flags)))
            self._waiting.sort(key=lambda item: item[0])
        self._pump()

    def _reap(self, process: subprocess.Popen) -> None:
        """A compiler's own thread: wait for it to end, then reap it and start what waits."""
        process.wait()
        with self._changed:
            if not self._stop.is_set():
                self._pump_once()
            self._changed.notify_all()

    def _pump(self, block: bool = False) -> None:
        """Reap finished compilers and start waiting units while slots are free; with
        ``block``, until every unit is compiled (or one failed, or ``TIMEOUT`` s passed)."""
        deadline = time.monotonic() + self.TIMEOUT
        with self._changed:
            self._pump_once()
            while block and self._running:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    self._failure = f"a compiler ran for more than {self.TIMEOUT} s"
                    return
                self._changed.wait(remaining)
                self._pump_once()

    def _pump_once(self) -> None:
        """Reap finished compilers and start waiting units while slots are free (under the lock)."""
        still = []
        for process, name in self._running:
            if process.poll() is None:
                still.append((process, name))
            elif process.returncode and self._failure is None:
                log = self._tmp / f"{name}.log"
                self._failure = (log.read_text(errors="replace")[-2000:] if log.exists() else "") or \
                    f"exit status {process.returncode} compiling {name}"
        self._running = still
        busy = sum(name not in self._beside for _, name in self._running)
        while self._waiting and self._failure is None:
            # The longest waiting unit (the list is sorted by length) that may start now.
            ready = [k for k, (_, name, _) in enumerate(self._waiting) if busy < self.jobs or name in self._beside]
            if not ready:
                break
            _, name, flags = self._waiting.pop(ready[-1])
            busy += name not in self._beside
            source, obj = self._tmp / f"{name}.c", self._tmp / f"{name}.o"
            cmd = [self.compiler, *flags, "-c", str(source), "-o", str(obj)]
            try:
                with open(self._tmp / f"{name}.log", "wb") as log:  # a file: a pipe could fill and block
                    process = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log, stderr=log)
            except OSError as exc:
                self._failure = str(exc)
                break
            self._running.append((process, name))
            threading.Thread(target=self._reap, args=(process,), name=f"mbcomp-cc-{name}", daemon=True).start()

    def finish(self) -> bytes | None:
        """Wait for every unit, link them, remove the directory; the library's bytes or None."""
        try:
            self._pump(block=True)
            self._store_shared()
            for (name, text, flags, statements, shared), key in self._deferred:
                obj = self._tmp / f"{name}.o"
                with cache.building(f"object-{key}"):  # the other process is done with it
                    if self._copy_cached(key, shared, obj):
                        continue
                self._shared.append((obj, key, shared))  # it failed or gave up: compile it here
                self._queue(name, text, flags, statements)
            self._pump(block=True)
            self._store_shared()
            if self._failure is None:
                out = self._tmp / "model.so"
                done = subprocess.run([self.compiler, "-shared", "-fPIC", *self._objects,
                                       *self._linked_last, "-o", str(out), "-lm"],
                                      capture_output=True, timeout=600, check=False)
                if done.returncode == 0:
                    return out.read_bytes()
                self._failure = done.stderr.decode(errors="replace")[-2000:]
            if "No space left on device" in self._failure:  # (a compiler's or linker's own writes)
                raise OSError(errno.ENOSPC, "No space left on device", str(self._tmp))
            warnings.warn(f"mbcomp: the C compiler failed, using the Python backend: {self._failure}",
                          RuntimeWarning, stacklevel=3)
            return None
        except OSError as exc:
            if exc.errno in DISK_FULL:
                raise
            return None
        except subprocess.SubprocessError:
            return None
        finally:
            self.cancel()

    def _store_shared(self) -> None:
        """Store the shared units compiled so far in the cache and release their build locks."""
        if self._failure is None:
            for obj, key, inputs in self._shared:
                cache.store(key, ".o", obj.read_bytes(), inputs)
        self._shared = []
        self._held.close()

    def cancel(self) -> None:
        """Stop every compiler still running and remove the build directory."""
        self._held.close()
        self._stop.set()
        with self._lock:
            for process, _ in self._running:
                process.kill()
                process.wait()
            self._running, self._waiting = [], []
        shutil.rmtree(self._tmp, ignore_errors=True)


#: The niceness of a background build: about a tenth of a core where every core is busy (CFS
#: weights 110 against 1024), so it barely slows the model's own compilers, yet a caller who
#: waits for it on a machine loaded by others waits a few times its compile time, not the
#: seventy times of the lowest priority (19).
BACKGROUND_NICE = 10


def spare_core() -> bool:
    """Whether the machine has a core to spare for work done ahead of need: the 1-minute
    load average is below the number of cores less a half (as ``make -l`` limits its jobs).
    Where every core is busy (parallel test runs, process pools, other users) such work
    only takes time from the work asked for; where the load cannot be read, assume a core."""
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):  # no load average (Windows)
        return True
    return load < (os.cpu_count() or 1) - 0.5


def compile_c(source: str, compiler: str, flags: tuple[str, ...] = C_FLAGS, *, idle: bool = False) -> bytes | None:
    """The shared library built from one C ``source`` with ``flags`` (its bytes), or None when
    the compiler fails (with a warning).  One compiler run compiles and links (the driver,
    compiler and linker start once: about 40 ms less than two runs); the build directory is
    removed on every path.  ``idle``: the compiler runs at a low priority (``nice -n
    BACKGROUND_NICE``, where there is a ``nice``), mostly on cores nothing else wants."""
    tmp = Path(tempfile.mkdtemp(prefix="mbcomp-build-"))
    try:
        unit, out = tmp / "unit.c", tmp / "library.so"
        write_file(unit, source)
        nice = shutil.which("nice") if idle else None
        command = [*([nice, "-n", str(BACKGROUND_NICE)] if nice else []),
                   compiler, *flags, "-shared", str(unit), "-o", str(out), "-lm"]
        done = subprocess.run(command, stdin=subprocess.DEVNULL,
                              capture_output=True, timeout=CBuild.TIMEOUT, check=False)
        if done.returncode == 0:
            return out.read_bytes()
        failure = done.stderr.decode(errors="replace")[-2000:]
    except (OSError, subprocess.SubprocessError) as exc:
        failure = str(exc)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    warnings.warn(f"mbcomp: the C compiler failed: {failure}", RuntimeWarning, stacklevel=2)
    return None


class BackgroundBuild:
    """A library compiled by ``compile_c`` on a thread of its own while the caller goes on
    (the compiler is another process: the thread holds no GIL while it waits), at a low
    priority (``BACKGROUND_NICE``): it takes mostly the cores the caller's own compilers and
    work leave idle.  ``store``: called on the thread with the bytes (e.g. to cache them), its
    return value kept.  The thread is not a daemon: the interpreter waits for it at exit, so
    what it stores is whole."""

    def __init__(self, source: str, compiler: str, flags: tuple[str, ...], store=None):
        self._pid = os.getpid()
        self._done = threading.Event()
        self._outcome: tuple = (None, None)

        def run():
            try:
                data = compile_c(source, compiler, flags, idle=True)
                self._outcome = (data, store(data) if data is not None and store is not None else None)
            finally:
                self._done.set()
        threading.Thread(target=run, name="mbcomp-background-build", daemon=False).start()

    def result(self) -> tuple:
        """``(bytes or None, what store returned)`` once the build is done; ``(None, None)`` in a
        forked child, which has no copy of the thread (the caller then builds it itself)."""
        if os.getpid() != self._pid:
            return None, None
        self._done.wait()
        return self._outcome


def load_library_bytes(data: bytes) -> ctypes.CDLL:
    """Load library bytes (not cached) from a private temporary directory, removed once loaded."""
    tmp = tempfile.mkdtemp(prefix="mbcomp-")
    try:
        path = Path(tmp) / "library.so"
        write_file(path, data)
        return ctypes.CDLL(str(path))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def load_private(data: bytes, sizes: dict) -> "CFunctions":
    """Load library bytes from a private temporary directory, removed once loaded (a
    loaded library stays mapped after its file is gone)."""
    tmp = tempfile.mkdtemp(prefix="mbcomp-")
    try:
        path = Path(tmp) / "model.so"
        write_file(path, data)
        return CFunctions(path, sizes)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def c_functions(source: str, sizes: dict, *, key: str | None = None, inputs: dict | None = None) -> "CFunctions | None":
    """Compile ``source`` and load it; with ``key``, also store it in the cache (signed
    manifest with ``inputs``).  None when no compiler works."""
    compiler = c_compiler()
    if compiler is None:
        return None
    return c_library(compile_c(source, compiler), sizes, key=key, inputs=inputs)


def c_library(data: bytes | None, sizes: dict, *, key: str | None = None,
              inputs: dict | None = None) -> "CFunctions | None":
    """Load built library bytes; with ``key``, store them in the cache first (signed manifest
    with ``inputs``) and load them from there.  None when there is no library."""
    if data is None:
        return None
    if key is not None:
        path = cache.store(key, ".so", data, inputs or {})
        if path is not None:
            try:
                return CFunctions(path, sizes)
            except OSError:
                cache.discard(key, ".so")
    return load_private(data, sizes)
