"""OutputLayout: one description of the packed outputs, shared by the C code and Python."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import fourbar, pendulum_chain
from mbcomp.build.layout import BODY_ROW, Block, OutputLayout, body_fields


def test_blocks_follow_each_other():
    layout = OutputLayout.of(nv=3, n_bodies=2, n_constraint_rows=4, n_contacts=1)
    M, f = layout.functions["dynamics"]
    assert (M.offset, M.size, M.packing) == (0, 6, "tril") and (f.offset, f.size) == (6, 3)
    assert layout.size("dynamics") == 9 and layout.size("energy") == 2
    assert layout.size("kinematics") == 2 * BODY_ROW + 3 * 6
    assert layout.block("constraints", "jacobian") == Block("jacobian", 4, (4, 3))
    assert layout.size("constraints") == 4 * (3 + 2) and layout.size("contacts") == 1 * (3 + 2)
    defines = layout.c_defines()
    assert "#define DYNAMICS_FORCES_OFF 6\n" in defines and "#define CONSTRAINTS_BIAS_OFF 16\n" in defines
    assert "#define KINEMATICS_SIZE 66\n" in defines


def test_unpack_restores_the_symmetric_matrix_and_shapes():
    layout = OutputLayout.of(nv=3, n_bodies=1, n_constraint_rows=0, n_contacts=0)
    M = np.array([[4.0, 1.0, 2.0], [1.0, 5.0, 3.0], [2.0, 3.0, 6.0]])
    flat = np.concatenate((M[np.tril_indices(3)], [7.0, 8.0, 9.0]))
    out = layout.unpack("dynamics", flat)
    np.testing.assert_array_equal(out["mass_matrix"], M)
    np.testing.assert_array_equal(out["forces"], [7.0, 8.0, 9.0])
    rows = np.arange(2 * BODY_ROW, dtype=float).reshape(2, BODY_ROW)
    fields = body_fields(rows)
    assert fields["rotation"].shape == (2, 3, 3) and fields["rotation"][1, 2, 2] == BODY_ROW + 8
    np.testing.assert_array_equal(fields["origin"][0], [9, 10, 11])
    np.testing.assert_array_equal(fields["bias"][1], rows[1, 18:24])


@pytest.mark.parametrize("model", [pendulum_chain(3), fourbar()], ids=["chain", "fourbar"])
def test_generated_outputs_fill_the_layout(model):
    system = model.compile("dae")
    compiled = system.kernel.compiled
    layout = compiled.output_layout
    q = np.linspace(0.1, 0.3, system.nq)
    qd = np.linspace(-0.2, 0.4, system.nv)
    for function in layout.functions:
        assert system.kernel.call(function, q, qd).shape == (layout.size(function),)
    # The layout decodes the same mass matrix as the generated Python functions' own packing
    M = system.mass_matrix(q)
    flat = system.kernel.call("dynamics", q, np.zeros(system.nv))
    np.testing.assert_array_equal(flat[: layout.block("dynamics", "mass_matrix").size], M[np.tril_indices(system.nv)])


def test_the_layout_is_part_of_the_cache_key():
    compiled = pendulum_chain(2).compile(backend="python").kernel.compiled
    assert "layout|" + compiled.output_layout.description() in compiled.description
