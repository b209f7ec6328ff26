"""One part protocol (issue 45, step 1): everything a scene holds — terms, colliders, grids,
flows, fluids — is a registered part (physcore._parts) that attaches through a small context,
writes its own entry of the scene file and loads itself back. Scene.add and the scene file have
no branch per kind, so a new kind of part joins a scene without any change to scene.py."""
from __future__ import annotations

import ast
import dataclasses
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

import physcore as pc
from physcore import _parts
from physcore._parts import PARTS, SECTIONS, AttachContext, Part
from physcore.fluids import Fluid, lattice, tank_walls
from physcore.terms import REGISTRY, Term, _vector

PKG = Path(pc.__file__).resolve().parent


def test_the_registry_holds_every_part_kind_under_its_section():
    expected = {
        "planes/plane": pc.Plane,
        "boxes/box": pc.Box,
        "spheres/sphere": pc.Sphere,
        "grids/wave": pc.Wave,
        "grids/gray_scott": pc.GrayScott,
        "grids/stable_fluid": pc.StableFluid,
        "flows/flow": pc.Flow,
        "terms/fluid": Fluid,
        "terms/contacts": pc.Contacts,
    }
    for key, cls in expected.items():
        assert PARTS[key] is cls
    for kind, cls in REGISTRY.items():  # every term type is a part of the "terms" section
        assert PARTS[f"terms/{kind}"] is cls
    for key, cls in PARTS.items():
        section, kind = key.split("/")
        assert issubclass(cls, Part) and cls.section == section and cls.part_kind == kind
        assert section in SECTIONS
    # The grid fluid and the term "fluid" are two parts with two kinds (issue 45: one meaning per word).
    assert PARTS["grids/stable_fluid"] is not PARTS["terms/fluid"] and "grids/fluid" not in PARTS


def test_a_key_is_taken_once():
    with pytest.raises(TypeError, match="'box' is already the key of Box"):

        class Crate(Part):
            section = "boxes"
            part_kind = "box"

    assert PARTS["boxes/box"] is pc.Box
    with pytest.raises(TypeError, match="section"):

        class Nowhere(Part):
            section = "nowhere"
            part_kind = "nowhere"


# ----------------------------------------------------------------------------- a new kind of part
@dataclasses.dataclass(frozen=True, eq=False)
class _Spring2Origin(Term, kind="test_tether"):
    """A part written here, outside physcore: a uniform pull along ``a`` (the core's
    uniform-field kernel) that also checks the scene's particle count through the context."""

    a: np.ndarray
    name: str = dataclasses.field(default="tether", kw_only=True)

    record_fields: ClassVar[dict[str, str]] = {"a": "vector"}

    def __post_init__(self) -> None:
        object.__setattr__(self, "a", _vector(self.a, "a"))

    def _attach(self, ctx: AttachContext, name: str) -> _Spring2Origin:
        if ctx.n_particles == 0:
            raise pc.InvalidInputError("a: a tether needs particles")
        if self.a.shape[0] != ctx.dim:
            raise pc.InvalidInputError(f"a: has {self.a.shape[0]} components, the scene is {ctx.dim}D")
        ctx.sim.add_term("gravity", name, {"g": self.a})
        return dataclasses.replace(self, name=name)


class _Marker(Part):
    """A part that is not a term at all: it registers nothing with the core and only records
    what the context told it."""

    section: ClassVar[str] = "terms"
    part_kind: ClassVar[str] = "test_marker"
    changes_energy: ClassVar[bool] = False

    def __init__(self, name: str = "marker") -> None:
        self.name = name
        self.seen: dict[str, Any] = {}

    def _claim_name(self, ctx: AttachContext) -> str:
        return _parts.unique_name(self.name, ctx.names["terms"])

    def _attach(self, ctx: AttachContext, name: str) -> _Marker:
        out = _Marker(name)
        out.seen = {
            "dim": ctx.dim,
            "integrator": ctx.integrator,
            "n": ctx.n_particles,
            "attributes": ctx.attributes,
            "names": dict(ctx.names),
            "parts": len(ctx.parts),
        }
        return out


def test_a_new_part_kind_joins_a_scene_through_scene_add_without_touching_scene_py(tmp_path):
    s = pc.Scene(dim=2, dt=1e-3, threads=1)
    with pytest.raises(pc.InvalidInputError, match="needs particles"):
        s.add(_Spring2Origin([1.0, 0.0]))
    assert s.terms == ()
    s.add_particles([[0.0, 0.0]], masses=[2.0])
    s.set_attribute("charge", [1.0])
    s.add(pc.Gravity([0.0, -1.0]))
    stored = s.add(_Spring2Origin([3.0, 0.0]))
    assert stored.name == "tether" and s.terms[-1] is stored
    marker = s.add(_Marker())
    assert marker.seen == {
        "dim": 2,
        "integrator": "verlet",
        "n": 1,
        "attributes": frozenset({"charge"}),
        "names": {"terms": frozenset({"gravity", "tether"}), "grids": frozenset(), "flows": frozenset()},
        "parts": 2,
    }
    assert s.add(_Marker()).name == "marker_2"
    s.step(1000)
    assert s.positions[0, 0] == pytest.approx(0.5 * 3.0, rel=2e-3)


