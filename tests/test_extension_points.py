"""The public extension points (docs/architecture.md): a joint written only as segments closes
loops in both formulations, a force element of the user's own is saved and loaded with no
file code, and the hooks that had private names still work (with a warning) for a release."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.core.params import ParameterSpec, nonnegative
from mbcomp.spec.components.base import KINDS, ForceElement
from mbcomp.spec.components.joints import Joint

ROOT = Path(__file__).resolve().parent.parent
A, B, C, D, RHO = 0.1, 0.35, 0.3, 0.4, 2.0      # crank, coupler, rocker, ground (m); kg/m


@pytest.fixture
def kinds():
    """A test may register a component kind: not for later tests."""
    saved = dict(KINDS)
    yield
    KINDS.clear()
    KINDS.update(saved)


# -- joints of the user's own, defined only by their segments -------------------------------------
class Hinge(Joint):
    """A rotation about z, written only as its segment."""

    n_coords = 1

    def screws(self):
        return [("R", (0.0, 0.0, 1.0))]


class Slide(Joint):
    """A translation along x, written only as its segment."""

    n_coords = 1
    coord_unit = "m"

    def screws(self):
        return [("P", (1.0, 0.0, 0.0))]


class Knuckle(Joint):
    """A free rotation (a quaternion), written only as its segment."""

    n_coords = 4
    coord_suffixes = ("qw", "qx", "qy", "qz")

    def segments(self):
        return [("B", None)]


class SlotPin(Joint):
    """Turns about y, slides along the turned z, turns about x: the slide's axis is fixed in
    neither the parent nor the child frame."""

    n_coords = 3
    coord_suffixes = ("a", "s", "b")

    def segments(self):
        return [("R", (0.0, 1.0, 0.0)), ("P", (0.0, 0.0, 1.0)), ("R", (1.0, 0.0, 0.0))]


def bar(m: mb.Model, name: str, length: float) -> mb.Body:
    inertia = (1e-6, RHO * length ** 3 / 12, RHO * length ** 3 / 12)
    return m.add(mb.Body(name, mass=RHO * length, com=(length / 2, 0, 0), inertia=inertia))


def four_bar(closing) -> mb.Model:
    """Crank, coupler and rocker turning about z under gravity -y; joint C (coupler to
    rocker, made by ``closing(name, parent, child, **points)``) closes the loop."""
    m = mb.Model("four_bar", gravity=(0, -9.81, 0))
    crank, coupler, rocker = bar(m, "crank", A), bar(m, "coupler", B), bar(m, "rocker", C)
    m.add(mb.Revolute("A", m.ground, crank, axis="z", coords="theta1"))
    m.add(mb.Revolute("B", crank, coupler, axis="z", parent_point=(A, 0, 0), coords="theta2"))
    m.add(mb.Revolute("D", m.ground, rocker, axis="z", parent_point=(D, 0, 0), coords="theta4"))
    m.add(closing("C", coupler, rocker, parent_point=(B, 0, 0), child_point=(C, 0, 0)))
    return m


def slider_crank(closing) -> mb.Model:
    """Crank and rod under gravity -y, a block on the rod's end; the block's joint to the
    ground along x (``closing``) closes the loop."""
    m = mb.Model("slider_crank", gravity=(0, -9.81, 0))
    crank, rod = bar(m, "crank", 0.1), bar(m, "rod", 0.3)
    block = m.add(mb.Body("block", mass=0.5, inertia=(1e-4, 1e-4, 1e-4)))
    m.add(mb.Revolute("A", m.ground, crank, axis="z", coords="theta"))
    m.add(mb.Revolute("B", crank, rod, axis="z", parent_point=(0.1, 0, 0), coords="phi"))
    m.add(mb.Revolute("P", rod, block, axis="z", parent_point=(0.3, 0, 0), coords="psi"))
    m.add(closing("S", m.ground, block))
    return m


CASES = {
    "hinge": (four_bar, Hinge, lambda n, a, b, **kw: mb.Revolute(n, a, b, axis="z", **kw),
              [np.pi / 2, -1.0, 1.9], [3.0, 0.0, 0.0]),
    "knuckle": (four_bar, Knuckle, mb.Ball, [np.pi / 2, -1.0, 1.9], [3.0, 0.0, 0.0]),
    "slide": (slider_crank, Slide, lambda n, a, b, **kw: mb.Prismatic(n, a, b, axis="x", **kw),
              [0.7, -0.9, 0.2], [2.0, 0.0, 0.0]),
}


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_a_joint_of_segments_closes_a_loop_like_the_library_joint(case, formulation):
    """The user's joint closing the loop gives the library joint's trajectory (1e-9), its
    reactions and its closure (a crank-angle run of 1 s, the loop held to 1e-8)."""
    build, mine, library, q_guess, qd_guess = CASES[case]
    runs = []
    for closing in (mine, library):
        system = build(closing).compile(formulation)
        assert system.ndof == 1
        q, qd = system.assemble(q_guess, qd_guess)
        reactions = system.reactions(q, qd)[("C" if build is four_bar else "S")]
        res = system.simulate(1.0, q, qd, t_eval=np.linspace(0.0, 1.0, 51), rtol=1e-10, atol=1e-12)
        assert res.constraint_violation().max() < 1e-6
        runs.append((q, reactions, res))
    (q1, r1, res1), (q2, r2, res2) = runs
    assert np.max(np.abs(q1 - q2)) <= 1e-9
    assert np.max(np.abs(np.asarray(r1) - np.asarray(r2))) <= 1e-9
    assert np.max(np.abs(res1.q - res2.q)) <= 1e-9 and np.max(np.abs(res1.qd - res2.qd)) <= 1e-9
    assert abs(np.ptp(res1.energy().total)) < 1e-6   # conservative: the closure does no work


def test_a_user_joint_closes_the_loop_from_its_own_segments():
    """The closure conditions come from the segments: a hinge about z keeps the two points
    together along world x, y, z and z parallel to the two normals of z (the equations a
    Revolute about z gives), and the four-bar's tree keeps its three coordinates."""
    from mbcomp.spec.components.constraints import LoopClosure
    m = four_bar(Hinge)
    ours = LoopClosure(m["C"]).equations(m.ground)
    theirs = LoopClosure(mb.Revolute("C", m["coupler"], m["rocker"], axis="z", parent_point=(B, 0, 0),
                                     child_point=(C, 0, 0))).equations(m.ground)
    assert ours == theirs
    assert [e.label for e in ours] == ["x", "y", "z", "t1", "t2"]
    assert m.compile().coords == ("theta1", "theta2", "theta4")


