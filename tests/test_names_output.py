"""Names and outputs: one naming rule for coordinates, speed columns, states and parameters
(clashes refused naming both sides, so no two columns or symbols mix); every writer reports a
failed write; CSV cells a spreadsheet would execute are escaped; the viewer's scene data is
safe inside its page for any name."""
from __future__ import annotations

import csv
import errno
import json
import re
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.core.result import spreadsheet_safe
from mbcomp.face.viewer.page import render_page, scene_json

FULL = Path("/dev/full")


def two_links(c1: str = "a", c2: str = "b", body2: str = "b2") -> mb.Model:
    """Two 1 kg point masses on rods of 1 m, hinged about x, coordinates ``c1`` and ``c2``."""
    m = mb.Model("two", gravity=(0, 0, -9.81))
    b1 = m.add(mb.Body("b1", mass=1.0, com=(0, 0, -1)))
    b2 = m.add(mb.Body(body2, mass=1.0, com=(0, 0, -1)))
    m.add(mb.Revolute("j1", m.ground, b1, axis="x", coords=c1))
    m.add(mb.Revolute("j2", b1, b2, axis="x", coords=c2, parent_point=(0, 0, -1)))
    return m


# -- the naming rule ------------------------------------------------------------------------------
class TestNamingRule:
    @pytest.mark.parametrize("c1, c2, says", [
        ("a", "a_d", r"name 'a_d' is both the speed column of coordinate 'a' \(Revolute 'j1'\) and a coordinate "
                     r"of Revolute 'j2'"),
        ("a_d", "a", r"name 'a_d' is both a coordinate of Revolute 'j1' and the speed column of coordinate 'a' "
                     r"\(Revolute 'j2'\)"),
        ("a", "b2.mass", r"name 'b2\.mass' is both a coordinate of Revolute 'j2' and the parameter 'b2\.mass'"),
        ("a", "gravity[2]", r"name 'gravity\[2\]' is both a coordinate of Revolute 'j2' and the parameter 'gravity\[2\]'"),
        ("a", r"\dot{a}", r"the speed symbol of coordinate 'a'"),
    ])
    def test_a_clash_is_a_compile_error_naming_both_sides(self, c1, c2, says):
        with pytest.raises(mb.CompileError, match=says):
            two_links(c1, c2).compile(backend="python", cache=False)

    @pytest.mark.parametrize("name, column", [("t", "time column"), ("kinetic", "kinetic-energy column"),
                                              ("potential", "potential-energy column"),
                                              ("total", "total-energy column")])
    def test_reserved_coordinate_names_are_refused_when_the_joint_is_made(self, name, column):
        with pytest.raises(mb.ModelError, match=rf"Revolute 'j2': coordinate name '{name}' is reserved: it is the {column}"):
            two_links("a", name)

    def test_a_joint_whose_default_coordinate_is_reserved_says_to_give_coords(self):
        m = mb.Model("m")
        body = m.add(mb.Body("b", mass=1.0))
        with pytest.raises(mb.ModelError, match=r"Revolute 't': coordinate name 't' is reserved.*give coords"):
            m.add(mb.Revolute("t", m.ground, body, axis="x"))

    def test_a_coordinate_named_like_a_state_is_refused(self):
        m = two_links("a", "m.current")
        m.add(mb.DCMotor("m", "j1", ratio=1.0, resistance=1.0, inductance=0.01, k=0.1, voltage=1.0))
        with pytest.raises(mb.CompileError, match=r"'m\.current'"):
            m.compile(backend="python", cache=False)

    def test_distinct_names_give_distinct_columns_and_symbols(self, tmp_path):
        import sympy as sp
        system = two_links("a", "a_dd").compile(backend="python", cache=False)
        res = system.simulate(0.2, [0.3, -0.2], t_eval=[0.0, 0.1, 0.2])
        res.to_csv(tmp_path / "out.csv")
        with open(tmp_path / "out.csv", newline="") as fh:
            rows = list(csv.reader(fh))
        header = rows[0]
        assert header == ["t", "a", "a_dd", "a_d", "a_dd_d", "kinetic", "potential", "total"]
        table = np.array(rows[1:], dtype=float)
        np.testing.assert_allclose(table[:, 1], res["a"])
        np.testing.assert_allclose(table[:, 3], res.qd[:, 0])
        np.testing.assert_allclose(table[:, 4], res.qd[:, 1])
        M, f = system.equations()
        free = {str(s) for s in M.free_symbols | f.free_symbols}
        assert {"a", "a_dd"} <= free and "b2.mass" in free
        # each name is one symbol: as many symbols as names
        assert len(M.free_symbols | f.free_symbols) == len(free)
        # and with every other parameter put in, the mass matrix is the two point masses':
        # M[1, 1] = m2 l^2 = b2.mass (l = 1 m), M[0, 0] = m1 + m2 (2 l)^2 at a_dd = 0
        values = {}
        for key, value in system.parameters.items():
            if key != "b2.mass":
                values.update({key: value} if np.ndim(value) == 0 else
                              {f"{key}[{i}]": v for i, v in enumerate(np.ravel(value))})
        M, f = system.equations(values)
        m2, a_dd = sp.Symbol("b2.mass"), sp.Symbol("a_dd")
        assert sp.simplify(M[1, 1] - m2) == 0
        assert sp.simplify(M[0, 0].subs(a_dd, 0) - (1 + 4 * m2)) == 0

    def test_the_dataframe_keeps_every_column(self):
        pd = pytest.importorskip("pandas", exc_type=ImportError)
        system = two_links("a", "a_dd").compile(backend="python", cache=False)
        frame = system.simulate(0.1, [0.3, -0.2], t_eval=[0.0, 0.1]).to_dataframe()
        assert list(frame.columns) == ["a", "a_dd", "a_d", "a_dd_d"] and isinstance(frame, pd.DataFrame)


