"""Compiling works on a frozen copy: it never changes or keeps the user's components."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.build.flatten import flatten


def pendulum_with_torque():
    m = mb.Model("p")
    bob = m.add(mb.Body("bob", mass=2.0, com=(0, 0, -1.0), inertia=(0.1, 0.1, 0.01)))
    hinge = m.add(mb.Revolute("hinge", m.ground, bob, axis="x"))
    m.add(mb.JointTorque("drive", hinge, value=lambda t, q, qd: [0.5]))
    m.add(mb.TorsionSpring("spring", hinge, stiffness=3.0))
    return m


def snapshot(model):
    return {name: copy.copy(vars(comp)) for name, comp in model.components.items()}


class TestCompileLeavesComponentsAlone:
    def test_vars_unchanged_by_compile(self):
        m = pendulum_with_torque()
        before = snapshot(m)
        sys = m.compile(backend="python")
        assert snapshot(m) == before  # nothing written into the user's objects (no JointTorque._size)
        assert all(sys.topology.components[n] is not c for n, c in m.components.items())

    def test_editing_after_compile_does_not_change_the_system(self):
        m = pendulum_with_torque()
        sys = m.compile(backend="python")
        q, qd = [0.3], [0.2]
        M0, a0 = sys.mass_matrix(q), sys.accelerations(q, qd)
        m["bob"].mass = 20.0
        m["bob"].com = (0, 0, -3.0)
        m["hinge"].axis = "y"
        m["spring"].stiffness = 100.0
        assert np.array_equal(sys.mass_matrix(q), M0) and np.array_equal(sys.accelerations(q, qd), a0)
        # The independent number: I = m l^2 + Ixx = 2 * 1 + 0.1.
        assert M0[0, 0] == pytest.approx(2.1, rel=1e-14)
        # A new compile sees the edits: 20 * 9 + Iyy.
        assert m.compile(backend="python").mass_matrix(q)[0, 0] == pytest.approx(180.1, rel=1e-14)

    def test_compiled_copies_are_frozen(self):
        sys = pendulum_with_torque().compile(backend="python")
        bob = sys.topology.components["bob"]
        with pytest.raises(AttributeError, match="compiled copy"):
            bob.mass = 5.0
        with pytest.raises(mb.ModelError, match="compiled copy"):
            bob.anything = 1
        assert bob.mass == 2.0

    def test_input_sizes_live_on_the_topology(self):
        sys = pendulum_with_torque().compile(backend="python")
        assert sys.topology.input_sizes == {"drive": 1}
        # With the spring off: I qdd = 0.5 - m g l sin(q), I = m l^2 + Ixx = 2.1.
        free = sys.with_parameters({"spring.stiffness": 0.0})
        q = 0.3
        expected = (0.5 - 2.0 * 9.81 * 1.0 * np.sin(q)) / 2.1
        assert free.accelerations([q], [0.0])[0] == pytest.approx(expected, rel=1e-12)


class TestFlatModel:
    def test_flat_model_is_a_consistent_frozen_copy(self):
        m = pendulum_with_torque()
        flat = flatten(m)
        assert list(flat.components) == list(m.components)
        assert flat["hinge"].child is flat["bob"] and flat["hinge"].parent is flat.ground
        with pytest.raises(TypeError):
            flat.components["x"] = 1  # read-only mapping
        assert flat["drive"].value is m["drive"].value  # callables are shared, not copied

    def test_torque_size_checked_without_mutation(self):
        m = mb.Model("p")
        bob = m.add(mb.Body("bob", mass=1.0, com=(0, 0, -1)))
        hinge = m.add(mb.Revolute("hinge", m.ground, bob, axis="x"))
        torque = m.add(mb.JointTorque("tq", hinge, value=[1.0, 2.0]))
        before = dict(vars(torque))
        with pytest.raises(mb.ModelError, match="JointTorque 'tq': value has 2 entries, joint 'hinge' has 1"):
            m.compile(backend="python")
        assert vars(torque) == before
