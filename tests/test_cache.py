"""The code cache runs only what this user's mbcomp wrote: ownership, permissions, signed
manifests, artefact hashes, and a key that covers templates, compiler and flags."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen import cache, printer as codegen
from mbcomp.codegen.backend import c_compiler, compile_c
from conftest import arm_model, assert_close, primed_cache

needs_cc = pytest.mark.skipif(c_compiler() is None, reason="no C compiler")
#: One worker: the module fixtures (the arm compiled in another process, its reference
#: accelerations) are built once per run.
pytestmark = pytest.mark.xdist_group("cache-entries")

# The arm at a fixed state, with accelerations computed without any cache.
Q, QD = [0.3, -0.2, 0.9], [0.1, 0.4, -0.3]


@pytest.fixture(scope="module")
def expected_accelerations():
    return arm_model().compile(backend="python", cache=False).accelerations(Q, QD)


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    path = tmp_path / "cache"
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(path))
    return path


def _fill_in_subprocess(directory: Path, backend: str) -> str:
    """Compile the arm in another process (so this one never maps the files we then damage);
    returns the entry key."""
    code = ("import sys; sys.path.insert(0, 'tests'); from conftest import arm_model; "
            f"s = arm_model().compile(backend={backend!r}); print(s._compiled.key)")
    env = {**os.environ, "MBCOMP_CACHE_DIR": str(directory)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300,
                          cwd=Path(__file__).resolve().parent.parent, check=True)
    return done.stdout.split()[-1]


@pytest.fixture(scope="module")
def filled_c(tmp_path_factory, tree_templates):
    """A cache directory holding the arm's compiled library, and its key (the templates
    object linked from ``conftest.tree_templates``: the damage tests rebuild the model, not
    the templates)."""
    if c_compiler() is None:
        pytest.skip("no C compiler")
    directory = primed_cache(tree_templates, tmp_path_factory.mktemp("filled") / "cache")
    return directory, _fill_in_subprocess(directory, "c")


@pytest.fixture
def filled(filled_c, cache_dir):
    """A private copy of the filled cache as this test's cache directory."""
    source, key = filled_c
    shutil.copytree(source, cache_dir)
    return cache_dir, key


def _compile_arm(backend="c"):
    with warnings.catch_warnings():
        warnings.simplefilter("error", cache.CacheWarning)
        return arm_model().compile(backend=backend)


