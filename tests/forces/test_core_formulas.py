"""Each formula in one language (issue 45, step 2): the fluid's resolution (kernel, particle
mass, wall volumes, sound speed, step limit at rest), grid step limits, the part–integrator
rules and the rule for dt live in the core; the facade shows the core's values and messages.
And the core's replace_term, through Scene.replace: a parameter changed in place continues
exactly as a scene rebuilt from its own file with the new record would."""
from __future__ import annotations

import ast
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

import physcore as pc
from physcore import _core
from physcore._live import _rebuild
from physcore.fluids import Fluid, kernel_w, lattice, lattice_density_sum, tank_walls

PKG = Path(pc.__file__).resolve().parent


def _closed_form_w(q: np.ndarray, h: float, dim: int, kernel: str) -> np.ndarray:
    """The kernels as printed (Monaghan & Lattanzio 1985 eq. 21; Wendland C2), σ over h^dim."""
    if kernel == "cubic_spline":
        s = (10 / (7 * math.pi) if dim == 2 else 1 / math.pi) / h**dim
        return s * (0.25 * np.clip(2 - q, 0, None) ** 3 - np.clip(1 - q, 0, None) ** 3)
    s = (7 / (4 * math.pi) if dim == 2 else 21 / (16 * math.pi)) / h**dim
    return s * np.clip(1 - q / 2, 0, None) ** 4 * (2 * q + 1)


@pytest.mark.parametrize("kernel", ["cubic_spline", "wendland_c2"])
@pytest.mark.parametrize("dim", [2, 3])
def test_the_cores_kernel_is_the_printed_kernel_and_integrates_to_one(kernel, dim):
    h = 0.013
    q = np.linspace(0.0, 2.5, 251)
    np.testing.assert_allclose(kernel_w(q, h, dim, kernel), _closed_form_w(q, h, dim, kernel), rtol=1e-13, atol=0)
    # ∫ W dV = 1 over the support (shell quadrature in q, midpoint rule).
    qm = (np.arange(20000) + 0.5) * (2.0 / 20000)
    shell = 2 * math.pi * qm * h if dim == 2 else 4 * math.pi * (qm * h) ** 2
    assert np.sum(kernel_w(qm, h, dim, kernel) * shell * h * (2.0 / 20000)) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_lattice_at_the_particle_mass_sits_at_the_rest_density(dim):
    # The particle mass is rho0 / (lattice sum): the density summed over a lattice's interior
    # particle, by the facade's own neighbour pairs and the core's kernel, is rho0.
    spacing, density = 0.01, 1000.0
    hi = [0.1] * dim
    f = Fluid(lattice([0.0] * dim, hi, spacing), spacing, density=density)
    x = f.positions
    centre = int(np.argmin(np.linalg.norm(x - np.mean(x, axis=0), axis=1)))
    r = np.linalg.norm(x - x[centre], axis=1)
    rho = f.particle_mass() * np.sum(kernel_w(r / f.h, f.h, dim, f.kernel))
    assert rho == pytest.approx(density, rel=1e-12)
    assert f.particle_mass() == density / lattice_density_sum(spacing, f.h, dim, f.kernel)


def test_wall_volumes_come_from_the_core_by_akinci_lattice_or_given():
    x = lattice([0, 0], [0.1, 0.05], 0.01)
    # Akinci et al. 2012, eq. 4: V_b = 1/Σ_k W_bk. A one-layer wall of the lattice spacing has
    # fewer neighbours than a fluid particle inside the lattice, so a larger volume; in a thick
    # wall the outer layer's particles have fewer neighbours than the inner layer's.
    line = np.column_stack([np.linspace(-0.1, 0.2, 31), np.full(31, -0.005)])
    m = Fluid(x, 0.01).particle_mass()
    assert np.all(Fluid(x, 0.01, boundary=line, boundary_volume="akinci").boundary_psi() > 1.5 * m)
    w = tank_walls([0, 0], [0.2, 0.2], 0.01)
    akinci = Fluid(x, 0.01, boundary=w, boundary_volume="akinci").boundary_psi()
    assert m < akinci.min() < 1.05 * m and akinci.max() > 1.5 * m
    np.testing.assert_array_equal(Fluid(x, 0.01, boundary=w, boundary_volume="lattice").boundary_psi(),
                                  Fluid(x, 0.01).particle_mass())
    np.testing.assert_array_equal(Fluid(x, 0.01, boundary=w, boundary_volume=2e-5).boundary_psi(), 1000.0 * 2e-5)


def test_the_sound_speed_is_ten_times_the_free_fall_speed_over_the_fluids_height():
    s = pc.Scene(2, integrator="semi_implicit_euler", threads=1)
    s.add(pc.Gravity([0.0, -9.81]))
    x = lattice([0, 0], [0.2, 0.1], 0.01)
    f = s.add(Fluid(x, 0.01, method="wcsph"))
    height = np.ptp(x[:, 1]) + 0.01
    assert f.sound_speed == pytest.approx(10 * math.sqrt(2 * 9.81 * height), rel=1e-15)
    assert f.max_dt() == pytest.approx(0.25 * f.h / (f.sound_speed * (1 + 0.6 * f.alpha)), rel=1e-15)
    assert s.dt <= f.max_dt()
    with pytest.raises(pc.InvalidInputError, match="sound_speed"):
        pc.Scene(2, threads=1).add(Fluid(x, 0.01))  # at rest, no gravity: nothing to estimate from