def test_a_new_term_kind_round_trips_through_the_scene_file(tmp_path):
    s = pc.Scene(dim=3, dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.0, 0.0]])
    s.add(_Spring2Origin([0.0, 1.0, 0.0], name="pull"))
    s.step(10)
    back = pc.Scene.load(s.save(tmp_path / "t.npz"))
    assert back.terms == s.terms
    back.step(5)
    s.step(5)
    assert np.array_equal(back.positions, s.positions)


# ------------------------------------------------------------------------------ every kind, saved
def _every_kind() -> list[pc.Scene]:
    a = pc.Scene(2, threads=1)
    a.add_particles([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    a.set_attribute("charge", [1e-6, -1e-6, 0.0])
    for t in (
        pc.Gravity([0.0, -9.81]), pc.Drag(0.1), pc.Springs([0], [1]), pc.PairwiseGravity(G=1e-3), pc.TreeGravity(G=1e-3),
        pc.ElectricField([1.0, 0.0]), pc.Coulomb(softening=0.1), pc.MagneticField(0.5),
        pc.GridElectricField(np.ones((3, 3, 2)), [-1.0, -1.0], spacing=1.0), pc.GridMagneticField(np.ones((3, 3)), [-1.0, -1.0], spacing=1.0),
        pc.PointMasses([[5.0, 5.0]], [1.0]), pc.PointCharges([[5.0, -5.0]], [1e-9]), pc.HarmonicTrap(0.5),
        pc.PotentialGrid(np.zeros((4, 4)), 0.5, origin=[-1.0, -1.0]),
        pc.Plane([0.0, -1.0], [0.0, 1.0]), pc.Box([-3.0, -3.0], [3.0, 3.0]), pc.Sphere([0.0, 0.0], 9.0, inside=True),
        pc.Capsule([-4.0, -2.5], [4.0, -2.5], 0.2), pc.OrientedBox([6.0, 6.0], [0.5, 0.25], 0.3),
        pc.Wave((8, 8), 0.1, drops=[pc.Drop(0.0, (0.4, 0.4), radius=0.1, amplitude=0.01)]), pc.GrayScott((8, 8), preset="spots"),
        pc.StableFluid((8, 8), 0.1, tracers=4), pc.Flow("van_der_pol", 3, seed=1),
    ):
        a.add(t)
    b = pc.Scene(2, integrator="xpbd", threads=1)
    b.add_particles([[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]])
    b.set_attribute("radius", [0.05] * 3)
    b.add(pc.XpbdConstraints(distance=[[0, 1]], area=[[0, 1, 2]]))
    b.add(pc.Contacts(1e3))
    c = pc.Scene(2, integrator="semi_implicit_euler", threads=1)
    c.add(pc.Gravity([0.0, -9.81]))
    c.add_fluid(lattice([0, 0], [0.05, 0.05], 0.01), spacing=0.01, boundary=tank_walls([0, 0], [0.1, 0.1], 0.01))
    d = pc.Scene(2, integrator="semi_implicit_euler", threads=1)
    d.add(pc.Gravity([0.0, -9.81]))
    d.add(Fluid(lattice([0, 0], [0.05, 0.05], 0.01), 0.01, method="dfsph"))
    e = pc.Scene(3, threads=1)
    e.add(pc.Flow("lorenz", 4, seed=2))
    f = pc.Scene(2, integrator="semi_implicit_euler", threads=1)
    f.add(pc.Gravity([0.0, -9.81]))
    f.add(pc.Bodies("box", size=[(2.0, 0.1)], positions=[(0.0, -0.1)], kind="fixed"))
    tri = f.add(pc.Bodies("polygon", positions=[(0.0, 0.5), (0.3, 0.9)], vertices=[(0, 0), (0.2, 0), (0, 0.2)]))
    f.add(pc.Joints("rope", tri[0], tri[1], anchors=(0.0, 0.5), anchors_b=(0.3, 0.9), length=0.6))
    f.add_particles([[0.5, 1.0]])
    g = pc.Scene(3, integrator="semi_implicit_euler", threads=1)
    g.add(pc.Gravity([0.0, 0.0, -9.81]))
    g.add(pc.Bodies("mesh", vertices=[(-2, -2, 0), (2, -2, 0), (2, 2, 0)], triangles=[(0, 1, 2)], kind="fixed"))
    hull = g.add(pc.Bodies("hull", positions=[(0.0, 0.0, 0.5), (0.3, 0.0, 0.9)], orientations=[(0, 0, 0.6, 0.8)] * 2,
                           vertices=[(0, 0, 0), (0.2, 0, 0), (0, 0.2, 0), (0, 0, 0.2)]))
    g.add(pc.Joints("spherical", hull[0], hull[1], anchors=(0.1, 0.0, 0.7)))
    g.add(pc.Joints("revolute", None, hull[0], anchors=(0.0, 0.0, 0.5), axis=(0.0, 1.0, 0.0), limits=(-1.0, 1.0)))
    g.add_particles([[0.3, 0.0, 1.0], [0.4, 0.0, 1.0]])
    g.add(pc.Pins([1], hull[1]))
    return [a, b, c, d, e, f, g]


def test_the_scene_file_round_trips_every_part_kind(tmp_path):
    scenes = _every_kind()
    kinds = {f"{p.section}/{p.part_kind}" for s in scenes for p in s._parts}
    assert kinds >= {k for k in PARTS if not k.startswith("terms/test_")}
    for k, s in enumerate(scenes):
        s.step(2)
        path = s.save(tmp_path / f"s{k}.npz")
        back = pc.Scene.load(path)
        assert [type(p) for p in back._parts] == [type(p) for p in sorted(s._parts, key=lambda p: SECTIONS.index(p.section))]
        # (A loaded fluid's record holds what the file holds: its mass and wall volumes resolved.)
        assert [t for t in back.terms if t not in back.fluids] == [t for t in s.terms if t not in s.fluids]
        assert [(f.name, f.first, len(f)) for f in back.fluids] == [(f.name, f.first, len(f)) for f in s.fluids]
        assert [g.name for g in back.grids] == [g.name for g in s.grids]
        assert [f.name for f in back.flows] == [f.name for f in s.flows]
        assert repr(back) == repr(s)
        # The reloaded scene writes the same bytes, and steps on as the original does.
        assert back.save(tmp_path / f"b{k}.npz").read_bytes() == path.read_bytes()
        s.step(3)
        back.step(3)
        assert s.save(tmp_path / f"s{k}.npz").read_bytes() == back.save(tmp_path / f"b{k}.npz").read_bytes()


def test_scene_colliders_is_one_list_of_every_collider_record(tmp_path):
    """Issue 62, one shape layer: ``Scene.colliders`` lists every collider record, the plane,
    box and sphere sections first and then the keyed colliders, each in the order added (the
    file's order, so a loaded copy lists them alike); ``planes``, ``boxes`` and ``spheres``
    stay as they were."""
    s = pc.Scene(2)
    s.add_particles([[0.0, 0.5]])
    rod, block = pc.Capsule([-1.0, 0.0], [1.0, 0.2], 0.1), pc.OrientedBox([0.0, -1.0], [2.0, 1.0], 0.3)
    ball, box, floor = pc.Sphere([3.0, 0.0], 0.5), pc.Box([-5.0, -5.0], [5.0, 5.0]), pc.Plane([0.0, -3.0], [0.0, 1.0])
    for c in (rod, ball, box, block, floor):
        s.add(c)
    assert [type(c) for c in s.colliders] == [pc.Plane, pc.Box, pc.Sphere, pc.Capsule, pc.OrientedBox]
    assert s.colliders[0] is floor and s.colliders[1] is box and s.colliders[2] is ball
    assert s.colliders[3:] == [rod, block]
    assert len(s.planes) == 1 + 4 and s.boxes == [box] and s.spheres == [ball]
    s.colliders.clear()  # a new list each time
    assert len(s.colliders) == 5
    back = pc.Scene.load(s.save(tmp_path / "all.npz"))
    assert [type(c) for c in back.colliders] == [type(c) for c in s.colliders] and back.colliders[3:] == [rod, block]
    assert pc.Scene(3).colliders == []
    from physcore.testing import assert_momentum_conserved

    only_box = pc.Scene(2)
    only_box.add_particles([[0.0, 0.0]])
    only_box.add(pc.Box([-1.0, -1.0], [1.0, 1.0]))
    with pytest.raises(pc.InvalidInputError, match="colliders"):  # a box alone is a collider too
        assert_momentum_conserved(only_box, 1)


# ----------------------------------------------------------------------------------- refusals
@pytest.mark.parametrize("item", [object(), "gravity", 3.0, None, Part()])
def test_scene_add_refuses_what_is_not_a_part_naming_item_and_every_kind_it_takes(item):
    s = pc.Scene(2, threads=1)
    with pytest.raises(pc.InvalidTypeError, match=r"^item: expected a part of physcore \(") as err:
        s.add(item)
    for kind in ("Gravity", "Springs", "Fluid", "Plane", "Capsule", "OrientedBox", "Bodies", "Joints", "Contacts", "Wave"):
        assert kind in str(err.value), kind
    assert s._parts == []


def test_scene_add_of_a_class_asks_for_an_instance():
    s = pc.Scene(2, threads=1)
    with pytest.raises(pc.InvalidTypeError, match=r"^item: got the class Gravity, not a part: did you mean Gravity\(\.\.\.\)\?"):
        s.add(pc.Gravity)
    assert s._parts == []


def test_an_unregistered_subclass_of_a_part_is_refused():
    class Ball(pc.Sphere):  # no key of its own: files could not name it
        pass

    s = pc.Scene(2, threads=1)
    with pytest.raises(pc.InvalidTypeError, match="item: .*Ball"):
        s.add(Ball([0.0, 0.0], 1.0))
    assert s.spheres == []


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: pc.Plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), "point: has 3 components"),
        (lambda: pc.Box([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]), "lower: has 3 components"),
        (lambda: pc.Sphere([0.0, 0.0, 0.0], 1.0), "center: has 3 components"),
        (lambda: pc.Gravity([0.0, 0.0, -1.0]), "g: has 3 components"),
        (lambda: pc.Springs([0], [7]), "j: index 7 is out of range"),
        (lambda: pc.Contacts(1e3), "integrator: Contacts need"),
        (lambda: pc.Wave((4, 4, 4)), "item: a 3D grid"),
        (lambda: pc.Flow("lorenz"), "item: a 3D flow"),
        (lambda: Fluid(lattice([0, 0, 0], [0.05, 0.05, 0.05], 0.01), 0.01), "positions: the fluid is 3D"),
        (lambda: Fluid(lattice([0, 0], [0.05, 0.05], 0.01), 0.01, method="dfsph"), "method: DFSPH steps with"),
    ],
)
def test_nothing_is_added_when_attach_fails(make, match):
    s = pc.Scene(2, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]])
    s.add(pc.Gravity([0.0, -9.81]))
    before = (s._file_arrays()["meta"].item(), s.n_particles, s.dt)
    with pytest.raises(pc.PhyscoreError, match=match):
        s.add(make())
    assert (s._file_arrays()["meta"].item(), s.n_particles, s.dt) == before
    assert len(s._parts) == 1


