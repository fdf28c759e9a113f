"""The examples and the documentation stay true: every ``examples/*.py`` runs, and every
```python block of every ``docs/*.md`` executes.

- Examples run as scripts (``__main__``, each in a process of its own, forked from one
  that has imported numpy, scipy, sympy and matplotlib once: ``script_server.py``) in a
  temporary working directory, with ``MBCOMP_CACHE_DIR`` in a temporary directory and
  ``MPLBACKEND=Agg``; each asserts its own physics, so a zero exit status is the check.
- The blocks of one docs page run in order in one fresh namespace (a page reads like a
  session), in a temporary working directory that holds a link to ``library/`` (the pages
  are written as if run from the repository root).  The blocks of a ``STANDALONE`` page
  each run in a fresh namespace of their own: each is a complete example.  A block whose first line is
  ``# not run`` (optionally followed by the reason) is skipped: it needs something the test machine may lack (ffmpeg, a
  cluster).
"""
from __future__ import annotations

import os
import re
import sys
import textwrap
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from mbcomp.spec.components.base import KINDS

try:                                    # tests/ on sys.path (pytest's default rootdir-less import)
    from script_server import ScriptServer
except ImportError:                     # tests imported as a package
    from tests.script_server import ScriptServer

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
DOCS = sorted((ROOT / "docs").glob("*.md"))
SKIP_MARK = "# not run"
#: Pages whose every block is a complete example (runs in a namespace of its own).
STANDALONE = ("contacts.md",)
FENCE = re.compile(r"^(\s*)```python\s*$")


def python_blocks(text: str) -> list[tuple[int, str]]:
    """``(first line number, source)`` of every ```python block, dedented (fences may be
    indented, e.g. inside a list)."""
    lines = text.splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if FENCE.match(lines[i]):
            j = i + 1
            while j < len(lines) and lines[j].strip() != "```":
                j += 1
            if j == len(lines):
                raise AssertionError(f"unclosed ```python block at line {i + 1}")
            blocks.append((i + 2, textwrap.dedent("\n".join(lines[i + 1:j]))))
            i = j + 1
        else:
            i += 1
    return blocks


def is_skipped(source: str) -> bool:
    first = next((line.strip() for line in source.splitlines() if line.strip()), "")
    return first.startswith(SKIP_MARK)


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory) -> Path:
    """Generated code goes to a temporary cache (the session's private one when set)."""
    env = os.environ.get("MBCOMP_CACHE_DIR")
    return Path(env) if env else tmp_path_factory.mktemp("mbcomp-cache")