def test_a_joint_whose_translation_turns_cannot_close_a_loop():
    """A translation along an axis that turns with the joint's rotation (not fixed in either
    frame) is refused with the joint's name, not with a wrong equation."""
    m = four_bar(lambda n, a, b, **kw: SlotPin(n, a, b, **kw))
    with pytest.raises(mb.ModelError, match="SlotPin 'C'.*translation axis turns"):
        m.compile()


# -- a force element of the user's own: its file form ----------------------------------------------
def page_namespace() -> dict:
    """The contributor page's force-element block, run as the docs test runs it."""
    from test_examples import python_blocks
    page = ROOT / "docs" / "architecture.md"
    (line, source), = [(n, s) for n, s in python_blocks(page.read_text()) if "class LinearDrag" in s]
    namespace: dict = {"__name__": "docs_architecture"}
    exec(compile(source, f"docs/architecture.md:{line}", "exec"), namespace)  # noqa: S102 - our own docs
    return namespace


def test_the_pages_force_element_is_saved_and_loaded(tmp_path, kinds):
    """The page's LinearDrag, off its body's centre on a pendulum, is written by save and
    read back by load; both models give the same run, and its parameters stay run-time ones."""
    LinearDrag = page_namespace()["LinearDrag"]
    m = mb.Model("swing", gravity=(0, -9.81, 0))
    bob = m.add(mb.Body("bob", mass=1.5, com=(0, -0.8, 0), inertia=(1e-3, 1e-3, 1e-3)))
    m.add(mb.Revolute("pivot", m.ground, bob, axis="z", coords="theta"))
    m.add(LinearDrag("air", bob, damping=0.7, point=(0.0, -0.8, 0.0)))
    path = tmp_path / "swing.toml"
    m.save(path)
    text = path.read_text()
    assert 'type = "linear_drag"' in text and 'body = "bob"' in text and "point = [0.0, -0.8, 0.0]" in text
    again = mb.load(path)
    assert isinstance(again["air"], LinearDrag) and again["air"].body == "bob"
    first, second = m.compile(), again.compile()
    res1, res2 = (s.simulate(3.0, [1.0], [0.0], t_eval=np.linspace(0, 3, 31)) for s in (first, second))
    assert np.array_equal(res1.q, res2.q)
    # the drag dissipates: the energy falls, by the work of c v^2 (a point 0.8 m out: v = 0.8 theta')
    energy = res1.energy().total
    assert energy[-1] < energy[0]
    theta_d = first.simulate(3.0, [1.0], [0.0], t_eval=np.linspace(0, 3, 3001))["theta_d"]
    from scipy.integrate import trapezoid
    work = trapezoid(0.7 * (0.8 * theta_d) ** 2, dx=0.001)
    assert energy[0] - energy[-1] == pytest.approx(work, rel=1e-4)
    # damping is a run-time parameter of the loaded model too
    assert second.parameters["air.damping"] == 0.7
    stiffer = second.with_parameters({"air.damping": 1.4}).simulate(3.0, [1.0], [0.0], t_eval=np.linspace(0, 3, 31))
    assert abs(stiffer.q[-1, 0]) < abs(res2.q[-1, 0])


