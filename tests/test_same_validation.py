"""One validation per parameter: for every parameter of every registered component kind,
the constructor, attribute assignment, ``System.with_parameters`` and a model file reject
the same bad values, naming the component and the attribute."""
from __future__ import annotations

import math

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

import mbcomp as mb
from mbcomp.spec.components.base import KINDS
from mbcomp.files.component_tables import toml_value
from mbcomp.files.toml_model import dumps, load
from mbcomp.core.params import ParameterError, in_range, nonnegative, positive, spd_inertia

NAN = float("nan")


def base_model():
    m = mb.Model("m")
    m.add(mb.Body("b", mass=1.0, com=(0, 0, -1.0), inertia=(0.1, 0.1, 0.1)))
    m.add(mb.Spherical("j", m.ground, "b", sequence="xy"))
    m.add(mb.Body("c", mass=1.0, com=(0, 0, -0.5), inertia=(0.1, 0.1, 0.1)))
    m.add(mb.Revolute("h", "b", "c", axis="x", parent_point=(0, 0, -1.0)))
    return m


#: kind -> (component name, keyword arguments of a valid instance)
EXAMPLES = {
    "body": ("d", dict(mass=1.0, com=(0, 0, -1.0), inertia=(0.1, 0.2, 0.25))),
    "revolute": ("r", dict(parent="c", child="d", axis="y", parent_point=(0, 0, -1.0))),
    "prismatic": ("r", dict(parent="c", child="d", axis="y", parent_point=(0, 0, -1.0))),
    "spring": ("k", dict(a="ground", b=("c", (0, 0, -1.0)), stiffness=10.0, rest_length=0.5, damping=0.1)),
    "damper": ("k", dict(a="ground", b=("c", (0, 0, -1.0)), damping=0.1)),
    "force": ("f", dict(body="c", point=(0, 0, -1.0), force=(1.0, 0, 0))),
    "joint_torque": ("tq", dict(joint="h", value=0.5)),
    "torsion_spring": ("ts", dict(joint="h", stiffness=2.0, rest=0.1, damping=0.2)),
    "slider": ("sl", dict(body="c", point=(0, 0, -1.0), origin=(0, 0, -2.0), axis="x")),
    "motor": ("mo", dict(joint="h", speed=1.0)),
    "contact": ("ct", dict(body="c", point=(0, 0, -1.0), normal="z", origin=(0, 0, -3.0), restitution=0.5)),
    "collision": ("hit", dict(a=("c", mb.Sphere(0.1, origin=(0, 0, -1.0))), b=("ground", mb.Plane(origin=(0, 0, -3.0))),
                              restitution=0.5, friction=0.3)),
    "drive": ("dr", dict(joint="h", ratio=10.0, rotor_inertia=1e-4, torque=0.1)),
    "dc_motor": ("dc", dict(joint="h", ratio=10.0, resistance=1.0, inductance=1e-3, k=0.05, voltage=1.0)),
    "joint_friction": ("fr", dict(joint="h", coulomb=0.1, viscous=0.01)),
    "joint_limit": ("lim", dict(joint="h", lower=-1.0, upper=1.0, restitution=0.5)),
    "rolling_disc": ("rd", dict(disc="c", radius=0.5, axis="y", center=(0, 0, 0.1), origin=(0, 0, -1.2))),
    "rolling_ball": ("rb", dict(ball="c", radius=0.5, center=(0, 0, 0.1), origin=(0, 0, -1.3))),
    "no_slip": ("ns", dict(body="c", point=(0, 0, -1.0), direction="x")),
}
#: Kinds whose parameters are tested with their own component (controllers take signals).
ELSEWHERE = {"pid"}
#: Kinds tested elsewhere or without run-time parameters beyond their joint points.
SPHERICAL_LIKE = {"spherical": dict(sequence="z"), "fixed": {}}


def build(kind: str):
    """The base model plus one component of ``kind`` (joints bring a body ``d``)."""
    m = base_model()
    cls = KINDS[kind]
    if cls.section == "joints":
        name, kwargs = EXAMPLES.get(kind, ("r", dict(parent="c", child="d", parent_point=(0, 0, -1.0),
                                                     **SPHERICAL_LIKE.get(kind, {}))))
        m.add(mb.Body("d", mass=1.0, com=(0, 0, -0.5), inertia=(0.1, 0.1, 0.1)))
    else:
        name, kwargs = EXAMPLES[kind]
    return m, cls, name, kwargs


