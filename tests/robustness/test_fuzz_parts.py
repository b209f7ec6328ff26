"""Hostile-argument fuzzing of the newer parts (issue 44 item 9): the grids (Wave, GrayScott,
StableFluid and their Drop / Oscillator / Source), the flows, the Fluid record and the fluids'
helpers, every term record (fields, XPBD constraints, colliders), the potentials, and the
options of ``render.render_frame`` and ``render.gif``.

Each call gets one hostile argument (NaN, infinities, 1e308, -1, 0, ints beyond float64, bools,
strings, None, lists, ragged and nested lists, numpy arrays of the wrong shape or of bool,
string, object or complex dtype) and must either build something usable or raise TypeError /
ValueError whose message names that argument (see test_fuzz_hostile). A part that is built is
then added to a scene and stepped once: that may refuse it with a PhyscoreError, or report a
divergence, but nothing else. The fast versions run by default (FAST examples each, derandomized
so that CI sees the same cases every run), and so does every value of the hostile list on every
argument; the ``_long`` ones, random, run under ``pytest -m fuzz``.
"""
from __future__ import annotations

import math
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from test_fuzz_hostile import (
    HOSTILE_INTS,
    NOT_NUMBERS,
    NUMPY_SCALARS,
    SPECIAL_FLOATS,
    _check_gif,
    _memory_limit,
    _names,
    _pendulum,
)

import physcore as pc
from physcore import render
from physcore.fluids import kernel_w, lattice, neighbors, tank_walls

FAST = 300  # examples per property in the default run (the lists below are also run whole)
LONG = 4000  # under -m fuzz

#: Hostile values that are not scalars: containers and arrays of every wrong kind.
NOT_SCALARS = [
    [], [[]], [None], ["a", "b"], [1.0, "b"], [[1.0, 2.0], [3.0]], [[[1.0]]], [1e308, 1e308, 1e308], [math.nan] * 3,
    [10**400, 0.0], [True, False], (1.0, 2.0, 3.0, 4.0), {"x": 1.0}, {1.0, 2.0}, range(3),
    np.zeros(0), np.zeros((0, 2)), np.zeros((2, 2, 2, 2)), np.full(3, np.inf), np.zeros(3, dtype=object),
    np.array([1 + 1j, 2]), np.array(["1", "2"]), np.zeros((2, 2), dtype=bool), np.array([None, None]),
    np.zeros((3, 3, 3), dtype=np.float16), np.arange(4, dtype=np.uint8), np.array(1e308), np.array([[1, 2], [3, 4]]),
]
HOSTILE = SPECIAL_FLOATS + HOSTILE_INTS + NOT_NUMBERS + NUMPY_SCALARS + NOT_SCALARS
#: Any hostile value (hypothesis shrinks towards the list's first entries).
hostile = st.one_of(st.sampled_from(HOSTILE), st.floats())


def _step(scene: pc.Scene) -> None:
    try:
        scene.step(1)
    except pc.SimulationDiverged:
        pass


# --------------------------------------------------------------------------- what each part is
def _particles(dim: int, integrator: str = "verlet") -> pc.Scene:
    s = pc.Scene(dim, threads=1, integrator=integrator)
    x = np.zeros((4, dim))
    x[1, 0] = x[3, 0] = x[2, 1] = x[3, 1] = 1.0
    s.add_particles(x)
    return s


def _term(make):
    """A term record: added to a 2D (or, refused there, 3D) scene of 4 particles and stepped."""

    def attach(term):
        for dim in (2, 3):
            s = _particles(dim, "xpbd" if isinstance(term, pc.XpbdConstraints) else "verlet")
            s.set_attribute("charge", [1.0, -1.0, 2.0, -0.5])  # so that the terms on charges act
            try:
                s.add(term)
            except pc.PhyscoreError:
                continue
            _step(s)
            return

    return make, attach


def _grid(make):
    def attach(grid):
        s = pc.Scene(grid.dim, threads=1)
        s.add(grid)
        _step(s)

    return make, attach