def test_grid_limits_are_the_cores():
    w = pc.Wave((40, 30), 0.05, c=2.0)
    assert w.cfl_limit == pytest.approx(0.05 / (2.0 * math.sqrt(2)), rel=1e-15)
    gs = pc.GrayScott((32, 32), 0.01, du=2e-5, dv=1e-5, preset="mitosis")
    assert gs.diffusion_limit == pytest.approx(0.01**2 / (4 * 2e-5), rel=1e-15)
    assert _core.grid_limits("stable_fluid", 2, {"shape": np.array([8.0, 8.0]), "spacing": 0.1, "edges": "fixed,fixed,fixed,fixed"}) == {}


@pytest.mark.parametrize(("kind", "integrator", "arg"), [("contacts", "rk4", "integrator"), ("dfsph", "verlet", "method")])
def test_part_integrator_rules_are_one_table_in_the_core(kind, integrator, arg):
    with pytest.raises(pc.InvalidInputError, match=f"^{arg}: .*the scene uses '{integrator}'"):
        _core.check_integrator(kind, integrator)
    _core.check_integrator(kind, "semi_implicit_euler")
    _core.check_integrator("gravity", integrator)  # no rule: any integrator
    # The facade has no list of its own: no integrator name is written in the part modules' checks.
    for module in ("contacts.py", "fluids.py"):
        tree = ast.parse((PKG / module).read_text())
        compares = [n for n in ast.walk(tree) if isinstance(n, ast.Compare)
                    and any(isinstance(c, ast.Attribute) and c.attr == "integrator" for c in [n.left, *n.comparators])]
        assert not compares, f"{module} compares the integrator itself"


@pytest.mark.parametrize("dt", [0.0, -1.0, 1e-320, math.inf, math.nan])
def test_dt_has_one_rule_the_cores(dt):
    with pytest.raises(pc.InvalidInputError, match=r"^dt: must be > 0 and finite \(at least 2\.225e-308 s"):
        pc.Scene(2, dt=dt)
    s = pc.Scene(2, dt=1e-3, threads=1)
    with pytest.raises(pc.InvalidInputError, match=r"^dt: must be > 0 and finite \(at least 2\.225e-308 s"):
        s.dt = dt
    assert s.dt == 1e-3


def test_replace_continues_exactly_as_the_rebuilt_scene_does():
    a = pc.scenes.cloth(n=6, threads=1)
    a.step(20)
    springs = next(t for t in a.terms if isinstance(t, pc.Springs))
    stiffer = dataclasses.replace(springs, stiffness=np.asarray(springs.stiffness) * 1.5)
    gravity = next(t for t in a.terms if isinstance(t, pc.Gravity))

    def edit(meta, arrays):  # the viewer's former path: a scene file with the record changed
        k = next(k for k, t in enumerate(meta["terms"]) if t["name"] == springs.name)
        arrays[f"term{k}_stiffness"] = arrays[f"term{k}_stiffness"] * 1.5

    b = _rebuild(a, edit)
    stored = a.replace(springs.name, stiffer)
    assert stored.name == springs.name and [t.name for t in a.terms] == [t.name for t in b.terms]
    np.testing.assert_array_equal(a.terms[[t.name for t in a.terms].index(springs.name)].stiffness, stored.stiffness)
    assert a.terms[a.terms.index(gravity)] == gravity  # the others untouched
    a.step(40)
    b.step(40)
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.velocities, b.velocities)
    assert a.energy() == b.energy()


def test_replace_refuses_by_name_and_changes_nothing():
    s = pc.Scene(2, integrator="semi_implicit_euler", threads=1)
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(Fluid(lattice([0, 0], [0.05, 0.05], 0.01), 0.01, method="wcsph", name="water"))
    s.add(pc.Drag(0.1, name="air"))
    before = (s.terms, s.positions.copy(), s.dt)
    with pytest.raises(pc.InvalidInputError, match="^name: .*'wind'"):
        s.replace("wind", pc.Drag(0.2))
    with pytest.raises(pc.InvalidInputError, match="^item: 'air' is a Drag; a Gravity cannot replace it"):
        s.replace("air", pc.Gravity([0.0, 1.0]))
    with pytest.raises(pc.InvalidInputError, match="^item: 'water' is a Fluid"):
        s.replace("water", Fluid(lattice([0, 0], [0.05, 0.05], 0.01), 0.01, method="wcsph"))
    with pytest.raises(pc.InvalidTypeError, match="^item"):
        s.replace("air", 3.0)
    assert s.terms == before[0] and s.dt == before[2]
    np.testing.assert_array_equal(s.positions, before[1])
    assert s.replace("air", pc.Drag(0.3)).coefficient == 0.3 and s.terms[2].name == "air"
