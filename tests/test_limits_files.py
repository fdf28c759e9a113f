"""Limits on files and sub-models (issue "Limits"): hostile inputs end in an mbcomp error that
names what is wrong, within seconds and in bounded memory, and no message shows a secret.

Sub-model instances and nesting are counted before anything is built; only regular files
within the size limit are read; ``library:`` never leaves the library; URDF links must form a
tree; a long bounded run says its step budget ran out; a symlinked cache directory works.
"""
from __future__ import annotations

import importlib.util
import os
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen import cache
from mbcomp.face.cli import main

from conftest import time_limit

SECRET = "sk_live_51HxQ2eKz8vYpL3mN4oP5qR6sT7uV8wX9yZ"
LEAF = ('[ports]\nbase = "external"\n[parameters]\nmass = 1.0\n[bodies.b]\nmass = "mass"\n'
        '[joints.j]\ntype = "revolute"\nparent = "base"\nchild = "b"\naxis = "z"\n')


def part_using(target: str, times: int) -> str:
    """A part file with ``times`` instances of ``target``, each hanging from its own port."""
    return '[ports]\nbase = "external"\n' + "".join(
        f'[submodels.s{k}]\nuse = "{target}"\nbase = "base"\n' for k in range(times))


def doubling_files(folder: Path, levels: int) -> Path:
    """``levels`` part files, each using the next one twice; returns the model using the first."""
    for i in range(levels):
        text = LEAF if i == levels - 1 else part_using(f"p{i + 1}.toml", 2)
        (folder / f"p{i}.toml").write_text(text)
    top = folder / "top.toml"
    top.write_text('[submodels.top]\nuse = "p0.toml"\nbase = "ground"\n')
    return top


def chain_files(folder: Path, length: int) -> Path:
    for i in range(length):
        text = LEAF if i == length - 1 else part_using(f"c{i + 1}.toml", 1)
        (folder / f"c{i}.toml").write_text(text)
    top = folder / "chain.toml"
    top.write_text('[submodels.top]\nuse = "c0.toml"\nbase = "ground"\n')
    return top


def instances(model) -> int:
    return model.registry.instances if model.registry is not None else 0


def load_error(spec) -> str:
    with pytest.raises(mb.ModelError) as info:
        mb.load(spec)
    return str(info.value)


# -- sub-model instances and nesting ---------------------------------------------------------------
def test_thirty_doubling_files_are_refused_before_building(tmp_path):
    """2**30 - 1 instances (1 + 2 + 4 + ... + 2**29): counted, not built."""
    top = doubling_files(tmp_path, 30)
    assert sum(p.stat().st_size for p in tmp_path.glob("*.toml")) < 5000
    tracemalloc.start()
    try:
        message = load_error(top)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert f"would build {2 ** 30 - 1} sub-model instances" in message
    assert "limit of 5000" in message and "MBCOMP_MAX_INSTANCES" in message and str(top) in message
    assert peak < 20e6, peak


def test_the_instance_limit_is_exact_and_can_be_raised(tmp_path, monkeypatch):
    top = doubling_files(tmp_path, 7)           # 1 + 2 + ... + 64 = 127 instances, 64 bodies
    monkeypatch.setenv("MBCOMP_MAX_INSTANCES", "126")
    assert "would build 127 sub-model instances, more than the limit of 126" in load_error(top)
    monkeypatch.setenv("MBCOMP_MAX_INSTANCES", "127")
    model = mb.load(top)
    assert instances(model) == 127 and len(model.bodies) == 64
    monkeypatch.setenv("MBCOMP_MAX_INSTANCES", "many")
    assert "MBCOMP_MAX_INSTANCES: must be a positive whole number, got 'many'" in load_error(top)


def test_a_chain_of_250_files_names_the_nesting_limit(tmp_path):
    top = chain_files(tmp_path, 250)
    message = load_error(top)
    assert "sub-models nest more than 50 deep" in message and "MBCOMP_MAX_NESTING" in message
    assert "chain.toml -> c0.toml -> c1.toml" in message and "nested too deeply to read" not in message


def test_a_chain_at_the_nesting_limit_loads_and_runs(tmp_path, monkeypatch):
    top = chain_files(tmp_path, 50)              # 50 nested instances: the limit
    model = mb.load(top)
    assert instances(model) == 50
    assert [b.name for b in model.bodies] == ["top" + ".s0" * 49 + ".b"]
    monkeypatch.setenv("MBCOMP_MAX_NESTING", "49")
    assert "nest more than 49 deep" in load_error(top)


