"""Terms describe themselves: a registry by type key, records that compare by value, and a term
defined outside physcore's own files that adds, saves and loads with no change anywhere else."""
from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np
import pytest

import physcore as pc
from physcore.fluids import Fluid, lattice
from physcore.terms import REGISTRY, Term, _vector


def test_every_term_type_is_registered_once_by_its_key():
    assert {"gravity", "drag", "springs", "pairwise_gravity", "fluid"} <= set(REGISTRY)
    for kind, cls in REGISTRY.items():
        assert cls.kind == kind and issubclass(cls, Term)
    with pytest.raises(TypeError, match="gravity"):

        class Again(Term, kind="gravity"):  # a second class may not take a key
            pass

    assert REGISTRY["gravity"] is pc.Gravity


@pytest.mark.parametrize(
    "make, other",
    [
        (lambda: pc.Gravity([0.0, -9.81]), lambda: pc.Gravity([0.0, -9.8])),
        (lambda: pc.Drag(0.5), lambda: pc.Drag(0.5, name="air")),
        (lambda: pc.PairwiseGravity(G=2.0, softening=0.1), lambda: pc.PairwiseGravity(G=2.0)),
        (lambda: pc.Springs([0, 1], [1, 2], stiffness=[1.0, 2.0]), lambda: pc.Springs([0, 1], [1, 2], stiffness=1.0)),
        (lambda: Fluid(lattice([0, 0], [0.1, 0.1], 0.05), 0.05), lambda: Fluid(lattice([0, 0], [0.1, 0.1], 0.05), 0.04)),
    ],
)
def test_records_compare_by_value(make, other):
    a, b, c = make(), make(), other()
    assert a == b and hash(a) == hash(b)
    assert a != c
    assert a != "not a term"


@dataclasses.dataclass(frozen=True, eq=False)
class _Wind(Term, kind="test_wind"):
    """A term written outside physcore: a uniform acceleration blowing along ``a``. It reuses the
    core's uniform-field kernel, so its whole definition is this class."""

    a: np.ndarray
    name: str = "wind"

    record_fields: ClassVar[dict[str, str]] = {"a": "vector"}

    def __post_init__(self) -> None:
        object.__setattr__(self, "a", _vector(self.a, "a"))

    def _attach(self, scene, name):
        if self.a.shape[0] != scene.dim:
            raise pc.InvalidInputError(f"a: has {self.a.shape[0]} components, the scene is {scene.dim}D")
        scene._sim.add_term("gravity", name, {"g": self.a})
        return dataclasses.replace(self, name=name)


def test_a_new_term_adds_steps_saves_and_loads_without_touching_physcore(tmp_path):
    s = pc.Scene(dim=2, dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.0]], [[0.0, 0.0]], masses=[2.0])
    stored = s.add(_Wind([3.0, 0.0]))
    assert stored == _Wind([3.0, 0.0]) and s.terms == (stored,)
    s.step(1000)
    assert s.positions[0, 0] == pytest.approx(0.5 * 3.0 * 1.0**2, rel=2e-3)
    s.save(tmp_path / "w.npz")
    back = pc.Scene.load(tmp_path / "w.npz")
    assert back.terms == s.terms
    back.step(10)
    s.step(10)
    assert np.array_equal(back.positions, s.positions)
    with pytest.raises(pc.InvalidInputError, match="a: has 3 components"):
        s.add(_Wind([1.0, 0.0, 0.0]))
    assert s.terms == (stored,)


def test_an_unregistered_term_is_refused_when_added_so_saving_never_meets_it():
    @dataclasses.dataclass(frozen=True, eq=False)
    class Unkeyed(Term):  # no kind: not a term type physcore can save
        name: str = "unkeyed"

    s = pc.Scene(dim=2, threads=1)
    with pytest.raises(TypeError, match="Unkeyed"):
        s.add(Unkeyed())
    assert s.terms == ()


@pytest.mark.parametrize(
    "make",
    [
        lambda: pc.Gravity([0.0, -9.81], "g"),
        lambda: pc.Drag(0.1, "air"),
        lambda: pc.PairwiseGravity(1.0, 0.0, "grav"),
        lambda: pc.ElectricField([1.0, 0.0], "e"),
        lambda: pc.Springs([0], [1], 1.0, 0.0, None, "s"),
    ],
)
def test_a_term_name_is_keyword_only(make):
    # The physics arguments may be positional; the energy-book key must be named (name=...).
    with pytest.raises(TypeError, match="positional argument"):
        make()