def bad_values(spec):
    """Values the spec must reject (beyond type errors)."""
    vector = tuple(spec.shape) == (3,) and spec.check is not spd_inertia
    out = [(NAN, 0.0, 0.0) if vector else NAN, (1.0, 2.0) if vector or spec.check is spd_inertia else [1.0, 2.0],
           "abc"]
    if tuple(spec.shape) == (-1,):
        del out[1]  # any length is a value; its size is checked against the joint (compile, file)
    if spec.check is positive:
        out += [-2.0, 0.0]
    if spec.check is nonnegative:
        out += [-2.0]
    if spec.check.describe.startswith("in ["):
        out += [1.5, -0.1]
    if spec.check is spd_inertia:
        out += [(1.0, 1.0, 5.0), (-1.0, 1.0, 1.0), [[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]]
    return out


def cases():
    for kind, cls in list(KINDS.items()):
        if kind not in EXAMPLES and kind not in SPHERICAL_LIKE:
            continue
        for spec in cls.params:
            if spec.structural:
                continue
            for i, bad in enumerate(bad_values(spec)):
                yield pytest.param(kind, spec.name, bad, id=f"{kind}-{spec.name}-{i}")


def detail(exc: BaseException) -> str:
    assert isinstance(exc, ParameterError), exc
    return exc.detail


def to_toml(value):
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(to_toml(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value + '"'
    return repr(float(value))


def write_file(tmp_path, model, section, name, key, bad, role=None):
    """The model's file with one value replaced by ``bad``."""
    data = tomllib.loads(dumps(model))
    lines = [f'name = "{data["name"]}"']
    for sec in ("bodies", "joints", "forces", "constraints", "contacts", "collisions"):
        for comp, table in data.get(sec, {}).items():
            lines.append(f"[{sec}.{comp}]")
            for k, v in table.items():
                if sec == section and comp == name and role is not None and k == role:
                    body = v if isinstance(v, str) else v["body"]
                    lines.append(f'{k} = {{ body = "{body}", point = {to_toml(bad)} }}')
                    continue
                if sec == section and comp == name and k == key:
                    v = bad
                elif isinstance(v, dict) and "point" not in v:   # a collision side: a body and a shape
                    lines.append(f"{k} = {toml_value(v)}")
                    v = None
                elif isinstance(v, dict):
                    v = None
                    lines.append(f'{k} = {{ body = "{table[k]["body"]}", point = {to_toml(table[k]["point"])} }}')
                if v is not None:
                    lines.append(f"{k} = {to_toml(v)}")
            if sec == section and comp == name and key not in table and role is None:
                lines.append(f"{key} = {to_toml(bad)}")
    path = tmp_path / "m.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


#: The tests that use ``systems`` stay on one worker (pytest-xdist): each worker would compile
#: every kind's system again.
ONE_WORKER = pytest.mark.xdist_group("same-validation")


@pytest.fixture(scope="module")
def systems():
    """One compiled system per kind (the python backend: no C compile needed for parameters)."""
    out = {}
    for kind in list(EXAMPLES) + list(SPHERICAL_LIKE):
        m, cls, name, kwargs = build(kind)
        if cls.section != "bodies":
            m.add(cls(name, **kwargs))
        else:
            m.add(cls(name, **kwargs))
            m.add(mb.Revolute("rd", "c", name, axis="y", parent_point=(0, 0, -1.0)))
        out[kind] = (m, m.compile(backend="python"))
    return out


@ONE_WORKER
@pytest.mark.parametrize("kind, attr, bad", list(cases()))
def test_same_verdict_everywhere(kind, attr, bad, systems, tmp_path):
    m, cls, name, kwargs = build(kind)
    owner = f"{cls.__name__} {name!r}"
    spec = cls.spec(attr)
    # 1. the constructor
    args = dict(kwargs)
    if attr in ("point_a", "point_b"):
        role = attr[-1]
        body = args[role][0] if isinstance(args[role], tuple) else args[role]
        args[role] = (body, bad)
    else:
        args[attr] = bad
    with pytest.raises(mb.ModelError, match=f"^{owner}: {attr} ") as built:
        cls(name, **args)
    expected = detail(built.value)
    # 2. assignment after construction
    comp = cls(name, **kwargs)
    with pytest.raises(mb.ModelError) as assigned:
        setattr(comp, attr, bad)
    assert str(assigned.value) == str(built.value)
    # 3. with_parameters / simulate(parameters=)
    model, system = systems[kind]
    key = f"{name}.{attr}"
    if key in system.parameters:
        with pytest.raises(mb.ModelError) as rebound:
            system.with_parameters({key: bad})
        assert str(rebound.value) == str(built.value), (rebound.value, built.value)
    else:
        assert spec.optional or spec.time_input, f"{key} is not a run-time parameter"
    # 4. a model file
    if not cls.file_keys:
        return
    role = attr[-1] if attr in ("point_a", "point_b") else None
    path = write_file(tmp_path, model, cls.section, name, attr, bad, role=role)
    with pytest.raises(mb.ModelError) as read:
        load(path)
    message = str(read.value)
    where = f"[{cls.section}.{name}.{role}] point" if role else f"[{cls.section}.{name}] {attr}"
    assert where in message, message
    if spec.check.describe not in ("finite",) and not isinstance(bad, str) and not (
            isinstance(bad, (tuple, list)) and len(bad) == 2):
        if not (isinstance(bad, float) and math.isnan(bad)) and not (isinstance(bad, tuple) and any(
                isinstance(v, float) and math.isnan(v) for v in bad)):
            assert f"{where}: {expected}" in message, (expected, message)


@ONE_WORKER
@pytest.mark.parametrize("kind", sorted(set(EXAMPLES) | set(SPHERICAL_LIKE)))
def test_good_values_round_trip_through_a_file(kind, systems, tmp_path):
    model, system = systems[kind]
    if not KINDS[kind].file_keys:
        pytest.skip(f"{kind} has no file form")
    path = tmp_path / "m.toml"
    model.save(path)
    again = load(path).compile(backend="python")
    assert again.parameters == system.parameters


def test_every_registered_kind_is_covered():
    ours = {k for k, c in KINDS.items() if c.__module__.startswith("mbcomp.")}  # not classes tests define
    missing = ours - set(EXAMPLES) - set(SPHERICAL_LIKE) - ELSEWHERE
    assert missing <= {k for k, c in KINDS.items() if c.section == "joints"}, missing