def test_inline_sub_models_count_too(tmp_path, monkeypatch):
    head = "[submodels." + ".submodels.".join(f"n{k}" for k in range(60)) + ".bodies.b]\nmass = 1.0\n"
    path = tmp_path / "inline.toml"
    path.write_text(head)
    assert "nest more than 50 deep" in load_error(path)
    monkeypatch.setenv("MBCOMP_MAX_NESTING", "60")
    assert instances(mb.load(path)) == 60


class Recursive(mb.Submodel):
    def build(self, parent):
        self.add(Recursive("next", parent=parent))


class Wide(mb.Submodel):
    def build(self, parent):
        for k in range(10):
            self.add(Leaf(f"leaf{k}", parent=parent))


class Leaf(mb.Submodel):
    def build(self, parent):
        self.add(mb.Body("b", mass=1.0))


def test_python_submodels_have_the_same_limits(monkeypatch):
    model = mb.Model("r")
    with pytest.raises(mb.ModelError, match="nest more than 50 deep.*MBCOMP_MAX_NESTING"):
        model.add(Recursive("first", parent=model.ground.frame()))
    monkeypatch.setenv("MBCOMP_MAX_INSTANCES", "21")
    model = mb.Model("w")
    model.add(Wide("a", parent=model.ground.frame()))          # 11 instances
    with pytest.raises(mb.ModelError, match=r"Leaf 'b.leaf9': the model would hold more than 21 sub-model "
                                            r"instances \(set MBCOMP_MAX_INSTANCES"):
        model.add(Wide("b", parent=model.ground.frame()))      # the 22nd is refused


# -- special and large files ------------------------------------------------------------------
@pytest.mark.parametrize("spec, says", [("/dev/zero", "is a character device, not a file"),
                                        ("/dev/null", "is a character device, not a file"),
                                        (".", "is a directory, not a file")])
def test_special_files_are_refused_by_the_python_api(spec, says, capsys):
    assert says in load_error(spec)
    assert main(["info", spec]) == 2 and says in capsys.readouterr().err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_is_refused_without_blocking(tmp_path, monkeypatch):
    """Under a time limit (a reader that blocked would never return: SIGALRM ends the wait)."""
    (tmp_path / "pipe.toml").unlink(missing_ok=True)
    os.mkfifo(tmp_path / "pipe.toml")
    (tmp_path / "uses.toml").write_text('[submodels.p]\nuse = "pipe.toml"\n')
    (tmp_path / "robot.urdf").unlink(missing_ok=True)
    os.mkfifo(tmp_path / "robot.urdf")
    monkeypatch.chdir(tmp_path)
    messages = []
    with time_limit(60.0):
        for spec in ("pipe.toml", "uses.toml", "robot.urdf"):
            with pytest.raises(mb.ModelError) as info:
                mb.load(spec)
            messages.append(str(info.value))
    assert all("is a FIFO (named pipe), not a file" in message for message in messages), messages


def test_a_file_over_the_size_limit_is_not_read(tmp_path, monkeypatch):
    path = tmp_path / "big.toml"
    path.write_text("# " + "x" * 300 + "\n[bodies.b]\nmass = 1.0\n")
    size = path.stat().st_size
    monkeypatch.setenv("MBCOMP_MAX_FILE_BYTES", str(size - 1))
    message = load_error(path)
    assert f"the file holds {size} bytes, more than the limit of {size - 1} bytes" in message
    assert "MBCOMP_MAX_FILE_BYTES" in message
    monkeypatch.setenv("MBCOMP_MAX_FILE_BYTES", str(size))
    assert [b.name for b in mb.load(path).bodies] == ["b"]


# -- library: stays inside the library, no secret in any message -----------------------------------
@pytest.fixture
def secret_file(tmp_path):
    outside = tmp_path / "private" / "credentials.toml"
    outside.parent.mkdir()
    outside.write_text(f'api_key = "{SECRET}"\n[parameters]\napi_key = "{SECRET}"\n[bodies.b]\nmass = "{SECRET}"\n')
    return outside