# -- writers report a failed write -----------------------------------------------------------------
@pytest.fixture(scope="module")
def result():
    system = two_links().compile()
    return system.simulate(0.2, [0.3, -0.2], t_eval=np.linspace(0, 0.2, 5))


@pytest.mark.skipif(not FULL.exists(), reason="needs /dev/full")
class TestFailedWrites:
    def test_csv(self, result):
        with pytest.raises(mb.WriteError, match=r"to_csv: cannot write '/dev/full': No space left on device"):
            result.to_csv(FULL)

    def test_html(self, result):
        with pytest.raises(mb.ModelError, match=r"view: cannot write '/dev/full': No space left on device"):
            result.view(FULL)

    def test_save(self):
        with pytest.raises(mb.ModelError, match=r"save: cannot write '/dev/full': No space left on device"):
            two_links().save(FULL)

    def test_plot(self, result, tmp_path):
        pytest.importorskip("matplotlib", exc_type=ImportError)
        from mbcomp.face.plotting import work_precision_plot
        rows = [{"label": "DOP853", "error": 1e-5, "time": 0.1}, {"label": "DOP853", "error": 1e-7, "time": 0.2}]
        with pytest.raises(mb.ModelError, match=r"savefig: cannot write '/dev/full': No space left on device"):
            work_precision_plot(rows, FULL)

    def test_animation(self, result, monkeypatch):
        pytest.importorskip("PIL", exc_type=ImportError)
        from mbcomp.core import writing
        real = writing.write_file

        def to_full(path, data, what, **options):  # a .gif suffix, the bytes to a full disk
            return real(FULL, data, what)
        monkeypatch.setattr(writing, "write_file", to_full)
        with pytest.raises(mb.ModelError, match=r"animate: cannot write '/dev/full': No space left on device"):
            result.animate("out.gif", fps=5, duration=0.2)

    def test_the_error_is_also_an_os_error(self, result):
        with pytest.raises(OSError):
            result.to_csv(FULL)

    def test_a_close_error_is_reported(self, tmp_path, monkeypatch):
        # A write that only fails when the file is closed (a full disk, a network file system).
        from mbcomp.core import writing
        real_open = open

        class FailsOnClose:
            def __init__(self, fh):
                self.fh = fh

            def __enter__(self):
                return self

            def write(self, data):
                return self.fh.write(data)

            def __exit__(self, *exc):
                self.fh.close()
                raise OSError(errno.EIO, "Input/output error")
        monkeypatch.setattr(writing, "open", lambda *a, **k: FailsOnClose(real_open(*a, **k)), raising=False)
        with pytest.raises(mb.ModelError, match="save: cannot write .*Input/output error"):
            writing.write_file(tmp_path / "x.toml", "x", "save")

    @pytest.mark.parametrize("option", ["--plot", "--out", "--html"])
    def test_the_command_line_fails_and_does_not_say_wrote(self, option, tmp_path, capsys, monkeypatch):
        """The command's ``main`` in this process (the code ``python -m mbcomp.face.cli`` runs,
        without a new interpreter's start-up): exit code 1, the reason, no "wrote"."""
        pytest.importorskip("matplotlib", exc_type=ImportError)
        from mbcomp.face.cli import main
        monkeypatch.chdir(tmp_path)
        monkeypatch.delenv("MBCOMP_LIBRARY", raising=False)
        capsys.readouterr()
        code = main(["run", "double_pendulum", "--t-end", "0.05", "--samples", "3", option, str(FULL)])
        out, err = capsys.readouterr()
        assert code == 1, out + err
        assert "wrote" not in out
        assert "cannot write '/dev/full': No space left on device" in err
        assert "Traceback" not in err