def _flow(make):
    def attach(flow):
        s = pc.Scene(flow.dim, threads=1)
        s.add(flow)
        _step(s)

    return make, attach


def _plain(make):
    return make, None


def _fluid(make):
    def attach(fluid):
        s = pc.Scene(fluid.dim, threads=1, integrator="semi_implicit_euler" if fluid.method == "dfsph" else "verlet")
        s.add(fluid)
        _step(s)

    return make, attach


X2 = lattice([0.0, 0.0], [0.4, 0.2], 0.1)
WALLS = [[0.0, -0.1], [0.1, -0.1], [0.2, -0.1], [0.3, -0.1]]
SQ = (12, 10)

#: "Part.argument" -> (make(value), attach(part) or None).
PARTS = {
    # terms
    "Gravity.g": _term(lambda v: pc.Gravity(v)),
    "Gravity.name": _term(lambda v: pc.Gravity([0.0, -9.81], name=v)),
    "Drag.coefficient": _term(lambda v: pc.Drag(v)),
    "Springs.rest_length": _term(lambda v: pc.Springs([0], [1], rest_length=v)),
    "Springs.name": _term(lambda v: pc.Springs([0], [1], name=v)),
    "PairwiseGravity.softening": _term(lambda v: pc.PairwiseGravity(softening=v)),
    "TreeGravity.G": _term(lambda v: pc.TreeGravity(G=v)),
    "TreeGravity.softening": _term(lambda v: pc.TreeGravity(softening=v)),
    "TreeGravity.theta": _term(lambda v: pc.TreeGravity(theta=v)),
    "ElectricField.E": _term(lambda v: pc.ElectricField(v)),
    "Coulomb.k": _term(lambda v: pc.Coulomb(k=v)),
    "Coulomb.softening": _term(lambda v: pc.Coulomb(softening=v)),
    "MagneticField.B": _term(lambda v: pc.MagneticField(v)),
    "GridElectricField.E": _term(lambda v: pc.GridElectricField(v, [0.0, 0.0], spacing=0.5)),
    "GridElectricField.origin": _term(lambda v: pc.GridElectricField(np.ones((3, 3, 2)), v, spacing=0.5)),
    "GridElectricField.spacing": _term(lambda v: pc.GridElectricField(np.ones((3, 3, 2)), [0.0, 0.0], spacing=v)),
    "GridMagneticField.B": _term(lambda v: pc.GridMagneticField(v, [0.0, 0.0], spacing=0.5)),
    "GridMagneticField.origin": _term(lambda v: pc.GridMagneticField(np.ones((3, 3)), v, spacing=0.5)),
    "GridMagneticField.spacing": _term(lambda v: pc.GridMagneticField(np.ones((3, 3)), [0.0, 0.0], spacing=v)),
    "Plane.friction": _term(lambda v: pc.Plane([0.0, 0.0], [0.0, 1.0], friction=v)),
    "Box.lower": _term(lambda v: pc.Box(v, [2.0, 2.0])),
    "Box.restitution": _term(lambda v: pc.Box([-1.0, -1.0], [2.0, 2.0], restitution=v)),
    "Sphere.center": _term(lambda v: pc.Sphere(v, 3.0, inside=True)),
    "Sphere.radius": _term(lambda v: pc.Sphere([0.0, 0.0], v)),
    "Sphere.restitution": _term(lambda v: pc.Sphere([0.0, 0.0], 3.0, restitution=v)),
    "Sphere.friction": _term(lambda v: pc.Sphere([0.0, 0.0], 3.0, friction=v)),
    "Sphere.inside": _term(lambda v: pc.Sphere([0.0, 0.0], 3.0, inside=v)),
    # XPBD: each argument on its own, the others at their defaults (or the one they need)
    "XpbdConstraints.distance": _term(lambda v: pc.XpbdConstraints(distance=v)),
    "XpbdConstraints.distance_compliance": _term(lambda v: pc.XpbdConstraints(distance=[[0, 1]], distance_compliance=v)),
    "XpbdConstraints.rest_length": _term(lambda v: pc.XpbdConstraints(distance=[[0, 1]], rest_length=v)),
    "XpbdConstraints.bending": _term(lambda v: pc.XpbdConstraints(bending=v)),
    "XpbdConstraints.bending_compliance": _term(lambda v: pc.XpbdConstraints(bending=[[0, 1, 3]], bending_compliance=v)),
    "XpbdConstraints.rest_angle": _term(lambda v: pc.XpbdConstraints(bending=[[0, 1, 3]], rest_angle=v)),
    "XpbdConstraints.pins": _term(lambda v: pc.XpbdConstraints(pins=v)),
    "XpbdConstraints.pin_targets": _term(lambda v: pc.XpbdConstraints(pins=[0], pin_targets=v)),
    "XpbdConstraints.pin_compliance": _term(lambda v: pc.XpbdConstraints(pins=[0], pin_compliance=v)),
    "XpbdConstraints.area": _term(lambda v: pc.XpbdConstraints(area=v)),
    "XpbdConstraints.area_compliance": _term(lambda v: pc.XpbdConstraints(area=[[0, 1, 2]], area_compliance=v)),
    "XpbdConstraints.rest_area": _term(lambda v: pc.XpbdConstraints(area=[[0, 1, 2]], rest_area=v)),
    "XpbdConstraints.volume": _term(lambda v: pc.XpbdConstraints(volume=v)),
    "XpbdConstraints.rest_volume": _term(lambda v: pc.XpbdConstraints(volume=[[0, 1, 2, 3]], rest_volume=v)),
    "XpbdConstraints.shapes": _term(lambda v: pc.XpbdConstraints(shapes=v)),
    "XpbdConstraints.shape_sizes": _term(lambda v: pc.XpbdConstraints(shapes=[[0, 1, 2]], shape_sizes=v)),
    "XpbdConstraints.shape_rest": _term(lambda v: pc.XpbdConstraints(shapes=[[0, 1, 2]], shape_rest=v)),
    "XpbdConstraints.shape_stiffness": _term(lambda v: pc.XpbdConstraints(shapes=[[0, 1, 2]], shape_stiffness=v)),
    "XpbdConstraints.name": _term(lambda v: pc.XpbdConstraints(distance=[[0, 1]], name=v)),
    # potentials
    "PointMasses.positions": _term(lambda v: pc.PointMasses(v, [1.0])),
    "PointMasses.masses": _term(lambda v: pc.PointMasses([[5.0, 5.0]], v)),
    "PointMasses.G": _term(lambda v: pc.PointMasses([[5.0, 5.0]], [1.0], G=v)),
    "PointMasses.softening": _term(lambda v: pc.PointMasses([[5.0, 5.0]], [1.0], softening=v)),
    "PointCharges.positions": _term(lambda v: pc.PointCharges(v, [1.0])),
    "PointCharges.charges": _term(lambda v: pc.PointCharges([[5.0, 5.0]], v)),
    "PointCharges.k": _term(lambda v: pc.PointCharges([[5.0, 5.0]], [1.0], k=v)),
    "HarmonicTrap.k": _term(lambda v: pc.HarmonicTrap(v)),
    "HarmonicTrap.center": _term(lambda v: pc.HarmonicTrap(1.0, center=v)),
    "HarmonicTrap.name": _term(lambda v: pc.HarmonicTrap(1.0, name=v)),
    "PotentialGrid.phi": _term(lambda v: pc.PotentialGrid(v, 0.5)),
    "PotentialGrid.spacing": _term(lambda v: pc.PotentialGrid(np.zeros((4, 4)), v)),
    "PotentialGrid.origin": _term(lambda v: pc.PotentialGrid(np.zeros((4, 4)), 0.5, origin=v)),
    "PotentialGrid.coupling": _term(lambda v: pc.PotentialGrid(np.zeros((4, 4)), 0.5, coupling=v)),
    # grids
    "Wave.shape": _grid(lambda v: pc.Wave(v)),
    "Wave.spacing": _grid(lambda v: pc.Wave(SQ, v)),
    "Wave.c": _grid(lambda v: pc.Wave(SQ, c=v)),
    "Wave.damping": _grid(lambda v: pc.Wave(SQ, damping=v)),
    "Wave.edges": _grid(lambda v: pc.Wave(SQ, edges=v)),
    "Wave.absorbing": _grid(lambda v: pc.Wave(SQ, absorbing=v)),
    "Wave.layer": _grid(lambda v: pc.Wave(SQ, absorbing=("x-",), layer=v)),
    "Wave.layer_strength": _grid(lambda v: pc.Wave(SQ, absorbing=("x-",), layer=3, layer_strength=v)),
    "Wave.mask": _grid(lambda v: pc.Wave(SQ, mask=v)),
    "Wave.drops": _grid(lambda v: pc.Wave(SQ, drops=v)),
    "Wave.oscillators": _grid(lambda v: pc.Wave(SQ, oscillators=v)),
    "Wave.cfl": _grid(lambda v: pc.Wave(SQ, cfl=v)),
    "Wave.name": _grid(lambda v: pc.Wave(SQ, name=v)),
    "Drop.t": _grid(lambda v: pc.Wave(SQ, drops=[pc.Drop(v, (5.0, 5.0), radius=2.0, amplitude=0.1)])),
    "Drop.center": _grid(lambda v: pc.Wave(SQ, drops=[pc.Drop(0.0, v, radius=2.0, amplitude=0.1)])),
    "Drop.radius": _grid(lambda v: pc.Wave(SQ, drops=[pc.Drop(0.0, (5.0, 5.0), radius=v, amplitude=0.1)])),
    "Drop.amplitude": _grid(lambda v: pc.Wave(SQ, drops=[pc.Drop(0.0, (5.0, 5.0), radius=2.0, amplitude=v)])),
    "Oscillator.amplitude": _grid(lambda v: pc.Wave(SQ, oscillators=[pc.Oscillator(v, 1.0, center=(5.0, 5.0), radius=2.0)])),
    "Oscillator.frequency": _grid(lambda v: pc.Wave(SQ, oscillators=[pc.Oscillator(0.1, v, center=(5.0, 5.0), radius=2.0)])),
    "Oscillator.center": _grid(lambda v: pc.Wave(SQ, oscillators=[pc.Oscillator(0.1, 1.0, center=v, radius=2.0)])),
    "Oscillator.radius": _grid(lambda v: pc.Wave(SQ, oscillators=[pc.Oscillator(0.1, 1.0, center=(5.0, 5.0), radius=v)])),
    "Oscillator.region": _grid(lambda v: pc.Wave(SQ, oscillators=[pc.Oscillator(0.1, 1.0, region=v)])),
    "Oscillator.phase": _grid(lambda v: pc.Wave(SQ, oscillators=[pc.Oscillator(0.1, 1.0, center=(5.0, 5.0), radius=2.0, phase=v)])),
    "GrayScott.shape": _grid(lambda v: pc.GrayScott(v, preset="spots")),
    "GrayScott.spacing": _grid(lambda v: pc.GrayScott(SQ, v, preset="spots")),
    "GrayScott.du": _grid(lambda v: pc.GrayScott(SQ, du=v, preset="spots")),
    "GrayScott.dv": _grid(lambda v: pc.GrayScott(SQ, dv=v, preset="spots")),
    "GrayScott.feed": _grid(lambda v: pc.GrayScott(SQ, feed=v, kill=0.06)),
    "GrayScott.kill": _grid(lambda v: pc.GrayScott(SQ, feed=0.03, kill=v)),
    "GrayScott.preset": _grid(lambda v: pc.GrayScott(SQ, preset=v)),
    "GrayScott.edges": _grid(lambda v: pc.GrayScott(SQ, edges=v, preset="spots")),
    "GrayScott.cfl": _grid(lambda v: pc.GrayScott(SQ, cfl=v, preset="spots")),
    "StableFluid.shape": _grid(lambda v: pc.StableFluid(v)),
    "StableFluid.spacing": _grid(lambda v: pc.StableFluid(SQ, v)),
    "StableFluid.nu": _grid(lambda v: pc.StableFluid(SQ, nu=v)),
    "StableFluid.buoyancy": _grid(lambda v: pc.StableFluid(SQ, buoyancy=v)),
    "StableFluid.ambient_temperature": _grid(lambda v: pc.StableFluid(SQ, ambient_temperature=v)),
    "StableFluid.vorticity": _grid(lambda v: pc.StableFluid(SQ, vorticity=v)),
    "StableFluid.advection": _grid(lambda v: pc.StableFluid(SQ, advection=v)),
    "StableFluid.tolerance": _grid(lambda v: pc.StableFluid(SQ, tolerance=v)),
    "StableFluid.max_iterations": _grid(lambda v: pc.StableFluid(SQ, max_iterations=v)),
    "StableFluid.walls": _grid(lambda v: pc.StableFluid(SQ, walls=v)),
    "StableFluid.lid": _grid(lambda v: pc.StableFluid(SQ, lid=v)),
    "StableFluid.inflow": _grid(lambda v: pc.StableFluid(SQ, inflow=v)),
    "StableFluid.obstacles": _grid(lambda v: pc.StableFluid(SQ, obstacles=v)),
    "StableFluid.sources": _grid(lambda v: pc.StableFluid(SQ, sources=v)),
    "StableFluid.tracers": _grid(lambda v: pc.StableFluid(SQ, tracers=v)),
    "StableFluid.cfl": _grid(lambda v: pc.StableFluid(SQ, cfl=v)),
    "Source.density": _grid(lambda v: pc.StableFluid(SQ, sources=[pc.Source(density=v, center=(0.1, 0.1), radius=0.03)])),
    "Source.temperature": _grid(lambda v: pc.StableFluid(SQ, sources=[pc.Source(temperature=v, center=(0.1, 0.1), radius=0.03)])),
    "Source.velocity": _grid(lambda v: pc.StableFluid(SQ, sources=[pc.Source(velocity=v, center=(0.1, 0.1), radius=0.03)])),
    "Source.center": _grid(lambda v: pc.StableFluid(SQ, sources=[pc.Source(center=v, radius=0.03)])),
    "Source.radius": _grid(lambda v: pc.StableFluid(SQ, sources=[pc.Source(center=(0.1, 0.1), radius=v)])),
    "Source.region": _grid(lambda v: pc.StableFluid(SQ, sources=[pc.Source(region=v)])),
    # flows
    "Flow.kind": _flow(lambda v: pc.Flow(v)),
    "Flow.points": _flow(lambda v: pc.Flow("lorenz", v)),
    "Flow.spread": _flow(lambda v: pc.Flow("lorenz", 3, spread=v)),
    "Flow.seed": _flow(lambda v: pc.Flow("lorenz", 3, seed=v)),
    "Flow.method": _flow(lambda v: pc.Flow("lorenz", method=v)),
    "Flow.max_dt": _flow(lambda v: pc.Flow("lorenz", max_dt=v)),
    "Flow.name": _flow(lambda v: pc.Flow("lorenz", name=v)),
    "rho": _flow(lambda v: pc.Flow("lorenz", rho=v)),
    "mu": _flow(lambda v: pc.Flow("van_der_pol", mu=v)),
    # fluids
    "Fluid.positions": _fluid(lambda v: pc.Fluid(v, 0.1, sound_speed=20.0)),
    "Fluid.spacing": _fluid(lambda v: pc.Fluid(X2, v, sound_speed=20.0)),
    "Fluid.method": _fluid(lambda v: pc.Fluid(X2, 0.1, boundary=WALLS, method=v, sound_speed=20.0)),
    "Fluid.density_error": _fluid(lambda v: pc.Fluid(X2, 0.1, boundary=WALLS, method="dfsph", density_error=v, sound_speed=20.0)),
    "Fluid.divergence_error": _fluid(lambda v: pc.Fluid(X2, 0.1, boundary=WALLS, method="dfsph", divergence_error=v, sound_speed=20.0)),
    "Fluid.max_iterations": _fluid(lambda v: pc.Fluid(X2, 0.1, boundary=WALLS, method="dfsph", max_iterations=v, sound_speed=20.0)),
    "Fluid.cfl": _fluid(lambda v: pc.Fluid(X2, 0.1, boundary=WALLS, cfl=v, sound_speed=20.0)),
    "Fluid.surface_tension": _fluid(lambda v: pc.Fluid(X2, 0.1, boundary=WALLS, surface_tension=v, sound_speed=20.0)),
    "Fluid.adhesion": _fluid(lambda v: pc.Fluid(X2, 0.1, boundary=WALLS, adhesion=v, sound_speed=20.0)),
    "Fluid.gamma": _fluid(lambda v: pc.Fluid(X2, 0.1, boundary=WALLS, gamma=v, sound_speed=20.0)),
    "Fluid.name": _fluid(lambda v: pc.Fluid(X2, 0.1, name=v, sound_speed=20.0)),
    "Fluid.first": _fluid(lambda v: pc.Fluid(X2, 0.1, first=v, sound_speed=20.0)),
    "neighbors.points": _plain(lambda v: neighbors(v, 0.5)),
    "neighbors.radius": _plain(lambda v: neighbors(X2, v)),
    "lattice.lower": _plain(lambda v: lattice(v, [0.4, 0.2], 0.1)),
    "lattice.upper": _plain(lambda v: lattice([0.0, 0.0], v, 0.1)),
    "lattice.spacing": _plain(lambda v: lattice([0.0, 0.0], [0.4, 0.2], v)),
    "tank_walls.lower": _plain(lambda v: tank_walls(v, [0.4, 0.2], 0.1)),
    "tank_walls.spacing": _plain(lambda v: tank_walls([0.0, 0.0], [0.4, 0.2], v)),
    "tank_walls.layers": _plain(lambda v: tank_walls([0.0, 0.0], [0.4, 0.2], 0.1, v)),
    "tank_walls.top": _plain(lambda v: tank_walls([0.0, 0.0], [0.4, 0.2], 0.1, top=v)),
    "kernel_w.q": _plain(lambda v: kernel_w(v, 0.1, 2)),
    "kernel_w.h": _plain(lambda v: kernel_w(np.linspace(0, 2, 5), v, 2)),
    "kernel_w.dim": _plain(lambda v: kernel_w(np.linspace(0, 2, 5), 0.1, v)),
    "kernel_w.kernel": _plain(lambda v: kernel_w(np.linspace(0, 2, 5), 0.1, 2, v)),
}


