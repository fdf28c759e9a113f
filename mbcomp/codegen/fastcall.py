"""Fast public evaluation calls: accelerations, mass matrix and body kinematics from Python
at a fraction of a microsecond above the generated code itself.

A call through ``ctypes`` costs about a microsecond per argument (conversions, pointer
objects), several times the generated dynamics of a small model.  So where a C compiler and
Python's headers (``Python.h``, and numpy's) are available, a tiny CPython extension,
independent of any model, is built once per toolchain and kept in the code cache.  Its
``Calls`` object holds the addresses of one compiled model's functions and one parameter
vector, and takes the user's arrays as they are: a float64, aligned, C-contiguous,
native-order 1-D ndarray of the right length with finite entries goes straight to the
generated code; anything else (lists, dicts, other dtypes, wrong lengths, NaN) makes the
call return ``None`` and the caller takes its checked path, which converts or raises a
clear ``ModelError``.  Non-finite results and singular mass matrices also return ``None``,
so the checked path explains them.  The extension keeps the GIL (calls take microseconds)
and uses only its stack and fresh output arrays: concurrent calls from threads are safe.

Without the headers, ``CtypesCalls`` gives the same interface through ``ctypes``.
"""
from __future__ import annotations

import ctypes
import functools
import math
import importlib.machinery
import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np

from mbcomp.codegen import backend, cache
from mbcomp.core import c_text
from mbcomp.build.layout import BODY_FIELDS

MODULE = "mbcomp_fastcall"
#: Flags of the extension (part of its cache key).
FLAGS = ("-O2", "-shared", "-fPIC")

#: The extension's C (``c/fastcall.c``; part of its cache key).
SOURCE = c_text.read("mbcomp.codegen", "fastcall.c")


def _headers() -> list[str] | None:
    """Include directories with ``Python.h`` and numpy's headers, or None."""
    python = sysconfig.get_paths().get("include")
    numpy_include = np.get_include()
    if not python or not (Path(python) / "Python.h").is_file():
        return None
    if not (Path(numpy_include) / "numpy" / "arrayobject.h").is_file():
        return None
    return [python, numpy_include]


def _flags() -> tuple[str, ...]:
    return FLAGS + (("-undefined", "dynamic_lookup") if sys.platform == "darwin" else ())


