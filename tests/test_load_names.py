"""``mb.load`` accepts library model names as the command line does."""
from pathlib import Path

import pytest

import mbcomp as mb
from mbcomp.files.toml_model import dumps, library_models
from mbcomp.files.library import resolve_model_path


def test_load_by_name_reads_the_library_file():
    path = library_models()["double_pendulum"]
    by_name = mb.load("double_pendulum")
    assert Path(by_name.path).resolve() == path.resolve()
    assert dumps(by_name) == dumps(mb.load(path))
    assert dumps(mb.load("double_pendulum.toml")) == dumps(by_name)
    assert dumps(mb.load("library:double_pendulum")) == dumps(by_name)


def test_existing_file_wins_over_library_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "double_pendulum").write_text('name = "mine"\n[bodies.b]\nmass = 2.5\n')
    model = mb.load("double_pendulum")
    assert model.name == "mine"
    assert resolve_model_path("double_pendulum") == Path("double_pendulum")


def test_unknown_name_lists_the_library():
    with pytest.raises(mb.ModelError) as err:
        mb.load("no_such_model")
    message = str(err.value)
    assert "no_such_model" in message and "no library model" in message and "four_bar" in message


def test_extra_library_folder_from_environment(tmp_path, monkeypatch):
    (tmp_path / "my_part.toml").write_text('name = "my_part"\ndescription = "one body"\n'
                                           '[bodies.b]\nmass = 3.0\n')
    monkeypatch.setenv("MBCOMP_LIBRARY", str(tmp_path))
    model = mb.load("my_part")
    assert model.description == "one body"
    assert "mass = 3.0" in dumps(model)


def test_library_lists_models_parts_and_robots(capsys):
    from mbcomp.face.cli import main
    from mbcomp.files.library import library_parts, library_robots, read_description
    assert main(["library"]) == 0
    out = capsys.readouterr().out
    parts = library_parts()
    assert parts, "the library ships parts"
    models_part, parts_part = out.split("\nparts")
    for text, entries in ((models_part, library_models()), (parts_part, parts)):
        for name, path in entries.items():
            line = next(line for line in text.splitlines() if line.split() and line.split()[0] == name)
            assert read_description(path) in line
    for name in library_robots():
        assert any(line.startswith(name) and "URDF" in line for line in out.splitlines())