def _refused(exc: BaseException, arg: str, call: str) -> None:
    """A refusal must be physcore's (or a TypeError) and name the argument."""
    assert isinstance(exc, (TypeError, pc.InvalidInputError)), f"{call:.200}: {type(exc).__name__}: {exc}"
    assert _names(exc, arg), f"{call:.200}: {type(exc).__name__} does not name {arg!r}: {exc}"


def _arg(key: str) -> str:
    return key.rsplit(".", 1)[-1]


def _check_part(case) -> str:
    """"built" (and, for a part that joins a scene, added and stepped) or "refused" by name.

    Refused: TypeError or ValueError naming the argument. Once built, adding and stepping may
    raise only a PhyscoreError (a refusal by the scene, a reported divergence)."""
    key, value = case
    make, attach = PARTS[key]
    arg = _arg(key)
    with _memory_limit(64 << 20):
        try:
            part = make(value)
        except (TypeError, ValueError) as e:
            _refused(e, arg, f"{key}={value!r}")
            return "refused"
        if attach is not None:
            try:
                with warnings.catch_warnings():
                    # A valid but extreme value (a wave speed of 1e300) may put the step past
                    # a grid's stability limit, which the step warns of.
                    warnings.simplefilter("ignore", pc.StabilityWarning)
                    attach(part)
            except pc.PhyscoreError:
                pass
    return "built"