@pytest.fixture(scope="module")
def scripts(cache_dir):
    """The process the example scripts are forked from (its environment is theirs)."""
    env = dict(os.environ, MBCOMP_CACHE_DIR=str(cache_dir), MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    server = ScriptServer(env)
    yield server
    server.close()


def run_example(script: Path, cwd: Path, scripts: ScriptServer):
    return scripts.run(script, cwd, timeout=300)


@pytest.fixture(scope="module")
def example_runs(tmp_path_factory, request):
    """The example scripts, run one after another on a background thread while the docs
    blocks execute in this process: ``{script: (future, working directory)}``.  Empty under
    pytest-xdist, whose parallel workers share the tests out (the example tests, kept on one
    worker with its one script server, each run their own script; a background thread per
    worker would run every script twice, and a docs page would start a server of its own)."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        yield {}
        return
    scripts = request.getfixturevalue("scripts")
    pool = ThreadPoolExecutor(max_workers=1)
    runs = {}
    for script in EXAMPLES:
        cwd = tmp_path_factory.mktemp(f"example-{script.stem}")
        runs[script] = (pool.submit(run_example, script, cwd, scripts), cwd)
    yield runs
    pool.shutdown(wait=True, cancel_futures=True)


def test_the_parser_finds_blocks_and_skip_marks():
    text = "x\n```python\na = 1\n```\n- item\n\n  ```python\n  # not run: needs ffmpeg\n  b = 2\n  ```\n```text\nc\n```\n"
    blocks = python_blocks(text)
    assert blocks == [(3, "a = 1"), (8, "# not run: needs ffmpeg\nb = 2")]
    assert [is_skipped(src) for _, src in blocks] == [False, True]


def test_there_are_examples_and_docs():
    assert len(EXAMPLES) >= 4, "examples/ should hold at least four scripts"
    assert (ROOT / "docs" / "index.md").exists()


@pytest.mark.parametrize("page", DOCS, ids=[p.name for p in DOCS])
def test_docs_code_blocks_run(page, tmp_path, monkeypatch, cache_dir, example_runs):
    blocks = python_blocks(page.read_text())
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(cache_dir))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    (tmp_path / "library").symlink_to(ROOT / "library", target_is_directory=True)
    namespace: dict = {"__name__": f"docs_{page.stem}"}
    kinds = dict(KINDS)  # a page may define a component kind (docs/architecture.md): not for later tests
    try:
        for line, source in blocks:
            if is_skipped(source):
                continue
            if page.name in STANDALONE:
                namespace = {"__name__": f"docs_{page.stem}"}
            code = compile(source, f"{page.relative_to(ROOT)}:{line}", "exec")
            try:
                exec(code, namespace)  # noqa: S102 - our own documentation
            except Exception as exc:
                raise AssertionError(f"{page.name}, block at line {line} failed: {type(exc).__name__}: {exc}\n"
                                     f"{source}") from exc
    finally:
        KINDS.clear()
        KINDS.update(kinds)
        if "matplotlib.pyplot" in sys.modules:
            sys.modules["matplotlib.pyplot"].close("all")


@pytest.mark.xdist_group("example-scripts")  # one worker, one preloaded script server
@pytest.mark.parametrize("script", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs(script, example_runs, tmp_path_factory, scripts):
    if script in example_runs:
        future, cwd = example_runs[script]
        proc = future.result()
    else:
        cwd = tmp_path_factory.mktemp(f"example-{script.stem}")
        proc = run_example(script, cwd, scripts)
    assert proc.returncode == 0, (f"{script.name} failed (exit {proc.returncode})\n"
                                  f"--- stdout ---\n{proc.stdout}\n--- stderr ---\n{proc.stderr}")
    assert proc.stdout.strip(), f"{script.name} printed nothing"
    assert not any(cwd.iterdir()), f"{script.name} wrote files without being given a path"


def test_every_example_has_a_docstring_saying_how_to_run_it():
    for script in EXAMPLES:
        text = script.read_text()
        assert text.lstrip().startswith('"""'), f"{script.name}: no module docstring"
        assert "Run:" in text, f"{script.name}: the docstring should say how to run it"


def test_index_links_every_page():
    index = (ROOT / "docs" / "index.md").read_text()
    linked = set(re.findall(r"\]\(([\w.-]+\.md)(?:#[\w-]*)?\)", index))
    missing = sorted(p.name for p in DOCS if p.name != "index.md" and p.name not in linked)
    assert not missing, f"docs/index.md does not link {missing}"


@pytest.mark.xdist_group("example-scripts")
def test_scripts_run_like_python_script(tmp_path, scripts):
    """The example runner gives what ``python script.py`` gives: ``__main__``, argv, the
    script's directory on sys.path, its working directory, exit status, both streams."""
    where = tmp_path / "scripts"
    where.mkdir()
    (where / "sibling.py").write_text("VALUE = 42\n")
    script = where / "exits.py"
    script.write_text("import os, sys\nimport sibling\n"
                      "print(__name__, sys.argv == [__file__], os.getcwd(), sibling.VALUE)\n"
                      "print('to stderr', file=sys.stderr)\nsys.exit(3)\n")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    proc = scripts.run(script, cwd)
    assert proc.returncode == 3
    assert proc.stdout.split() == ["__main__", "True", str(cwd), "42"]
    assert proc.stderr == "to stderr\n"
    script.write_text("import sys\nsys.modules['numpy'].left_behind = 1\nraise ValueError('boom')\n")
    proc = scripts.run(script, cwd)
    assert proc.returncode == 1 and "ValueError: boom" in proc.stderr and proc.stdout == ""
    script.write_text("import numpy\nprint(hasattr(numpy, 'left_behind'))\n")
    assert scripts.run(script, cwd).stdout == "False\n"  # nothing one script does reaches the next