def test_a_force_element_on_a_joint_gets_its_file_form(tmp_path, kinds):
    """An element that names a joint: the argument ``joint`` is a joint reference in the file,
    a constructor argument without a default is required, and the rest are parameters."""
    class Brake(ForceElement):
        """A viscous torque -c q' (N m) on a 1-DOF joint."""

        kind = "test_brake"
        params = (ParameterSpec("c", (), "N m s", nonnegative),)

        def __init__(self, name, joint, c):
            super().__init__(name)
            self.joint, self.c = joint, c

        def references(self):
            return {"joint": self.joint}

        def loads(self, kin):
            (rate,) = kin.qd(self.joint)
            return [("generalized", self.joint, [-kin.param(self, "c") * rate])]

    assert Brake.refs == {"joint": "joint"} and Brake.file_keys == ("joint", "c") and Brake.file_required == ("joint", "c")
    assert Brake.section == "forces"
    m = mb.Model("braked", gravity=(0, -9.81, 0))
    bob = m.add(mb.Body("bob", mass=1.0, com=(0, -1, 0), inertia=(1e-3, 1e-3, 1e-3)))
    m.add(mb.Revolute("pivot", m.ground, bob, axis="z", coords="theta"))
    m.add(Brake("brake", "pivot", c=0.3))
    path = tmp_path / "braked.toml"
    m.save(path)
    assert 'joint = "pivot"' in path.read_text()
    again = mb.load(path)
    res1, res2 = (x.compile().simulate(2.0, [0.5], t_eval=np.linspace(0, 2, 21)) for x in (m, again))
    assert np.array_equal(res1.q, res2.q)
    # the brake's torque -c theta' at a state: the acceleration against the free pendulum's
    braked, free = again.compile(), mb.load(path).compile().with_parameters({"brake.c": 0.0})
    gap = braked.accelerations([0.5], [2.0])[0] - free.accelerations([0.5], [2.0])[0]
    assert gap == pytest.approx(-0.3 * 2.0 / (1.0 + 1e-3), rel=1e-12)   # -c theta' / (m l^2 + I_zz)
    broken = path.read_text().replace("c = 0.3\n", "")
    path.write_text(broken)
    with pytest.raises(mb.ModelError, match=r"\[forces.brake\] c: missing"):
        mb.load(path)