_part_case = st.sampled_from(sorted(PARTS)).flatmap(lambda k: st.tuples(st.just(k), hostile))


@settings(max_examples=FAST, derandomize=True, deadline=None)
@given(_part_case)
def test_fuzz_parts(case):
    assert _check_part(case) in ("built", "refused")


@pytest.mark.fuzz
@settings(max_examples=LONG, deadline=None)
@given(_part_case)
def test_fuzz_parts_long(case):
    assert _check_part(case) in ("built", "refused")


@pytest.mark.parametrize("key", sorted(PARTS))
def test_every_hostile_value_on_every_part(key):
    """Every value of the hostile list on this argument (cheap: about 3 s for all of them)."""
    for value in HOSTILE:
        assert _check_part((key, value)) in ("built", "refused")


# --------------------------------------------------------------------------- render_frame
P2 = np.array([[0.0, 0.0], [1.0, 0.5], [0.5, 1.0]])
FRAME_ARGS = ["positions", "size", "velocities", "pinned", "springs", "planes", "pressures", "boundary", "color_by",
              "speed_scale", "pressure_scale", "colorbar", "radius", "view", "extent"]
_frame_value = st.one_of(hostile, st.sampled_from([(16, 16), (10**6, 10**6), (16, -1), P2, P2[:, :1], [[0, 1]], [[0, 5]],
                                                   [pc.Plane([0.0, 0.0], [0.0, 1.0])], ["x"], "pressure", "none"]))