def test_library_names_cannot_leave_the_library(tmp_path, secret_file, capsys):
    stem = str(secret_file.with_suffix(""))
    ups = "../" * (len(Path(mb.library.library_dirs()[0]).resolve().parts) + 2)
    model_dir = tmp_path / "model"
    model_dir.mkdir()
    for k, use in enumerate([f"library:{stem}", f"library:{ups}{stem.lstrip('/')}", f"library:parts/../../{stem}",
                             "library:..", "library:", "../private/credentials.toml"]):
        path = model_dir / f"m{k}.toml"
        path.write_text(f'[submodels.s]\nuse = "{use}"\n')
        message = load_error(path)
        assert "[submodels.s] use:" in message and SECRET[:20] not in message, message
        assert any(why in message for why in ("absolute path", "'..'", "is empty", "leaves the directory")), message
    for spec in (f"library:{stem}", f"library:{ups}{stem.lstrip('/')}"):
        message = load_error(spec)
        assert SECRET[:20] not in message and ("absolute path" in message or "'..'" in message), message
        assert main(["run", spec]) == 2
        assert SECRET[:20] not in capsys.readouterr().err


def test_a_symlink_out_of_the_library_is_not_a_library_file(tmp_path, secret_file, monkeypatch):
    library = tmp_path / "lib"
    (library / "parts").mkdir(parents=True)
    (library / "parts" / "evil.toml").symlink_to(secret_file)
    (library / "evil2.toml").symlink_to(secret_file)
    (library / "parts" / "fine.toml").write_text(LEAF)
    monkeypatch.setenv("MBCOMP_LIBRARY", str(library))
    model = tmp_path / "m.toml"
    for name in ("evil", "evil2", "parts/evil"):
        model.write_text(f'[submodels.s]\nuse = "library:{name}"\nbase = "ground"\n')
        message = load_error(model)
        assert f"no library part or model '{name}'" in message and SECRET[:20] not in message
    assert "evil2" not in mb.library.library_models()
    for name in ("fine", "parts/fine"):   # a name, or a path inside the library
        model.write_text(f'[submodels.s]\nuse = "library:{name}"\nbase = "ground"\n')
        assert [b.name for b in mb.load(model).bodies] == ["s.b"]