def test_the_old_private_hook_names_still_work_with_a_warning(kinds):
    """``_loads`` (and the other old names) is taken as ``loads`` for one release, with a
    DeprecationWarning that names the new name; the element then acts the same."""
    with pytest.warns(DeprecationWarning, match="_loads is deprecated: name the method loads"):
        class OldPush(ForceElement):
            def __init__(self, name, body):
                super().__init__(name)
                self.body = body

            def references(self):
                return {"body": self.body}

            def _loads(self, kin):
                return [("point", self.body, kin.position(self.body, (0.0, 0.0, 0.0)), [2.0, 0.0, 0.0])]

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = mb.Model("pushed", gravity=(0, 0, 0))
        box = m.add(mb.Body("box", mass=4.0, inertia=(1e-3, 1e-3, 1e-3)))
        m.add(mb.Prismatic("rail", m.ground, box, axis="x", coords="x"))
        m.add(OldPush("push", box))
        assert m.compile().accelerations([0.0], [0.0])[0] == pytest.approx(0.5, rel=1e-14)  # F / m


# -- hooks instead of type tests: a joint given backwards, a parametrisation's singularity -----------
def test_a_joint_given_backwards_is_turned_round_by_its_own_hook():
    """A revolute joint from the bob to the ground (``Joint.reversed``: about -z from the
    ground) has the forward pendulum's dynamics with the angle's sign flipped:
    ``theta''_backward(theta) = -theta''_forward(-theta)``."""
    def pendulum(backward: bool) -> mb.System:
        m = mb.Model("pendulum", gravity=(0, -9.81, 0))
        bob = m.add(mb.Body("bob", mass=1.2, com=(0.0, -0.3, 0.0), inertia=(1e-3, 1e-3, 2e-3)))
        if backward:
            m.add(mb.Revolute("pivot", bob, m.ground, axis="z", parent_point=(0.0, 0.5, 0.0),
                              child_point=(0.1, 0.0, 0.0), coords="theta"))
        else:
            m.add(mb.Revolute("pivot", m.ground, bob, axis="z", parent_point=(0.1, 0.0, 0.0),
                              child_point=(0.0, 0.5, 0.0), coords="theta"))
        return m.compile()

    forward, backward = pendulum(False), pendulum(True)
    assert backward.coords == ("theta",)
    for theta, rate in ((0.4, 0.0), (-1.1, 2.0)):
        expected = -forward.accelerations([-theta], [-rate])[0]
        assert backward.accelerations([theta], [rate])[0] == pytest.approx(expected, rel=1e-12)
    # closed form: theta'' = -m g r sin(theta) / (m r^2 + I_zz), r = 0.8 m below the pivot
    assert forward.accelerations([0.4], [0.0])[0] == pytest.approx(
        -1.2 * 9.81 * 0.8 * np.sin(0.4) / (1.2 * 0.8 ** 2 + 2e-3), rel=1e-12)


