"""Edges where the parts meet the user: what the command line prints, what an error suggests,
and what the docs promise (issue "Seams", item 8: analysis and command-line parts)."""
from __future__ import annotations

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.face.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]


def _equation_lines(out: str, label: str) -> list[str]:
    """The printed lines of one equation (``f[0] = ...`` or ``f[0] =`` then indented lines)."""
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"{label} ="))
    first = lines[start][len(f"{label} ="):].strip()
    body = [first] if first else []
    for line in lines[start + 1:]:
        if not line.startswith("    "):
            break
        body.append(line.strip())
    return body


def test_info_prints_equations_without_wrap_marks_and_they_evaluate_to_the_model(capsys, monkeypatch):
    import sympy as sp
    monkeypatch.setenv("COLUMNS", "72")
    assert main(["info", "double_pendulum"]) == 0
    out = capsys.readouterr().out
    equations = out[out.index("equations of motion"):]
    assert all(len(line) <= 72 for line in equations.splitlines()), equations
    assert not re.search(r"(^|\s)>(\s|$)", equations), equations          # sympy's pretty wrap marks
    system = mb.load(str(ROOT / "library" / "double_pendulum.toml")).compile()
    q, qd = np.array([0.4, -0.9]), np.array([1.3, 0.7])
    _, f = system.tree_dynamics(q, qd)
    names = {"phi1": q[0], "theta2": q[1], "phi1_d": qd[0], "theta2_d": qd[1]}
    for i in range(2):
        text = " ".join(_equation_lines(out, f"f[{i}]")).replace("'", "_d")
        value = float(sp.sympify(text).subs(names))        # our own printout, parsed back
        assert value == pytest.approx(f[i], rel=1e-5, abs=1e-6), (i, text)


def test_a_misspelt_parameter_gets_a_few_close_names_not_all_of_them():
    system = mb.load(str(ROOT / "library" / "servo_arm.toml")).compile()
    assert len(system.parameters) > 20
    with pytest.raises(mb.ModelError) as info:
        system.with_parameters({"shoulder.pid.kpp": 10.0})
    message = str(info.value)
    assert "did you mean 'shoulder.pid.kp'" in message
    quoted = re.findall(r"'([\w.]+)'", message)
    assert 2 <= len(quoted) <= 5, message              # the wrong name, up to three suggestions, the model
    with pytest.raises(mb.ModelError, match="unknown parameter 'zzz' \\(45 parameters"):
        system.with_parameters({"zzz": 1.0})


URDF = """<?xml version="1.0"?>
<robot name="one">
  <link name="base"/>
  <link name="arm">
    <inertial><origin xyz="0 0 -0.25"/><mass value="2.0"/>
      <inertia ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.01"/></inertial>
    <collision><geometry><box size="0.1 0.1 0.5"/></geometry></collision>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="arm"/><axis xyz="1 0 0"/>
    <limit lower="-1.5" upper="1.5" effort="50" velocity="2"/>
  </joint>
</robot>
"""


def test_run_on_a_urdf_prints_its_warning_as_one_clean_line(tmp_path, capsys):
    pytest.importorskip("yourdfpy", exc_type=ImportError)
    path = tmp_path / "one.urdf"
    path.write_text(URDF)
    assert main(["run", str(path), "--t-end", "0.05"]) == 0
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("mbcomp: warning: one.urdf: URDF features not modelled"), err
    assert "UserWarning" not in err and ".py:" not in err


