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
from mbcomp.io import load  # noqa: E402

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
    from mbcomp.cli import main
    path = tmp_path / "bad.toml"
    path.write_text('[joints.j]\ntype = ["revolute"]\nparent = "ground"\nchild = "ground"\n', encoding="utf-8")
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "[joints.j] type: must be a string" in err