def _load_module(path: Path):
    loader = importlib.machinery.ExtensionFileLoader(MODULE, str(path))
    spec = importlib.util.spec_from_file_location(MODULE, str(path), loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def _build(compiler: str, includes: list[str]) -> bytes | None:
    with tempfile.TemporaryDirectory(prefix="mbcomp-fastcall-") as tmp:
        src, out = Path(tmp) / "fastcall.c", Path(tmp) / "fastcall.so"
        src.write_text(SOURCE)
        cmd = [compiler, *_flags(), *(f"-I{d}" for d in includes), str(src), "-o", str(out)]
        try:
            subprocess.run(cmd, check=True, capture_output=True, timeout=300)
            return out.read_bytes()
        except (OSError, subprocess.SubprocessError):
            return None


_lock = threading.Lock()


@functools.lru_cache(maxsize=1)
def _extension():
    includes = _headers()
    compiler = backend.c_compiler()
    if includes is None or compiler is None:
        return None
    tools = cache.toolchain(compiler, _flags())
    tools["numpy"] = np.__version__
    key = cache.entry_key(f"fastcall extension {MODULE}", SOURCE + "|".join(includes), tools)
    path = cache.verified(key, ".so", tools)
    if path is not None:
        try:
            return _load_module(path)
        except (ImportError, OSError):
            cache.discard(key, ".so")
    data = _build(compiler, includes)
    if data is None:
        return None
    path = cache.store(key, ".so", data, tools)
    if path is not None:
        try:
            return _load_module(path)
        except (ImportError, OSError):
            cache.discard(key, ".so")
    tmp = tempfile.mkdtemp(prefix="mbcomp-fastcall-")
    try:  # an unusable cache: load from a private copy (the mapping outlives the file)
        private = Path(tmp) / "fastcall.so"
        private.write_bytes(data)
        return _load_module(private)
    except (ImportError, OSError):
        return None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def extension():
    """The compiled extension module (built on first use, then from the code cache), or None
    where there is no C compiler, no ``Python.h`` or numpy headers, or the build fails.
    ``MBCOMP_FASTCALL=ctypes`` in the environment disables it (the ``ctypes`` path)."""
    if os.environ.get("MBCOMP_FASTCALL", "").lower() == "ctypes":
        return None
    with _lock:
        return _extension()


def _address(lib, name: str) -> int:
    return ctypes.cast(getattr(lib, name), ctypes.c_void_p).value


def _offsets(layout) -> dict[str, int]:
    starts, start = {}, 0
    for name, width in BODY_FIELDS:
        starts[name] = start
        start += width
    return {"dyn_size": layout.size("dynamics"), "mm_off": layout.block("dynamics", "mass_matrix").offset,
            "kin_size": layout.size("kinematics"), "bodies_off": layout.block("kinematics", "bodies").offset,
            "body_row": start, "rot_off": starts["rotation"], "origin_off": starts["origin"],
            "vel_off": starts["velocity"], "n_bodies": layout.block("kinematics", "bodies").shape[0]}


def _plain(a: Any, n: int) -> bool:
    """``a`` is a float64 ndarray of shape (n,) with finite entries (what the fast path takes)."""
    if type(a) is not np.ndarray or a.dtype != np.float64 or a.shape != (n,):
        return False
    total = float(a.sum())
    return total - total == 0.0 or bool(np.all(np.isfinite(a)))


def _finite(a: np.ndarray) -> bool:
    """Every entry of ``a`` finite (a dot product that overflows says no: the caller's checked
    path then decides, so this never wrongly says yes)."""
    return math.isfinite(a.dot(a))


class CtypesCalls:
    """The extension's ``Calls`` interface through ``ctypes`` (where it cannot be built).

    Same contract: the result, or ``None`` when the inputs or the result need the checked
    path.  ``accelerations`` copies the state into this thread's buffers, whose pointers are
    bound once per thread (ctypes releases the GIL during the call: threads never share
    them); the other calls go through ``CFunctions``."""

    def __init__(self, functions: Any, layout: Any, p: np.ndarray, nq: int, nv: int):
        self.functions, self.layout, self.p = functions, layout, p
        self.nq, self.nv = nq, nv
        self.pointer = functions.bind_parameters(p)
        self.zeros = np.zeros(nv)
        self.no_inputs = np.zeros(0)
        self.offsets = _offsets(layout)
        self.tril = np.tril_indices(nv)
        self.function = functions.lib.accelerations
        self.function.restype = ctypes.c_int
        self.local = threading.local()

    def _thread_buffers(self):
        """``(state, q, qd, out, args)`` of this thread: ``q`` and ``qd`` are views of one
        ``state`` buffer; ``args`` the bound pointers of the compiled call."""
        state, out = np.empty(self.nq + self.nv), np.empty(self.nv)
        work, u = np.empty(max(self.offsets["dyn_size"], 1)), np.zeros(1)
        q, qd = state[: self.nq], state[self.nq:]
        pointer = ctypes.c_void_p
        args = (pointer(q.ctypes.data), pointer(qd.ctypes.data), self.pointer, pointer(u.ctypes.data), None,
                pointer(out.ctypes.data), pointer(work.ctypes.data))
        buffers = self.local.buffers = (state, q, qd, out, args, work, u)  # the arrays outlive the pointers
        return buffers

    def check(self, q: Any, qd: Any) -> bool:
        return _plain(q, self.nq) and (qd is None or _plain(qd, self.nv))

    def accelerations(self, q: Any, qd: Any) -> np.ndarray | None:
        if type(q) is not np.ndarray or q.dtype != np.float64 or q.shape != (self.nq,):
            return None
        if qd is None:
            qd = self.zeros
        elif type(qd) is not np.ndarray or qd.dtype != np.float64 or qd.shape != (self.nv,):
            return None
        buffers = getattr(self.local, "buffers", None) or self._thread_buffers()
        state, bq, bqd, out, args = buffers[:5]
        bq[:] = q
        bqd[:] = qd
        if not _finite(state) or self.function(*args):
            return None
        qdd = out.copy()
        return qdd if _finite(qdd) else None

    def mass_matrix(self, q: Any) -> np.ndarray | None:
        if not _plain(q, self.nq):
            return None
        tri = self.functions("dynamics", q, self.zeros, self.p, self.no_inputs)[self.offsets["mm_off"]:]
        tri = tri[: self.nv * (self.nv + 1) // 2]
        if not np.all(np.isfinite(tri)):
            return None
        M = np.empty((self.nv, self.nv))
        rows, cols = self.tril
        M[rows, cols] = tri
        M[cols, rows] = tri
        return M

    def body(self, q: Any, qd: Any, index: int, local: np.ndarray):
        o = self.offsets
        if not self.check(q, qd) or not _plain(local, 3) or not 0 <= index < o["n_bodies"]:
            return None
        kin = self.functions("kinematics", q, self.zeros if qd is None else qd, self.p, self.no_inputs)
        row = kin[o["bodies_off"] + index * o["body_row"]:]
        R = row[o["rot_off"]:o["rot_off"] + 9].reshape(3, 3).copy()
        w, v0 = row[o["vel_off"]:o["vel_off"] + 3].copy(), row[o["vel_off"] + 3:o["vel_off"] + 6]
        x = row[o["origin_off"]:o["origin_off"] + 3] + R @ local
        v = v0 + np.array([w[1] * x[2] - w[2] * x[1], w[2] * x[0] - w[0] * x[2], w[0] * x[1] - w[1] * x[0]])
        return x, v, R, w, kin


class Decline:
    """Stands in where no fast path applies: every call declines (the checked path runs)."""

    def check(self, q: Any, qd: Any) -> bool:
        return False

    def accelerations(self, q: Any, qd: Any) -> None:
        return None

    def mass_matrix(self, q: Any) -> None:
        return None

    def body(self, q: Any, qd: Any, index: int, local: Any) -> None:
        return None


DECLINE = Decline()


def calls(functions: Any, layout: Any, p: np.ndarray, nq: int, nv: int, *, use_extension: bool = True):
    """Fast calls of a compiled model (``functions``: the C backend's ``CFunctions``) with the
    parameter vector ``p``: the extension's ``Calls`` when it is available, else ``CtypesCalls``."""
    module = extension() if use_extension else None
    if module is None:
        return CtypesCalls(functions, layout, p, nq, nv)
    o = _offsets(layout)
    lib = functions.lib
    return module.Calls(_address(lib, "accelerations"), _address(lib, "dynamics"), _address(lib, "kinematics"),
                        p, functions, nq, nv, o["dyn_size"], o["mm_off"], o["kin_size"], o["bodies_off"],
                        o["body_row"], o["rot_off"], o["origin_off"], o["vel_off"], o["n_bodies"])