def test_a_user_joints_singularity_hook_names_it_when_the_mass_matrix_is_singular():
    """A gimbal written as three rotations (x, y, x) is singular where y's angle is 0; its
    ``singularity`` hook gives the message the simulation error carries."""
    class Gimbal(Joint):
        n_coords = 3
        coord_suffixes = ("a", "b", "c")

        def screws(self):
            return [("R", (1.0, 0.0, 0.0)), ("R", (0.0, 1.0, 0.0)), ("R", (1.0, 0.0, 0.0))]

        def singularity(self, q):
            return f"gimbal {self.name!r} locked (b = {q[1]:g})" if abs(np.sin(q[1])) < 1e-6 else None

    m = mb.Model("gimbal", gravity=(0, 0, 0))
    rotor = m.add(mb.Body("rotor", mass=1.0, inertia=(1.0, 2.0, 3.0)))
    m.add(Gimbal("mount", m.ground, rotor))
    system = m.compile()
    assert np.linalg.matrix_rank(system.mass_matrix([0.2, 0.0, 0.1])) == 2
    with pytest.raises(mb.SimulationError, match="gimbal 'mount' locked \\(b = 0\\)"):
        system.accelerations([0.2, 0.0, 0.1], [0.0, 0.0, 0.0])
    assert np.all(np.isfinite(system.accelerations([0.2, 0.5, 0.1], [0.0, 0.0, 0.0])))


def test_a_reference_of_no_known_role_names_a_body_or_a_joint(tmp_path, kinds):
    """A constructor argument the role rule does not know (``target``) is a reference to a
    body or a joint by name: a joint's name is written and read back, an unknown name is
    refused with the file's location."""
    class Pull(ForceElement):
        """A constant generalised force (N or N m) on a 1-DOF joint."""

        kind = "test_pull"
        params = (ParameterSpec("size", (), "N"),)

        def __init__(self, name, target, size):
            super().__init__(name)
            self.target, self.size = target, size

        def references(self):
            return {"target": self.target}

        def loads(self, kin):
            return [("generalized", self.target, [kin.param(self, "size")])]

    assert Pull.refs == {"target": "component"}
    m = mb.Model("pulled", gravity=(0, 0, 0))
    box = m.add(mb.Body("box", mass=2.0, inertia=(1e-3, 1e-3, 1e-3)))
    m.add(mb.Prismatic("rail", m.ground, box, axis="x", coords="x"))
    m.add(Pull("pull", "rail", size=3.0))
    path = tmp_path / "pulled.toml"
    m.save(path)
    assert 'target = "rail"' in path.read_text()
    again = mb.load(path)
    assert again["pull"].target == "rail"
    assert again.compile().accelerations([0.0], [0.0])[0] == pytest.approx(3.0 / 2.0, rel=1e-14)   # F / m
    path.write_text(path.read_text().replace('target = "rail"', 'target = "rial"'))
    with pytest.raises(mb.ModelError, match=r"\[forces.pull\] target: unknown body or joint 'rial' \(did you mean 'rail'\?\)"):
        mb.load(path)


def test_an_argument_that_is_neither_parameter_nor_reference_is_not_guessed(tmp_path, kinds):
    """A derived file form takes an unknown argument for a reference; when the element does
    not list it in ``references()``, saving refuses with the argument's name instead of
    writing a file that cannot be read back."""
    class Nudge(ForceElement):
        kind = "test_nudge"
        params = (ParameterSpec("size", (), "N"),)

        def __init__(self, name, body, size, mode="push"):
            super().__init__(name)
            self.body, self.size, self.mode = body, size, mode

        def references(self):
            return {"body": self.body}

        def loads(self, kin):
            return [("point", self.body, kin.position(self.body, (0.0, 0.0, 0.0)), [kin.param(self, "size"), 0.0, 0.0])]

    m = mb.Model("nudged", gravity=(0, 0, 0))
    box = m.add(mb.Body("box", mass=2.0, inertia=(1e-3, 1e-3, 1e-3)))
    m.add(mb.Prismatic("rail", m.ground, box, axis="x", coords="x"))
    m.add(Nudge("nudge", box, 1.0))
    with pytest.raises(mb.ModelError, match="Nudge 'nudge'.*argument 'mode' is neither a declared parameter"):
        m.save(tmp_path / "nudged.toml")
    assert not (tmp_path / "nudged.toml").exists()