class TestEntries:
    def test_an_entry_has_a_signed_manifest_with_the_artefact_hash(self, filled):
        directory, key = filled
        library = directory / f"{key}.so"
        manifest = json.loads((directory / f"{key}.so.json").read_text())
        assert manifest["sha256"] == hashlib.sha256(library.read_bytes()).hexdigest()
        assert manifest["key"] == key and manifest["size"] == library.stat().st_size
        inputs = manifest["inputs"]
        assert inputs["compiler"] == c_compiler() and inputs["compiler_version"]
        assert "-fPIC" in inputs["flags"] and len(inputs["source_sha256"]) == 64
        assert len(manifest["hmac"]) == 64
        secret = directory / "secret"
        assert secret.stat().st_mode & 0o777 == 0o600 and secret.stat().st_size == 32
        assert (directory.stat().st_mode & 0o777) == 0o700

    @needs_cc
    def test_an_intact_entry_is_a_cache_hit(self, filled, expected_accelerations):
        sys_ = _compile_arm()
        assert sys_._compiled.cache_hit and sys_._compiled.key == filled[1]
        assert_close(sys_.accelerations(Q, QD), expected_accelerations, rtol=1e-12, name="qdd")

    @needs_cc
    @pytest.mark.parametrize("damage", ["flip-a-byte", "truncate", "empty", "replace"])
    def test_a_damaged_library_is_rebuilt_not_loaded(self, filled, damage, expected_accelerations):
        directory, key = filled
        library = directory / f"{key}.so"
        data = bytearray(library.read_bytes())
        if damage == "flip-a-byte":
            data[len(data) // 2] ^= 0xFF
            library.write_bytes(bytes(data))
        elif damage == "truncate":
            with open(library, "r+b") as fh:
                fh.truncate(len(data) // 2)
        elif damage == "empty":
            library.write_bytes(b"")
        else:  # another valid library under this name: an attacker's code
            other = compile_c("int accelerations(void) { return 0; }\n", c_compiler())
            library.write_bytes(other)
        sys_ = _compile_arm()
        assert not sys_._compiled.cache_hit
        assert_close(sys_.accelerations(Q, QD), expected_accelerations, rtol=1e-12, name="qdd after rebuild")
        assert hashlib.sha256(library.read_bytes()).hexdigest() == json.loads(
            (directory / f"{key}.so.json").read_text())["sha256"]            # rebuilt and signed again
        assert _compile_arm()._compiled.cache_hit

    @needs_cc
    @pytest.mark.parametrize("forgery", ["no-manifest", "wrong-secret", "edited-manifest", "not-json"])
    def test_a_manifest_that_does_not_verify_means_rebuild(self, filled, forgery, expected_accelerations):
        directory, key = filled
        manifest_path = directory / f"{key}.so.json"
        manifest = json.loads(manifest_path.read_text())
        if forgery == "no-manifest":
            manifest_path.unlink()
        elif forgery == "wrong-secret":
            manifest["hmac"] = cache._sign(b"x" * 32, manifest)
            manifest_path.write_text(json.dumps(manifest))
        elif forgery == "edited-manifest":
            manifest["inputs"]["flags"] = ["-O3"]
            manifest_path.write_text(json.dumps(manifest))
        else:
            manifest_path.write_text("{not json")
        sys_ = _compile_arm()
        assert not sys_._compiled.cache_hit
        assert_close(sys_.accelerations(Q, QD), expected_accelerations, rtol=1e-12, name="qdd")

    @needs_cc
    def test_a_replaced_secret_invalidates_every_entry(self, filled):
        directory, _ = filled
        (directory / "secret").write_bytes(os.urandom(32))
        assert not _compile_arm()._compiled.cache_hit

    @needs_cc
    def test_a_group_writable_library_is_not_loaded(self, filled):
        directory, key = filled
        os.chmod(directory / f"{key}.so", 0o664)
        assert not _compile_arm()._compiled.cache_hit

    def test_a_planted_python_file_is_never_executed(self, cache_dir, tmp_path, expected_accelerations):
        key = arm_model().compile(backend="python")._compiled.key
        marker = tmp_path / "planted-code-ran"
        planted = f"open({str(marker)!r}, 'w').write('x')\n" + (cache_dir / f"{key}.py").read_text()
        (cache_dir / f"{key}.py").write_text(planted)
        manifest = json.loads((cache_dir / f"{key}.py.json").read_text())
        manifest["sha256"], manifest["size"] = hashlib.sha256(planted.encode()).hexdigest(), len(planted.encode())
        (cache_dir / f"{key}.py.json").write_text(json.dumps(manifest))     # hash fixed, signature not
        sys_ = _compile_arm("python")
        assert not marker.exists() and not sys_._compiled.cache_hit
        assert_close(sys_.accelerations(Q, QD), expected_accelerations, rtol=1e-12, name="qdd")

    def test_a_python_file_without_manifest_is_never_executed(self, cache_dir, tmp_path):
        key = arm_model().compile(backend="python", cache=False)._compiled.key
        marker = tmp_path / "planted-code-ran"
        cache_dir.mkdir(exist_ok=True)
        (cache_dir / f"{key}.py").write_text(f"open({str(marker)!r}, 'w').write('x')\n")
        assert not _compile_arm("python")._compiled.cache_hit
        assert not marker.exists()


class TestDirectory:
    def test_a_new_directory_is_private(self, cache_dir):
        assert cache.cache_dir() == cache_dir
        assert cache_dir.stat().st_mode & 0o777 == 0o700

    @pytest.mark.parametrize("problem", ["group-writable", "world-writable", "other-owner", "a-file", "symlink"])
    def test_an_unsafe_directory_falls_back_with_a_warning(self, cache_dir, tmp_path, monkeypatch, problem):
        cache_dir.mkdir(mode=0o700)
        if problem == "group-writable":
            os.chmod(cache_dir, 0o770)
        elif problem == "world-writable":
            os.chmod(cache_dir, 0o777)
        elif problem == "other-owner":
            uid = os.getuid()
            monkeypatch.setattr(cache, "_uid", lambda: uid + 1)
        elif problem == "a-file":
            cache_dir.rmdir()
            cache_dir.write_text("not a directory")
        else:  # a symlink to a directory that is not private (one to a private directory is used)
            target = tmp_path / "elsewhere"
            target.mkdir(mode=0o700)
            os.chmod(target, 0o770)
            cache_dir.rmdir()
            cache_dir.symlink_to(target)
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        with pytest.warns(cache.CacheWarning, match="cache directory"):
            used = cache.cache_dir()
        assert used != cache_dir and used.parent == tmp_path
        if problem != "other-owner":  # (the pretended uid owns nothing)
            assert cache.directory_problem(used) is None

    def test_compiling_with_an_unsafe_directory_warns_and_works(self, cache_dir, tmp_path, monkeypatch,
                                                                expected_accelerations):
        cache_dir.mkdir(mode=0o700)
        arm_model().compile(backend="python")
        os.chmod(cache_dir, 0o775)                   # now anyone in the group could plant files
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        with pytest.warns(cache.CacheWarning):
            sys_ = arm_model().compile(backend="python")
        assert not sys_._compiled.cache_hit          # nothing was loaded from the unsafe directory
        assert_close(sys_.accelerations(Q, QD), expected_accelerations, rtol=1e-12, name="qdd")

    def test_another_users_directory_gives_a_warning_not_permission_error(self, cache_dir, tmp_path, monkeypatch):
        cache_dir.mkdir(mode=0o700)
        (cache_dir / "secret").write_bytes(b"s" * 32)
        uid = os.getuid()
        monkeypatch.setattr(cache, "_uid", lambda: uid + 1)
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        with pytest.warns(cache.CacheWarning, match="owned by another user"):
            sys_ = arm_model().compile(backend="python")
        assert sys_.accelerations(Q, QD).shape == (3,)

    def test_an_unwritable_location_is_not_an_error(self, tmp_path, monkeypatch):
        blocker = tmp_path / "file"
        blocker.write_text("not a directory")
        monkeypatch.setenv("MBCOMP_CACHE_DIR", str(blocker / "cache"))
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        with pytest.warns(cache.CacheWarning, match="cannot be created"):
            sys_ = arm_model().compile(backend="python")
        assert not sys_._compiled.cache_hit and sys_.accelerations(Q, QD).shape == (3,)

    def test_the_directory_follows_the_environment(self, tmp_path, monkeypatch):
        monkeypatch.setenv("MBCOMP_CACHE_DIR", str(tmp_path / "mine"))
        assert cache.configured_dir() == tmp_path / "mine"
        monkeypatch.delenv("MBCOMP_CACHE_DIR")
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
        if sys.platform.startswith("linux"):
            assert cache.configured_dir() == tmp_path / "xdg" / "mbcomp"


class TestKey:
    TOOLS = {"compiler": "/usr/bin/cc", "compiler_version": "cc 1.0", "flags": ["-O1"], "python": "cpython-311",
             "platform": "linux|x86_64"}

    def test_the_key_is_stable_and_covers_structure_templates_and_toolchain(self):
        a = cache.entry_key("Revolute|elbow|x", "template", self.TOOLS)
        assert a == cache.entry_key("Revolute|elbow|x", "template", dict(self.TOOLS))
        assert len(a) == 32 and all(ch in "0123456789abcdef" for ch in a)
        assert a != cache.entry_key("Revolute|elbow|y", "template", self.TOOLS)
        assert a != cache.entry_key("Revolute|elbow|x", "template ", self.TOOLS)
        for name, value in [("compiler", "/usr/bin/clang"), ("compiler_version", "cc 1.1"),
                            ("flags", ["-O2"]), ("python", "cpython-312"), ("platform", "darwin|arm64")]:
            assert a != cache.entry_key("Revolute|elbow|x", "template", {**self.TOOLS, name: value}), name

    def test_the_toolchain_names_the_compiler_and_its_version(self):
        cc = c_compiler()
        tools = cache.toolchain(cc, ("-O1",))
        assert tools["flags"] == ["-O1"] and tools["python"].startswith(sys.implementation.cache_tag)
        if cc:
            assert tools["compiler"] == cc and tools["compiler_version"]

    @needs_cc
    def test_a_changed_template_gives_a_new_entry(self, cache_dir, monkeypatch):
        first = _compile_arm()
        original = codegen.c_accelerations
        monkeypatch.setattr(codegen, "c_accelerations", lambda *nq: original(*nq) + "\n/* changed */\n")
        second = _compile_arm()
        assert not second._compiled.cache_hit and second._compiled.key != first._compiled.key

    @needs_cc
    def test_changed_flags_give_a_new_entry(self, cache_dir, monkeypatch):
        from mbcomp.codegen import backend
        from mbcomp.compiled import compiler
        first = _compile_arm()
        flags = backend.C_FLAGS + ("-DMBCOMP_TEST_FLAG",)
        monkeypatch.setattr(backend, "C_FLAGS", flags)
        monkeypatch.setattr(compiler, "C_FLAGS", flags)
        second = _compile_arm()
        assert not second._compiled.cache_hit and second._compiled.key != first._compiled.key
        assert json.loads((cache_dir / f"{second._compiled.key}.so.json").read_text())["inputs"]["flags"][-1] \
            == "-DMBCOMP_TEST_FLAG"

    def test_the_python_entry_key_covers_the_code_generator(self, cache_dir, monkeypatch):
        first = arm_model().compile(backend="python")._compiled.key
        codegen.generator_text.cache_clear()
        monkeypatch.setattr(codegen, "CODEGEN_VERSION", "test-version")
        try:
            second = arm_model().compile(backend="python")
            assert second._compiled.key != first and not second._compiled.cache_hit
        finally:
            monkeypatch.undo()
            codegen.generator_text.cache_clear()


class TestBuild:
    @needs_cc
    def test_a_failed_build_leaves_no_temporary_directory(self, tmp_path, monkeypatch):
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        with pytest.warns(RuntimeWarning, match="compiler failed"):
            assert compile_c("this is not C", c_compiler()) is None
        assert list(tmp_path.iterdir()) == []

    @needs_cc
    def test_an_uncached_build_leaves_no_files(self, cache_dir, tmp_path, monkeypatch, expected_accelerations):
        scratch = tmp_path / "scratch"
        scratch.mkdir()
        monkeypatch.setattr(tempfile, "tempdir", str(scratch))
        sys_ = arm_model().compile(backend="c", cache=False)
        sys_._compiled.wait_for_background()    # (the output functions' library)
        assert list(scratch.iterdir()) == [] and not cache_dir.exists()
        assert_close(sys_.accelerations(Q, QD), expected_accelerations, rtol=1e-12, name="qdd")

    def test_write_atomic_writes_private_files_and_leaves_no_temporary_files(self, tmp_path):
        target = tmp_path / "deep" / "er" / "file.so"
        cache.write_atomic(target, b"first")
        cache.write_atomic(target, b"second version")
        assert target.read_bytes() == b"second version"
        assert [p.name for p in target.parent.iterdir()] == ["file.so"]
        assert target.stat().st_mode & 0o777 == 0o600

    def test_a_failed_write_keeps_the_old_file_and_cleans_up(self, tmp_path):
        target = tmp_path / "file.py"
        cache.write_atomic(target, b"good")
        with pytest.raises(TypeError):
            cache.write_atomic(target, "not bytes")
        assert target.read_bytes() == b"good"
        assert [p.name for p in tmp_path.iterdir()] == ["file.py"]

    def test_store_and_read_round_trip(self, cache_dir):
        tools = cache.toolchain()
        assert cache.read_text("abc", ".py", tools) is None
        assert cache.store("abc", ".py", b"x = 1\n", tools) == cache_dir / "abc.py"
        assert cache.read_text("abc", ".py", tools) == "x = 1\n"
        assert cache.read_text("abc", ".py", {**tools, "python": "other"}) is None   # other toolchain
        assert sorted(p.name for p in cache_dir.iterdir()) == ["secret"]              # and discarded
