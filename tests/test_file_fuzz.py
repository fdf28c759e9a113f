"""Model files are data from anywhere: random mutations of the library's files end in a
``ModelError`` (with the file named) or a model, never in another exception.

The mutations replace, delete or add values anywhere in a file's tables (numbers of any
size, NaN and infinities, strings, expressions, arrays, nested arrays and tables, the
wrong types) and damage the text itself.
"""
from __future__ import annotations

import json
import math
import os
import random
import tempfile
from pathlib import Path

import pytest

hypothesis = pytest.importorskip("hypothesis", exc_type=ImportError)
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

import mbcomp as mb  # noqa: E402
from mbcomp.files.toml_model import load  # noqa: E402

LIBRARY = Path(__file__).resolve().parent.parent / "library"
FILES = sorted(LIBRARY.glob("*.toml"))
TEXTS = {path.name: path.read_text(encoding="utf-8") for path in FILES}
DATA = {name: tomllib.loads(text) for name, text in TEXTS.items()}
WORK = Path(tempfile.mkdtemp(prefix="mbcomp-fuzz-"))


def toml_key(key: str) -> str:
    return key if key and all(ch.isalnum() or ch in "_-" for ch in key) else json.dumps(key)


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return "{ " + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + " }"


def dump(data: dict) -> str:
    return "".join(f"{toml_key(k)} = {toml_value(v)}\n" for k, v in data.items())


WORDS = ["revolute", "prismatic", "spherical", "fixed", "spring", "damper", "force", "joint_torque", "motor", "slider",
         "ground", "x", "-z", "xyz", "t", "sin(t)", "1/0", "10**10**10", "m*L", "(" * 60 + "1" + ")" * 60,
         "library:link", "library:nothing", "../outside.toml", "a" * 300, "", " ", "\u00e9", "\x00"]
NUMBERS = [0, 1, -1, 2, 3, 2 ** 63, -(10 ** 30), 10 ** 400, 10 ** 4000, 0.5, -2.5, 1e308, -1e308, 1e-320, 1e11, 0.0, -0.0,
           float("nan"), float("inf"), float("-inf")]
KEYS = ["type", "body", "point", "use", "value", "mass", "axis", "joint", "parent", "child", "x", "q", ""]


def random_value(rng, depth: int = 0):
    """A TOML value of any type: numbers of any size, special floats, words and expressions,
    booleans, arrays and tables (nested a few levels)."""
    kind = rng.random()
    if kind < 0.35 or depth > 2:
        return rng.choice(NUMBERS) if rng.random() < 0.6 else rng.choice(WORDS + [True, False])
    if kind < 0.55:
        return [random_value(rng, depth + 1) for _ in range(rng.choice([0, 1, 2, 3, 3, 4]))]
    if kind < 0.65:
        return {rng.choice(KEYS): random_value(rng, depth + 1) for _ in range(rng.randint(0, 3))}
    if kind < 0.8:  # a vector or a matrix of numbers
        return [[rng.choice(NUMBERS) for _ in range(3)] for _ in range(3)] if rng.random() < 0.3 else \
            [rng.choice(NUMBERS) for _ in range(3)]
    return "".join(rng.choice("abcxyz0123456789+-*/(). _[]{}=\"'") for _ in range(rng.randint(0, 12)))


def paths(data: dict, prefix: tuple = ()):
    for key, value in data.items():
        yield prefix + (key,)
        if isinstance(value, dict):
            yield from paths(value, prefix + (key,))


def mutated_file(seed: int) -> tuple[str, str]:
    """A library file with 1 to 3 values replaced, deleted or added (reproducible from ``seed``)."""
    rng = random.Random(seed)
    name = rng.choice(sorted(DATA))
    data = json.loads(json.dumps(DATA[name], allow_nan=True))  # a deep copy of plain TOML data
    for _ in range(rng.randint(1, 3)):
        where = rng.choice(list(paths(data)) or [("name",)])
        parent = data
        for key in where[:-1]:
            parent = parent[key]
        action = rng.random()
        if action < 0.15:
            parent.pop(where[-1], None)
        elif action < 0.3:
            parent[rng.choice(KEYS[:-1])] = random_value(rng)
        else:
            parent[where[-1]] = random_value(rng)
    return name, dump(data)