_frame_case = st.tuples(st.sampled_from(FRAME_ARGS), _frame_value)


def _check_frame(case) -> str:
    arg, value = case
    kwargs = {"size": (32, 24), arg: value}
    positions = kwargs.pop("positions", P2)
    with _memory_limit(1 << 20):
        try:
            image = render.render_frame(positions, **kwargs)
        except (TypeError, ValueError) as e:
            _refused(e, arg, f"{arg}={value!r}")
            return "refused"
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    return "drawn"


@settings(max_examples=FAST, derandomize=True, deadline=None)
@given(_frame_case)
def test_fuzz_render_frame(case):
    assert _check_frame(case) in ("drawn", "refused")


@pytest.mark.fuzz
@settings(max_examples=LONG, deadline=None)
@given(_frame_case)
def test_fuzz_render_frame_long(case):
    assert _check_frame(case) in ("drawn", "refused")


@pytest.mark.parametrize("arg", FRAME_ARGS)
def test_every_hostile_value_on_render_frame(arg):
    for value in HOSTILE:
        assert _check_frame((arg, value)) in ("drawn", "refused")


# --------------------------------------------------------------------------- gif's newer options
GIF_OPTIONS = ["trail", "size_by", "theme", "title", "camera", "arrows", "mesh", "texture", "antialias", "colors",
               "cmap", "background", "surface", "extent", "halo", "loop", "look"]