def test_a_grid_or_flow_joins_one_scene_under_a_free_name():
    s = pc.Scene(2, threads=1)
    s.add(pc.Drag(0.1, name="pond"))
    with pytest.raises(pc.InvalidInputError, match="name: 'pond' is taken"):
        s.add(pc.Wave((4, 4), name="pond"))
    w = s.add(pc.Wave((4, 4)))
    with pytest.raises(pc.InvalidInputError, match="already in a scene"):
        pc.Scene(2, threads=1).add(w)
    with pytest.raises(pc.InvalidInputError, match="name: 'particles' is taken"):
        s.add(pc.Flow("van_der_pol", name="particles"))
    assert s.grids == (w,) and s.flows == ()


# ------------------------------------------------------------------------------- the import graph
PART_MODULES = ("terms", "contacts", "flows", "fluids", "grids", "potentials", "_scenefile", "_parts")


def _imports(module: str) -> set[str]:
    """physcore modules imported by ``module`` anywhere in it (functions and TYPE_CHECKING too);
    a package's (terms/) by any of its files, which reach physcore's modules as ``..``."""
    package = (PKG / module).is_dir()
    level = 2 if package else 1
    out = set()
    for path in sorted((PKG / module).glob("*.py")) if package else [PKG / f"{module}.py"]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == level:
                if node.module:
                    out.add(node.module.split(".")[0])
                else:
                    out.update(a.name for a in node.names)
    return out


@pytest.mark.parametrize("module", PART_MODULES)
def test_no_part_module_imports_the_scene(module):
    assert "scene" not in _imports(module)


def test_parts_and_the_scene_file_import_no_part_module():
    assert _imports("_parts") <= {"_errors"}
    assert not _imports("_scenefile") & {"terms", "contacts", "flows", "fluids", "grids", "potentials", "scene"}


def test_there_is_no_import_circle_among_the_scene_and_its_parts():
    modules = ("scene", *PART_MODULES)
    graph = {m: _imports(m) & set(modules) for m in modules}

    def reaches(a: str, b: str, seen: frozenset[str] = frozenset()) -> bool:
        return any(n == b or (n not in seen and reaches(n, b, seen | {n})) for n in graph[a])

    assert not [m for m in modules if reaches(m, m)]