def damaged_text(seed: int) -> tuple[str, str]:
    """A library file's text with 1 to 3 pieces cut out or put in."""
    rng = random.Random(seed)
    name = rng.choice(sorted(TEXTS))
    text = TEXTS[name]
    for _ in range(rng.randint(1, 3)):
        at = rng.randint(0, len(text))
        text = text[:at] + rng.choice(["", "[", "]", "=", '"', "\n", "[[x]]", "{", "9" * 5000, "[" * 2000, "a.b"]) \
            + text[at + rng.randint(0, 20):]
    return name, text


def check(name: str, text: str) -> None:
    path = WORK / name
    path.write_text(text, encoding="utf-8")
    try:
        load(path)
    except mb.ModelError as exc:
        assert str(path) in str(exc), f"the error does not name the file: {exc}"


#: Mutated files per run: 400 by default (about 6 s); MBCOMP_FUZZ_EXAMPLES=1500 (or more)
#: for a thorough run.  The damaged-text test runs a third as many.
EXAMPLES = int(os.environ.get("MBCOMP_FUZZ_EXAMPLES", "400"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                suppress_health_check=list(HealthCheck))
SEEDS = st.integers(min_value=0, max_value=2 ** 32 - 1)


@FUZZ
@given(SEEDS)
def test_mutated_library_files_end_in_model_errors(seed):
    check(*mutated_file(seed))


@settings(FUZZ, max_examples=max(1, EXAMPLES // 3))
@given(SEEDS)
def test_damaged_library_files_end_in_model_errors(seed):
    check(*damaged_text(seed))


@pytest.mark.parametrize("text, expected", [
    ('[joints.j]\ntype = ["revolute"]\nparent = "ground"\nchild = "b"\n', "[joints.j] type: must be a string"),
    ("x = " + "[" * 3000 + "]" * 3000 + "\n", "nested too deeply"),
    ("gravity = [" + "9" * 4400 + ", 0, 0]\n", ":1 gravity: an integer of 4400 digits is too long"),
    ("[bodies.b]\nmass = 1.0\ninertia = [[1e308, 1e308, 1e308], [1e308, 1e308, 1e308], [1e308, 1e308, 1e308]]\n",
     "[bodies.b] inertia: is too large to handle"),
    ("[simulation]\nn_samples = 1e11\n", "[simulation] n_samples: must be an integer from 2 to 1e+07"),
    ("[simulation]\nn_samples = 100000000000\n", "[simulation] n_samples: must be an integer from 2 to 1e+07"),
    ("[submodels.s]\nuse = \"" + "a" * 5000 + "\"\n", "[submodels.s] use:"),
], ids=["unhashable-type", "deep-nesting", "huge-integer", "overflowing-inertia", "float-samples", "too-many-samples",
        "long-file-name"])
def test_known_malformed_files(tmp_path, text, expected):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(mb.ModelError) as info:
        load(path)
    assert expected in str(info.value) and str(path) in str(info.value)


def test_cli_prints_one_line_and_exits_2(tmp_path, capsys):
    from mbcomp.face.cli import main
    path = tmp_path / "bad.toml"
    path.write_text('[joints.j]\ntype = ["revolute"]\nparent = "ground"\nchild = "ground"\n', encoding="utf-8")
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "[joints.j] type: must be a string" in err


# -- limits: random `use` graphs, escapes and special files (issue "Limits") ----------------------------
from unittest import mock  # noqa: E402

PART = '[ports]\nbase = "external"\n[bodies.b]\nmass = 1.0\n[joints.j]\ntype = "revolute"\nparent = "base"\n' \
       'child = "b"\naxis = "z"\n'
GRAPHS = st.lists(st.lists(st.tuples(st.integers(0, 5), st.integers(1, 3)), max_size=3), min_size=1, max_size=6)
SECRET = "sk_live_9fKq2LmNp4RsTuVwXyZa0b1C"


def expected_use(graph: list, top: list, deepest: int) -> tuple[str, int]:
    """("cycle" | "deep" | "ok", instances) of a use graph, counted independently by expanding it."""
    def expand(i: int, chain: tuple) -> tuple[int, int]:
        if i in chain:
            raise LookupError("cycle")
        count, depth = 0, 0
        for j, times in graph[i]:
            below, d = expand(j, chain + (i,))
            count += times * (1 + below)
            depth = max(depth, 1 + d)
        return count, depth
    try:
        parts = [expand(j, ()) for j, _ in top]
    except LookupError:
        return "cycle", 0
    total = sum(times * (1 + count) for (count, _), (_, times) in zip(parts, top))
    depth = max((1 + d for _, d in parts), default=0)
    return ("deep" if depth > deepest else "ok"), total


@settings(FUZZ, max_examples=max(1, EXAMPLES // 4))
@given(graph=GRAPHS, top=st.lists(st.tuples(st.integers(0, 5), st.integers(1, 3)), min_size=1, max_size=3),
       loop=st.integers(0, 4))
def test_random_use_graphs_load_or_name_the_limit(graph, top, loop):
    """Files using each other with multiplicities: a model with exactly the instances an
    independent expansion counts, or the limit (instances, nesting) or the cycle named.
    File i uses files after it (``loop == 0``: the last also uses the first, a cycle)."""
    n = len(graph)
    graph = [[(i + 1 + j, times) for j, times in entries if i + 1 + j < n] for i, entries in enumerate(graph)]
    if loop == 0:
        graph[-1].append((0, 1))
    top = [(j % n, times) for j, times in top]
    folder = Path(tempfile.mkdtemp(dir=WORK))
    for i, entries in enumerate(graph):
        uses = "".join(f'[submodels.u{k}_{m}]\nuse = "f{j}.toml"\nbase = "base"\n'
                       for k, (j, times) in enumerate(entries) for m in range(times))
        (folder / f"f{i}.toml").write_text(PART + uses)
    path = folder / "top.toml"
    path.write_text("".join(f'[submodels.t{k}_{m}]\nuse = "f{j}.toml"\nbase = "ground"\n'
                            for k, (j, times) in enumerate(top) for m in range(times)))
    verdict, total = expected_use(graph, top, 3)
    with mock.patch.dict(os.environ, {"MBCOMP_MAX_INSTANCES": "40", "MBCOMP_MAX_NESTING": "3"}):
        try:
            model = load(path)
        except mb.ModelError as exc:
            message = str(exc)
            if verdict == "deep":
                assert "nest more than 3 deep" in message, message
            elif verdict == "ok":
                assert total > 40 and f"would build {total} sub-model instances" in message, message
            else:
                assert "cycle" in message or "nest more than 3 deep" in message or "would build" in message
            return
    assert verdict == "ok" and total <= 40 and model.registry.instances == total
    assert len(model.bodies) == total


ESCAPES = st.sampled_from(["library:{abs}", "library:{up}{rel}", "library:parts/../../{up}{rel}", "{abs}.toml",
                           "../{name}.toml", "library:./{name}", "library:\\\\x", "library:c:{abs}", "{up}{rel}.toml",
                           "library:{name}/../../{name}", "sub/../../{name}.toml", "library:~/{name}"])


@settings(FUZZ, max_examples=max(1, EXAMPLES // 8))
@given(ESCAPES, st.sampled_from(["submodels", "top"]))
def test_use_never_reads_outside_and_never_tells(escape, where):
    """A file of secrets beside the model's folder (not below it): every way of naming it is
    refused before it is read, and no message shows its values."""
    folder = Path(tempfile.mkdtemp(dir=WORK))
    (folder / "model").mkdir()
    secret = folder / "credentials.toml"
    secret.write_text(f'api_key = "{SECRET}"\n[parameters]\ntoken = "{SECRET}"\n[bodies.b]\nmass = "{SECRET}"\n')
    stem = str(secret.with_suffix(""))
    up = "../" * (len(secret.parts) + 3)
    use = escape.format(abs=stem, up=up, rel=stem.lstrip("/"), name="credentials")
    if where == "top" and not use.startswith("library:"):
        return   # a path given to mb.load itself is the caller's choice
    path = folder / "model" / "m.toml"
    path.write_text(f'[submodels.s]\nuse = {json.dumps(use)}\n')
    spec = path if where == "submodels" else use
    try:
        load(spec) if where == "submodels" else mb.load(spec)
    except mb.ModelError as exc:
        assert SECRET[:16] not in str(exc), str(exc)
        return
    raise AssertionError(f"{use!r} was read")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_special_files_in_use_are_refused(tmp_path):
    os.mkfifo(tmp_path / "pipe.toml")
    (tmp_path / "dir.toml").mkdir()
    (tmp_path / "zero.toml").symlink_to("/dev/zero")
    for name, says in (("pipe", "pipe.toml: is a FIFO"), ("dir", "dir.toml: is a directory"),
                       ("zero", "'zero.toml' leaves the directory")):   # (a symlink is followed first)
        path = tmp_path / f"use_{name}.toml"
        path.write_text(f'[submodels.s]\nuse = "{name}.toml"\n')
        with pytest.raises(mb.ModelError, match=says):
            load(path)