_gif_value = st.one_of(hostile, st.sampled_from(["mass", "dark", "light", "orbit", "velocity", "viridis", "auto",
                                                 "#ff0000", (255, 0, 0), "x" * 300, "\x00", [[0, 1, 2]]]))
_gif_case = st.tuples(st.sampled_from(GIF_OPTIONS), _gif_value)


def _check_gif_option(case) -> bool:
    """True when the option drew a GIF (one file) or was refused (none), as it must."""
    arg, value = case
    outcome, files = _check_gif(case)
    assert len(files) == (outcome == "written"), f"{arg}={value!r}: {outcome}, files left: {files}"
    return len(files) == (outcome == "written")


@settings(max_examples=FAST, derandomize=True, deadline=None)
@given(_gif_case)
@example(("trail", 10**30))
def test_fuzz_gif_options(case):
    assert _check_gif_option(case)


@pytest.mark.fuzz
@settings(max_examples=LONG, deadline=None)
@given(_gif_case)
def test_fuzz_gif_options_long(case):
    assert _check_gif_option(case)


@pytest.mark.parametrize("arg", GIF_OPTIONS)
def test_every_hostile_value_on_gif_options(arg):
    for value in HOSTILE:
        assert _check_gif_option((arg, value))


def test_gif_option_fuzz_draws_a_scene():
    """The base case of the gif option fuzz writes a GIF (so that refusals are refusals)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = render.gif(_pendulum(), Path(tmp) / "x.gif", frames=2, size=(32, 24))
        assert out.stat().st_size > 0