def test_messages_cut_values_read_from_a_file(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(f'[parameters]\nk = "{SECRET}"\n[bodies.b]\nmass = "{SECRET} + 1"\n'
                    f'[joints.j]\ntype = "revolute"\nparent = "{SECRET}"\nchild = "b"\naxis = "{SECRET}"\n')
    message = load_error(path)
    for where in ("[parameters] k: ", "[bodies.b] mass: ", "[joints.j] parent: unknown body", "[joints.j] axis: "):
        assert where in message
    assert SECRET[:24] not in message and SECRET[:12] in message   # enough to find it, never all of it


# -- URDF trees ------------------------------------------------------------------------------------
INERTIAL = '<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>'


def urdf(tmp_path, links, joints, name="r.urdf") -> Path:
    text = ['<?xml version="1.0"?>\n<robot name="r">']
    text += [f'<link name="{link}">{INERTIAL}</link>' for link in links]
    for joint, parent, child, kind, *extra in joints:
        origin = f'<origin xyz="{extra[0]}"/>' if extra else ""
        text.append(f'<joint name="{joint}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                    f'{origin}<axis xyz="{extra[1] if len(extra) > 1 else "0 0 1"}"/></joint>')
    path = tmp_path / name
    path.write_text("".join(text) + "</robot>")
    return path


needs_urdf = pytest.mark.skipif(importlib.util.find_spec("yourdfpy") is None, reason="yourdfpy reads URDF")


@needs_urdf
@pytest.mark.parametrize("links, joints, says", [
    (["base", "a"], [("j0", "base", "a", "continuous"), ("loop", "a", "a", "continuous")],
     ["URDF joint 'loop': connects link 'a' to itself"]),
    (["base", "a", "b", "c"], [("j0", "base", "a", "continuous"), ("j1", "b", "c", "continuous"),
                               ("j2", "c", "b", "continuous")],
     ["URDF joints 'j1', 'j2': form a cycle (b -> c -> b)"]),
    (["a", "b"], [("j1", "a", "b", "fixed"), ("j2", "b", "a", "fixed")], ["'j1', 'j2': form a cycle"]),
    (["base", "a", "b"], [("j1", "base", "b", "continuous"), ("j2", "a", "b", "continuous"),
                          ("j0", "base", "a", "continuous")],
     ["URDF link 'b': has 2 parent joints ('j1', 'j2')"]),
    (["base", "a"], [("j0", "base", "a", "continuous", "0 0 0", "nan 0 0")],
     ["URDF joint 'j0': axis nan 0 0 is not three finite numbers"]),
], ids=["self-joint", "cycle", "fixed-cycle", "two-parents", "nan-axis"])
def test_urdf_links_must_form_a_tree(tmp_path, links, joints, says):
    path = urdf(tmp_path, links, joints)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        message = load_error(path)
    assert all(text in message for text in says), message
    assert "b_2" not in message and "has no joint" not in message


@needs_urdf
def test_a_long_urdf_chain_loads_without_recursion(tmp_path):
    """1100 welded links then a hinge: the hinge sits at the sum of the weld offsets."""
    n = 1100
    links = [f"l{k}" for k in range(n)] + ["tip"]
    joints = [(f"w{k}", f"l{k - 1}", f"l{k}", "fixed", "0 0 0.001") for k in range(1, n)]
    joints.append(("hinge", f"l{n - 1}", "tip", "continuous", "0 0 0", "1 0 0"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = mb.load(urdf(tmp_path, links, joints))
    (tip,) = model.bodies
    hinge = model["hinge"]
    assert tip.name == "tip" and hinge.coords == ("hinge",)
    np.testing.assert_allclose(hinge.parent_point, [0.0, 0.0, (n - 1) * 0.001], atol=1e-12)


# -- the step budget ----------------------------------------------------------------------------------
def test_a_long_bounded_run_says_the_step_budget_ran_out(capsys):
    assert main(["run", "double_pendulum", "--t-end", "1e9", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "step budget ran out" in err and "MBCOMP_MAX_STEPS" in err and "growing without bound" not in err


@pytest.mark.parametrize("integrator, t_end", [("compiled", 800.0), ("scipy", 100.0)])
def test_the_step_budget_estimate_and_its_variable(monkeypatch, integrator, t_end):
    """The budget checks the pace every 4096 (compiled) or 1000 steps: a run of several times
    that many, given a quarter of the steps it takes, stops early and estimates its length."""
    system = mb.load("double_pendulum").compile()
    steps = system.simulate(t_end, [1.0, 0.5], integrator=integrator).stats["steps"]
    assert steps > 6000 if integrator == "compiled" else steps > 1500
    share = 100 if integrator == "scipy" else 1     # Python-stepped loops get a hundredth
    monkeypatch.setenv("MBCOMP_MAX_STEPS", str(int(steps * share / 4)))
    with pytest.raises(mb.SimulationError, match="step budget ran out") as info:
        system.simulate(t_end, [1.0, 0.5], integrator=integrator)
    estimate = float(str(info.value).split("would take about ")[1].split(" steps")[0])
    assert steps / 1.5 < estimate < steps * 1.5, (estimate, steps)


# -- the cache directory -------------------------------------------------------------------------------
def test_a_symlink_to_a_private_cache_directory_is_used(tmp_path, monkeypatch):
    target = tmp_path / "real"
    target.mkdir(mode=0o700)
    link = tmp_path / "link"
    link.symlink_to(target)
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(link))
    with warnings.catch_warnings():
        warnings.simplefilter("error", cache.CacheWarning)
        assert cache.cache_dir() == link
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    assert cache.directory_problem(tmp_path / "dangling").endswith("which does not exist")
    (tmp_path / "file").write_text("x")
    (tmp_path / "to_file").symlink_to(tmp_path / "file")
    assert cache.directory_problem(tmp_path / "to_file").endswith("which is not a directory")
    assert cache.directory_problem(tmp_path / "file") == "is not a directory (it is a regular file)"


def test_one_compile_warns_once(tmp_path, monkeypatch):
    import tempfile
    from conftest import arm_model
    unsafe = tmp_path / "shared"
    unsafe.mkdir(mode=0o700)
    os.chmod(unsafe, 0o770)
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(unsafe))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        arm_model().compile(backend="python")
        arm_model().compile(backend="python")
    messages = [str(w.message) for w in caught if issubclass(w.category, cache.CacheWarning)]
    assert len(messages) == 1 and "writable by group or others" in messages[0]
