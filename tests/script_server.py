"""Run Python scripts as ``__main__`` in fresh processes without paying the imports each time.

A script started with ``python script.py`` spends about a second of CPU importing numpy,
scipy, sympy and matplotlib before its first line of work; the examples' tests run a dozen
of them.  ``ScriptServer`` starts one process that imports those libraries (and the bare
``mbcomp`` package) once, then forks a child per script: each child is a separate process
with its own working directory, argv, exit status, stdout and stderr, exactly as
``python script.py`` would give them, and nothing one script does reaches the next (the
server itself never runs a script).  Where ``os.fork`` is missing, ``ScriptServer.run``
falls back to ``subprocess``.

Protocol (this file run as a program): one JSON request per line on stdin
``{"script", "cwd", "timeout"}``, one JSON reply per line on stdout
``{"returncode", "stdout", "stderr"}``.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading

PRELOAD = ("numpy", "scipy.integrate", "scipy.optimize", "scipy.linalg", "sympy", "matplotlib", "mbcomp")


class Completed:
    """A finished script, shaped like ``subprocess.CompletedProcess``."""

    def __init__(self, returncode: int, stdout: str, stderr: str):
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


class ScriptServer:
    """One preloaded server process per test worker; ``run`` may be called from any thread
    (requests are answered one at a time)."""

    def __init__(self, env: dict):
        self.env = dict(env)
        self.lock = threading.Lock()
        self.process = None
        if hasattr(os, "fork"):
            self.process = subprocess.Popen([sys.executable, __file__], stdin=subprocess.PIPE,
                                            stdout=subprocess.PIPE, env=self.env, text=True, bufsize=1)

    def run(self, script, cwd, timeout: float = 300) -> Completed:
        """Run ``script`` as ``__main__`` in ``cwd``, like ``python script`` would."""
        if self.process is None:
            proc = subprocess.run([sys.executable, str(script)], cwd=cwd, env=self.env, capture_output=True,
                                  text=True, timeout=timeout)
            return Completed(proc.returncode, proc.stdout, proc.stderr)
        with self.lock:
            self.process.stdin.write(json.dumps({"script": str(script), "cwd": str(cwd), "timeout": timeout}) + "\n")
            self.process.stdin.flush()
            line = self.process.stdout.readline()
        if not line:
            raise RuntimeError(f"the script server stopped (exit {self.process.poll()}) while running {script}")
        reply = json.loads(line)
        return Completed(reply["returncode"], reply["stdout"], reply["stderr"])

    def close(self) -> None:
        if self.process is not None:
            self.process.stdin.close()
            self.process.wait(timeout=60)
            self.process.stdout.close()
            self.process = None


def _child(script: str, cwd: str, timeout: float, out_path: str, err_path: str) -> None:
    """In the forked child: become ``python script`` (never returns)."""
    import atexit
    import io
    import runpy
    import signal
    import traceback
    code = 1
    try:
        signal.alarm(max(1, int(timeout)))               # killed by SIGALRM like a timed-out run
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        for fd, path in ((1, out_path), (2, err_path)):
            handle = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            os.dup2(handle, fd)
            os.close(handle)
        sys.stdin = io.TextIOWrapper(io.FileIO(0, "r", closefd=False))
        sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), line_buffering=True)
        sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), line_buffering=True)
        os.chdir(cwd)
        sys.argv = [script]
        sys.path[0] = os.path.dirname(os.path.abspath(script))   # as for `python script`
        try:
            runpy.run_path(script, run_name="__main__")
            code = 0
        except SystemExit as exc:
            if exc.code is None or isinstance(exc.code, int):
                code = exc.code or 0
            else:
                print(exc.code, file=sys.stderr)
        except BaseException:  # noqa: BLE001 - reported like the interpreter would
            traceback.print_exc()
        atexit._run_exitfuncs()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001
                pass
        os._exit(code)


def serve() -> None:
    """The server loop: preload, then fork one child per request."""
    import importlib
    for name in PRELOAD:
        try:
            importlib.import_module(name)
        except ImportError:
            pass
    protocol = sys.stdout
    sys.stdout = sys.stderr  # nothing but replies on the protocol stream
    # mkdtemp, not TemporaryDirectory: a child runs the exit handlers it inherits (as a
    # fresh interpreter runs those of its imports), and a finalizer would delete this.
    tmp = tempfile.mkdtemp(prefix="script-server-")
    out_path, err_path = os.path.join(tmp, "stdout"), os.path.join(tmp, "stderr")
    try:
        for line in sys.stdin:
            request = json.loads(line)
            for path in (out_path, err_path):
                if os.path.exists(path):
                    os.unlink(path)
            protocol.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:
                _child(request["script"], request["cwd"], request["timeout"], out_path, err_path)
            _, status = os.waitpid(pid, 0)
            returncode = os.waitstatus_to_exitcode(status)
            texts = []
            for path in (out_path, err_path):
                try:
                    with open(path, encoding="utf-8", errors="replace") as handle:
                        texts.append(handle.read())
                except FileNotFoundError:
                    texts.append("")
            protocol.write(json.dumps({"returncode": returncode, "stdout": texts[0], "stderr": texts[1]}) + "\n")
            protocol.flush()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

if __name__ == "__main__":
    serve()