# -- CSV injection ------------------------------------------------------------------------------------
class TestSpreadsheetCells:
    @pytest.mark.parametrize("text, safe", [
        ("=cmd|' /C calc'!A0", "'=cmd|' /C calc'!A0"), ("+1", "'+1"), ("-2", "'-2"), ("@SUM(A1)", "'@SUM(A1)"),
        ("\tx", "'\tx"), ("\rx", "'\rx"), ("phi1", "phi1"), ("a=b", "a=b"), ("", ""),
    ])
    def test_cells_that_start_like_a_formula_get_a_quote(self, text, safe):
        assert spreadsheet_safe(text) == safe

    def test_a_formula_coordinate_name_is_text_in_the_csv(self, tmp_path):
        name = "=cmd|' /C calc'!A0"
        system = two_links(name, "@x").compile(backend="python", cache=False)
        res = system.simulate(0.1, [0.2, 0.1], t_eval=[0.0, 0.1])
        res.to_csv(tmp_path / "out.csv")
        with open(tmp_path / "out.csv", newline="") as fh:
            header = next(csv.reader(fh))
        assert header[1:5] == ["'" + name, "'@x", "'" + name + "_d", "'@x_d"]
        assert not any(cell.startswith(("=", "+", "-", "@", "\t", "\r")) for cell in header)
        assert res[name][0] == pytest.approx(0.2)  # the Result itself keeps the name as given


# -- the viewer's scene data ---------------------------------------------------------------------------
HOSTILE = ["<!--<script>", "</script><script>alert(1)</script>", "a&amp;b", "x\u2028y\u2029z", "<b>]]>",
           "'\"`${x}"]


class TestSceneData:
    @pytest.mark.parametrize("name", HOSTILE)
    def test_the_scene_json_reads_back_to_the_exact_names(self, name):
        scene = {"title": name, "bodies": [{"name": name}], "t": [0.0]}
        page = render_page(scene)
        found = re.search(r'<script type="application/json" id="mbcomp-scene">(.*?)</script>', page, re.S)
        data = found.group(1)
        assert not re.search(r"[<>&\u2028\u2029]", data)
        assert json.loads(data) == scene
        plain = render_page({"title": "x", "bodies": [{"name": "x"}], "t": [0.0]})
        assert page.count("<script") == plain.count("<script") and page.count("<!--") == plain.count("<!--")

    def test_scene_json_escapes_only_what_it_must(self):
        assert scene_json({"a": "x<y"}) == '{"a":"x\\u003cy"}'
        assert json.loads(scene_json({"a": "<&>"})) == {"a": "<&>"}

    def test_a_hostile_body_name_page_draws_in_a_browser(self, tmp_path):
        from browser import Browser, find_chromium
        if find_chromium() is None:
            pytest.skip("no Chromium here")
        name = "<!--<script>"
        system = two_links(body2=name).compile()
        res = system.simulate(0.5, [0.4, 0.2], t_eval=np.linspace(0, 0.5, 6))
        path = res.view(tmp_path / "hostile.html")
        with Browser() as browser:
            run = browser.open(path.as_uri() + "#t=0.2")
        assert 'data-rendered="1"' in run.dom and "data-error" not in run.dom, run.console
        assert run.requests == [] and not run.console