def test_a_library_robot_without_its_package_says_what_to_install(capsys, monkeypatch):
    import mbcomp.files.library
    monkeypatch.setattr(mbcomp.files.library, "robots_dir", lambda: None)
    assert main(["run", "ur5", "--t-end", "0.1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "example-robot-data" in err and "pip install" in err, err
    # the README's install line gives what the example needs
    readme = (ROOT / "README.md").read_text()
    assert 'pip install ".[robots]" && mbcomp run ur5 --html ur5.html' in readme
    import tomllib
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert {"example-robot-data", "yourdfpy"} <= {re.split(r"[<>=\[]", d)[0] for d in extras["robots"]}


def test_docs_cli_counts_and_lists_the_real_commands():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    commands = sorted(sub.choices)
    text = (ROOT / "docs" / "cli.md").read_text()
    words = {3: "three", 4: "four", 5: "five", 6: "six"}
    assert f"It has {words[len(commands)]} commands:" in text, commands
    block = text[text.index("commands:"):]
    block = block[:block.index("```", block.index("```") + 3)]
    assert sorted(re.findall(r"^mbcomp (\w+)", block, re.M)) == commands


def test_reference_table_names_every_public_name():
    text = (ROOT / "docs" / "reference.md").read_text()
    table = text[text.index("| name | kind | section |"):]
    table = table[:table.index("\n\n")]
    listed = set()
    for row in table.splitlines()[2:]:
        listed.update(re.findall(r"`(\w+)`", row.split("|")[1]))
    assert listed == set(mb.__all__), (sorted(set(mb.__all__) - listed), sorted(listed - set(mb.__all__)))
    anchors = set(re.findall(r"\]\(#([\w-]+)\)", table))
    headings = {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
                for h in re.findall(r"^#+ (.+)$", text, re.M)}
    assert anchors <= headings, sorted(anchors - headings)


def test_drive_callables_take_t_q_qd_as_docs_drives_says():
    text = (ROOT / "docs" / "drives.md").read_text()
    assert "any callable\n  of `t`" not in text and "must take `(t, q, qd)`" in text

    def pendulum(voltage):
        m = mb.Model("callable_voltage", gravity=(0, 0, -9.81))
        bob = m.add(mb.Body("bob", mass=1.0, com=(0, 0, -0.5)))
        joint = m.add(mb.Revolute("pivot", m.ground, bob, axis="x"))
        m.add(mb.DCMotor("motor", joint, ratio=10.0, resistance=2.0, inductance=0.01, k=0.05, voltage=voltage))
        return m.compile()

    res = pendulum(lambda t, q, qd: 6.0 * np.sin(2 * np.pi * t)).simulate(0.05, [0.0])
    assert np.all(np.isfinite(res.q)) and abs(res.q[-1, 0]) > 0      # the motor turned the joint
    with pytest.raises(mb.SimulationError, match="positional argument"):
        pendulum(lambda t: 6.0).simulate(0.05, [0.0])                  # a callable of t alone fails


def test_tests_pass_importorskip_its_exception_type():
    """pytest will stop skipping on a module that fails with ImportError by default: every
    importorskip says which exception it skips on."""
    offenders = []
    for path in sorted((ROOT / "tests").rglob("*.py")):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if "importorskip(" in line and "exc_type=" not in line:
                offenders.append(f"{path.name}:{number}")
    assert not offenders, offenders


def test_analyse_shape_column_is_bounded_for_a_long_chain(tmp_path, capsys):
    """Eight links: the shape column keeps to the largest three components."""
    links = "\n".join(textwrap.dedent(f"""
        [bodies.b{i}]
        mass = 1.0
        com = [0.0, 0.0, -0.2]
        inertia = [0.01, 0.01, 0.001]

        [joints.j{i}]
        type = "revolute"
        parent = "{'ground' if i == 0 else f'b{i - 1}'}"
        child = "b{i}"
        axis = "x"
        {'' if i == 0 else 'parent_point = [0.0, 0.0, -0.4]'}
        """) for i in range(8))
    path = tmp_path / "chain.toml"
    path.write_text('name = "chain"\ngravity = [0.0, 0.0, -9.81]\n' + links)
    assert main(["analyse", str(path)]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if re.match(r"\s+\d+\s+\d", line)]
    assert len(rows) == 8 and max(len(line) for line in out.splitlines()) < 140, out
    assert all("smaller)" in row for row in rows)
