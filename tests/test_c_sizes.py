"""c_sizes: the model's sizes leave the C templates, whose text then serves every model of a kind."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb

from conftest import bar, fourbar, pendulum_chain, xy_pairs
from mbcomp.build.c_sizes import CSizes
from mbcomp.build.layout import OutputLayout
from mbcomp.core.statemap import StateMap


def _templates(model, **options):
    return _text_and_sizes(model.compile(backend="python", cache=False, **options)._compiled)


def _text_and_sizes(compiled):
    return compiled._c_templates(compiled._c_sizes()), compiled._c_sizes()


def test_trees_of_every_size_share_the_templates_text_and_differ_in_their_unit():
    chain, chain_sizes = _templates(pendulum_chain(4))
    pairs, pair_sizes = _templates(xy_pairs())
    assert chain == pairs  # 4 bodies against 2: other layouts, one state length
    assert chain_sizes.values["KINEMATICS_SIZE"] != pair_sizes.values["KINEMATICS_SIZE"]
    assert chain_sizes.values["NQ"] == pair_sizes.values["NQ"] == 4 and chain_sizes.values["NMECH"] == 8
    assert f"mb_KINEMATICS_SIZE = {chain_sizes.values['KINEMATICS_SIZE']};" in chain_sizes.unit()
    longer, sizes7 = _templates(pendulum_chain(7))  # another state length: read at run time too
    assert longer == chain and sizes7.values["DYNAMICS_FORCES_OFF"] == 7 * 8 // 2 and sizes7.values["NMECH"] == 14
    assert "mb_NMECH = 14;" in sizes7.unit() and "#define NMECH mb_NMECH" in longer


def test_a_loop_and_a_tree_are_different_kinds():
    tree, _ = _templates(pendulum_chain(4), formulation="dae")
    loop, sizes = _templates(fourbar(), formulation="dae")
    rows = len(fourbar().compile(backend="python", cache=False)._compiled.geometric_rows)
    _, tree_sizes = _templates(pendulum_chain(4), formulation="dae")
    assert tree != loop and sizes.values["MB_HAS_NG"] == 1 and sizes.values["NG"] == rows > 0
    assert "mb_MB_HAS_NG = 1;" in sizes.unit() and "mb_MB_HAS_NG = 0;" in tree_sizes.unit()
    assert loop.startswith("#define REDUCED_LOOP 1\n#define DAE_LOOP 1\n") and "#define DAE_LOOP" not in tree


def test_what_a_model_has_is_read_at_run_time_so_the_library_compiles_two_kinds():
    """Drive elements, constraint rows, contacts and quaternions are run-time values: the
    compiles of the library's models (both formulations) with dense dynamics need two
    templates objects, one for trees (quaternions and drive elements among them) and one for
    loops and contacts (the Stewart platform's dae run, recursive dynamics, is a kind of
    its own)."""
    from pathlib import Path
    kinds: dict[str, list] = {}
    for path in sorted((Path(__file__).resolve().parents[1] / "library").glob("*.toml")):
        for formulation in ("lagrange", "dae"):
            # (through the session's cache: the dae compile of a model reads the lagrange compile's code)
            compiled = mb.load(path).compile(backend="python", formulation=formulation)._compiled
            if compiled.dynamics != "dense":
                continue
            text, sizes = _text_and_sizes(compiled)   # (of that compile: one derivation per model)
            kinds.setdefault(text, []).append(sizes.values)
    assert len(kinds) == 2
    has = {name: {tuple(sorted({v[name] for v in members})) for members in kinds.values()}
           for name in ("HAS_DRIVES", "MB_HAS_NG", "MB_HAS_CONTACTS", "MB_HAS_QUAT")}
    assert (0, 1) in has["HAS_DRIVES"] and (0, 1) in has["MB_HAS_QUAT"] and (0, 1) in has["MB_HAS_CONTACTS"]
    for text in kinds:
        assert "HAS_DRIVES 1" not in text and "MB_HAS_QUAT 1" not in text  # no compile-time switch


def test_loops_of_every_size_share_the_templates_text():
    """A four-bar (3 coordinates) and a five-bar (4 coordinates, another output layout)
    compile one templates object."""
    four, four_sizes = _templates(fourbar())
    five_bar = mb.Model("fivebar", gravity=(0, -9.81, 0))
    a, b, c, d = (five_bar.add(bar(n, L)) for n, L in (("a", 0.3), ("b", 0.8), ("c", 0.7), ("d", 0.4)))
    five_bar.add(mb.Revolute("A", five_bar.ground, a, axis="z"))
    five_bar.add(mb.Revolute("B", a, b, axis="z", parent_point=(0.3, 0, 0)))
    five_bar.add(mb.Revolute("E", five_bar.ground, d, axis="z", parent_point=(1.0, 0, 0)))
    five_bar.add(mb.Revolute("D", d, c, axis="z", parent_point=(0.4, 0, 0)))
    five_bar.add(mb.Revolute("C", b, c, axis="z", parent_point=(0.8, 0, 0), child_point=(0.7, 0, 0)))
    five, five_sizes = _templates(five_bar)
    assert four == five
    assert four_sizes.values["NMECH"] != five_sizes.values["NMECH"]


def test_buffers_and_tables_get_their_lengths_in_the_unit():
    layout = OutputLayout.of(nv=4, n_bodies=2, n_constraint_rows=3, n_contacts=2, n_drive_states=1)
    state_map = StateMap(4, 4, np.arange(4), np.arange(4), np.arange(0), np.arange(0))
    sizes = CSizes.of(layout, nq=4, ng=3, state_map=state_map, nz=1, drives=True)
    unit = sizes.unit()
    # DAE_NR = ng + nq + contacts = 9 rows; 5 longs per row of the spec; drives: 4 forces + 1 rate
    assert "dae_rows[9];" in unit and "dae_legacy[45];" in unit and "dae_lam[10];" in unit
    assert "lag_dv[6];" in unit and "lag_kc[13];" in unit  # contacts: 2 gaps, 2 x 4 Jacobian, 2 biases
    assert {name: sizes.values[name] for name in ("HAS_DRIVES", "MB_HAS_NG", "MB_HAS_CONTACTS", "MB_HAS_QUAT")} \
        == {"HAS_DRIVES": 1, "MB_HAS_NG": 1, "MB_HAS_CONTACTS": 1, "MB_HAS_QUAT": 0}
    assert "mb_MB_HAS_CONTACTS = 1;" in unit and "mb_MB_HAS_QUAT = 0;" in unit
    assert sizes.values["NMECH"] == 8 and "mb_NMECH = 8;" in unit  # the state lengths, read at run time
    assert sizes.values["NZ"] == 1 and "mb_NZ = 1;" in unit


def test_a_preprocessor_test_of_a_size_is_refused():
    _, sizes = _templates(pendulum_chain(2))
    with pytest.raises(AssertionError, match="NQ"):
        sizes.check_generic("#if NQ > 2\n#endif\n")
    with pytest.raises(AssertionError, match="DAE_NR"):  # through a macro defined from sizes
        sizes.check_generic("#define DAE_NR (NG + NQ)\n#if DAE_NR > 0\n#endif\n")
    with pytest.raises(AssertionError, match="as a number"):
        sizes.check_generic("#define NV 3\n")
    with pytest.raises(AssertionError, match="MB_HAS_QUAT"):  # what a model has is a run-time value too
        sizes.check_generic("#if MB_HAS_QUAT\n#endif\n")
    assert sizes.check_generic("#ifdef DAE_LOOP\n#endif\n") == "#ifdef DAE_LOOP\n#endif\n"


def test_a_compile_whose_templates_test_a_size_fails_and_keeps_nothing(tmp_path, monkeypatch):
    """The check runs while the templates compile: the build is cancelled, nothing cached."""
    from mbcomp.compiled import compiler
    if compiler.c_compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(tmp_path))
    original = compiler.CompiledModel._c_templates
    monkeypatch.setattr(compiler.CompiledModel, "_c_templates",
                        lambda self, sizes: original(self, sizes) + "#if NQ > 2\n#endif\n")
    with pytest.raises(AssertionError, match="NQ"):
        pendulum_chain(3).compile(backend="c")
    assert not list(tmp_path.glob("*.so")) and not list(tmp_path.glob("*.o"))
