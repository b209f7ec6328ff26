"""Grid scenes: waves (ripple, double_slit), reaction-diffusion (turing) and stable fluids
(smoke, cavity, vortex_street)."""
from __future__ import annotations

import math

import numpy as np

from .. import _check
from .._errors import InvalidInputError, InvalidTypeError
from ..scene import Scene
from ._common import _cells, _cfl_step, _count, _flag, _nonneg, _positive, _stamped


def ripple(
    n: int = 256,
    *,
    drops: int = 6,
    speed: float = 0.25,
    damping: float = 0.15,
    seed: int = 3,
    dt: float | None = None,
    threads: int | None = None,
    device: str = "cpu",
) -> Scene:
    """Ripples on a pond: stones dropped one after another into a 1 m square pond.

    The banks reflect (free faces); an n × n wave grid (:class:`~physcore.grids.Wave`).

    `drops` Gaussian dents (radius 1.2 cm, depth 4 mm) fall at random places (seeded) every 0.6 s
    from t = 0; the waves travel at `speed` (m/s) and fade at `damping` (1/s).
    ``device="gpu"`` (or ``"gpu:NAME"``) steps the grid on a GPU in float32 (see :class:`~physcore.Scene`).
    """
    from ..grids import Drop, Wave

    n = _count(n, "n", 16)
    _cells("n", n * n)
    drops = _check.int_in_range("drops", drops, 0, 1000)
    speed = _positive(speed, "speed")
    damping = _nonneg(damping, "damping")
    rng = np.random.default_rng(_check.int_in_range("seed", seed, 0, 2**63 - 1))
    stones = [Drop(0.6 * k, tuple(rng.uniform(0.2, 0.8, 2)), radius=0.012, amplitude=0.004) for k in range(drops)]
    scene = Scene(2, dt=1e-3 if dt is None else dt, threads=threads, device=device)
    pond = scene.add(Wave((n, n), 1.0 / n, c=speed, damping=damping, edges="free", drops=stones, name="pond"))
    if dt is None:
        scene.dt = _cfl_step(pond, "speed")
    return scene


# 25 fps: waves move everywhere, so each frame costs its whole picture; 4 s in 100 frames.
# From t = 0.12 s: the first stone (dropped at t = 0) already a ring in the first frame, which
# feeds and previews show (it was a blank pond).
ripple.render_defaults = {"frames": 100, "fps": 25, "frame_time": 1 / 25, "lead_in": 0.12, "substeps": "auto", "size": (400, 400)}
ripple = _stamped(ripple, old_order=('n', 'drops', 'speed', 'damping', 'seed', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))


def _start(value: object, top: float, unit: str) -> float:
    """`start=`: 0, or a normal float up to `top` (a subnormal one is no step that advance takes)."""
    start = _check.float_in_range("start", value, 0.0, top, unit=unit)
    if 0.0 < start < _check.MIN_NORMAL:
        raise InvalidInputError(f"start: must be 0 or at least {_check.MIN_NORMAL:.3g}, got {start:.3g}")
    return start


def double_slit(
    n: int = 256,
    *,
    wavelength: float = 0.05,
    separation: float = 0.2,
    width: float = 0.03,
    speed: float = 0.3,
    start: float = 0.0,
    dt: float | None = None,
    threads: int | None = None,
    device: str = "cpu",
) -> Scene:
    """Interference behind two slits: a plane wave passes a wall with two openings.

    The wave comes from an oscillating line on the left of a 1.5 m × 1 m tank and meets a wall
    with two slits (`width` m wide, centres `separation` m apart);
    the other faces absorb (damping layers), so the fringes are those of an open field. The
    grid is (1.5 n) × n; the source's frequency is speed / wavelength. With ``start`` > 0 the scene
    is returned already stepped `start` seconds (0 to 100) from rest (its clock reads `start`).
    The default, 0, returns the tank at rest, and its animation (``render_defaults["lead_in"]``)
    begins 0.6 / `speed` s later (2 s at the default speed): the plane wave's front, 0.23 m from
    the source line to the wall, passed the slits at 0.23 / `speed` s (0.77 s at 0.3 m/s) and
    has spread 0.37 m beyond them, so the first frame already shows the fringes behind the
    wall, not an empty tank. The lead-in is simulated by the renderer, under its progress bar
    and Ctrl-C, not here. Frames are `wavelength` / `speed` / 8 s apart (``frame_time``): the
    waves move an eighth of a wavelength a frame, smoothly rather than strobed, and the default
    96 frames span 12 of the source's periods, so the waves loop without a jump in phase.
    ``device="gpu"`` (or ``"gpu:NAME"``) steps the grid on a GPU in float32 (see :class:`~physcore.Scene`).
    """
    from ..grids import Oscillator, Wave

    n = _count(n, "n", 32)
    _cells("n", (3 * n * n) // 2)
    wavelength, separation, width = _positive(wavelength, "wavelength"), _positive(separation, "separation"), _positive(width, "width")
    speed = _positive(speed, "speed")
    if separation + width > 0.8:
        raise InvalidInputError(f"separation: {separation} m apart, {width} m wide: the slits must fit in the 1 m tank (separation + width <= 0.8)")
    if width > separation:
        raise InvalidInputError(f"width: {width} m is wider than the separation {separation} m: the slits would merge")
    nx, dx = (3 * n) // 2, 1.0 / n
    x = (np.arange(nx) + 0.5) * dx
    y = (np.arange(n) + 0.5) * dx
    wall = np.zeros((nx, n), dtype=bool)
    col = int(0.35 / dx)
    wall[col:col + 2, :] = True
    for yc in (0.5 - separation / 2, 0.5 + separation / 2):
        wall[col:col + 2, np.abs(y - yc) < width / 2] = False
    if wall[col].all():
        raise InvalidInputError(f"width, n: the slits ({width} m) are narrower than a cell (1/n = {dx:.3g} m); raise n or the width")
    line = np.zeros((nx, n), dtype=bool)
    line[np.argmin(np.abs(x - 0.12)), :] = True
    if not math.isfinite(40.0 * speed / wavelength):
        raise InvalidInputError(f"wavelength, speed: the source's frequency speed/wavelength = {speed / wavelength:g} Hz is beyond float64")
    source = Oscillator(amplitude=40.0 * speed / wavelength, frequency=speed / wavelength, region=line)
    scene = Scene(2, dt=1e-3 if dt is None else dt, threads=threads, device=device)
    layer = max(4, n // 10)
    tank = scene.add(Wave((nx, n), dx, c=speed, edges="fixed", absorbing=True, layer=layer, mask=wall, oscillators=[source], name="tank"))
    if dt is None:
        scene.dt = _cfl_step(tank, "speed")
    # Bounded: the wave has crossed the tank and settled into its fringes within 10 s.
    start = _start(start, 100.0, "s")
    if start > 0:  # the first frame shows the wave at the slits, not an empty tank
        step = scene.dt
        scene.advance(start)
        scene.dt = step  # advance leaves dt at its last substep: keep the scene's own step
    # Recorded from when the fringes have spread behind the slits (a scene returned at rest
    # only), an eighth of the source's period a frame.
    scene.render_defaults = {"lead_in": 0.6 / speed if start == 0 else 0.0, "frame_time": wavelength / speed / 8}
    return scene


# 24 fps, a frame an eighth of a period (0.05 m / 0.3 m/s / 8 = 1/48 s): 96 frames are 12 periods
# in 4 s. The lead-in, 2 s, starts the animation with the fringes already behind the slits.
double_slit.render_defaults = {
    "frames": 96, "fps": 24, "frame_time": 0.05 / 0.3 / 8, "lead_in": 2.0, "substeps": "auto", "size": (480, 320), "style": "signed",
}
double_slit = _stamped(double_slit, old_order=('n', 'wavelength', 'separation', 'width', 'speed', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))


def turing(
    preset: str = "maze",
    *,
    n: int = 256,
    duration: float = 4500.0,
    seeds: int = 2,
    seed: int = 1,
    start: float = 0.0,
    dt: float | None = None,
    threads: int | None = None,
    device: str = "cpu",
) -> Scene:
    """Turing patterns: Gray–Scott reaction–diffusion grows spots, stripes or mazes.

    :class:`~physcore.grids.GrayScott` from Pearson's start on his 2.5 × 2.5 periodic domain (n × n cells,
    D_u = 2e-5, D_v = 1e-5), with `seeds` perturbed squares (seeded) and the (F, k) of `preset`
    (:data:`physcore.grids.PRESETS`: spots, mitosis, stripes, maze, coral, holes, chaos).
    With ``start`` > 0 the scene is returned already stepped `start` time units (0 to 1e5) from the
    seeds (its clock reads `start`); the default, 0, returns Pearson's start itself. The
    animation ends `duration` time units after that: by default the maze grows until it fills
    the domain, at about t = 4500. From a scene returned at Pearson's start, the animation's first
    frame is drawn 22 % of `duration` in (``render_defaults["lead_in"]``: t = 1000 by default,
    a maze about a third of the domain across) rather than on the seeds' few small squares; the
    renderer simulates that lead-in under its progress bar and Ctrl-C. Steps are at most 1 time unit (the reaction's accuracy;
    Pearson's step) and within the diffusion limit, so coarse grids stay stable.
    ``device="gpu"`` (or ``"gpu:NAME"``) steps the grid on a GPU in float32 (see :class:`~physcore.Scene`).
    """
    from ..grids import PRESETS, GrayScott

    if not isinstance(preset, str):
        raise InvalidTypeError(f"preset: expected a name ({', '.join(PRESETS)}), got {type(preset).__name__}")
    if preset not in PRESETS:
        raise InvalidInputError(f"preset: unknown {preset!r}; valid: {', '.join(PRESETS)}")
    n = _count(n, "n", 16)
    _cells("n", n * n)
    duration = _positive(duration, "duration")
    scene = Scene(2, dt=1.0 if dt is None else dt, threads=threads, device=device)
    dx = 2.5 / n
    # The automatic step keeps a fraction of the diffusion limit dx²/(4 D_u), which grows as dx²:
    # on coarse grids (n <= 64: 76 time units at n = 32) it would step straight over the
    # reactions (rates ~1) and diverge; cap the step at 1, the reaction's accuracy.
    cfl = min(0.8, 1.0 / (dx * dx / (4 * 2e-5)))
    gs = scene.add(GrayScott((n, n), dx, preset=preset, cfl=cfl, name="turing"))
    if dt is None:
        scene.dt = gs.cfl * gs.diffusion_limit
    # Bounded: every time unit is a step or two of the whole grid (1e5: minutes at n = 256).
    start = _start(start, 1e5, "")
    gs.seed(_check.int_in_range("seed", seed, 0, 2**63 - 1), squares=_check.int_in_range("seeds", seeds, 1, 1000), size=0.06)
    if start > 0:  # the first frame shows a pattern, not the seeds' few small squares
        step = scene.dt
        scene.advance(start)
        scene.dt = step  # advance leaves dt at its last substep: keep the scene's own step
    # From Pearson's start, recorded from 22 % of the duration (t = 1000 of 4500: a maze a third of
    # the domain across) over 119 frame steps: the maze grows until the last frame fills the domain.
    lead = 1000.0 / 4500.0 * duration if start == 0 else 0.0
    scene.render_defaults = {"frame_time": (duration - lead) / 119, "lead_in": lead}
    return scene


turing.render_defaults = {"frames": 120, "fps": 30, "frame_time": 3500.0 / 119, "lead_in": 1000.0, "substeps": "auto", "size": (400, 400)}
turing = _stamped(turing, old_order=('preset', 'n', 'duration', 'seeds', 'seed', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))


def smoke(
    n: int = 128,
    *,
    buoyancy: float = 4.0,
    vorticity: float = 0.1,
    obstacle: bool = True,
    tracers: int = 0,
    dt: float | None = None,
    threads: int | None = None,
    device: str = "cpu",
) -> Scene:
    """Smoke: a hot plume rises from a vent and curls around a disc.

    The box is 1 m × 1.5 m (n × 1.5n cells, free-slip walls, viscosity ν = 3e-4 m²/s); the
    smoke is lifted by `buoyancy` (β, m/s² per unit temperature) and curled by vorticity
    confinement (ε = `vorticity`), around a disc of radius 0.09 m (`obstacle`), with `tracers`
    passive particles (:class:`~physcore.grids.StableFluid`; none by default: drawn as single
    pixels over the smoke they read as noise). The vent is a slot 3 cm deep, 3 cm above the
    floor and 16 cm across at x = 0.5 m, blowing smoke (density 1) at temperature 1 upwards at
    0.3 m/s over its middle 8 cm, fading to nothing by a smoothstep over 4 cm either side (in
    steps of 1/16, a source each), so the plume leaves it with soft sides rather than the
    staircase of a disc of cells. Its animation (``render_defaults``) begins after a lead-in
    of 2 s, when the plume has reached the disc and curls around it, and runs to t = 4.5 s.
    ``device="gpu"`` (or ``"gpu:NAME"``) steps the fluid on a GPU in float32 (see :class:`~physcore.Scene`).
    """
    from ..grids import StableFluid

    n = _count(n, "n", 16)
    _cells("n", (3 * n * n) // 2, arrays=40)
    buoyancy = _nonneg(buoyancy, "buoyancy")
    vorticity = _nonneg(vorticity, "vorticity")
    obstacle = _flag(obstacle, "obstacle")
    tracers = _check.int_in_range("tracers", tracers, 0, 1 << 20)
    ny, dx = (3 * n) // 2, 1.0 / n
    mask = None
    if obstacle:
        x = (np.arange(n) + 0.5) * dx
        y = (np.arange(ny) + 0.5) * dx
        mask = (x[:, None] - 0.45) ** 2 + (y[None, :] - 0.55) ** 2 < 0.09**2
    scene = Scene(2, dt=1e-2 if dt is None else dt, threads=threads, device=device)
    scene.add(
        StableFluid(
            (n, ny), dx, nu=3e-4, buoyancy=(0.0, buoyancy), vorticity=vorticity, obstacles=mask, sources=_vent(n, ny, dx),
            tracers=tracers, tolerance=1e-6, name="smoke",
        )
    )
    return scene


def _vent(n: int, ny: int, dx: float) -> list:
    """The smoke's soft slot vent: a slot 3 cm deep, 3 cm above the floor (the rows nearest
    that, at least one), centred on x = 0.5 m, whose strength w is 1 over its middle 8 cm and
    falls to 0 by a smoothstep over 4 cm either side (16 cm across in all); as sources of w's
    steps of 1/16 (density and temperature w, velocity w · 0.3 m/s up). Soft at the sides only:
    a source sets its cells every step, so a fringe above the slot would cap the plume with its
    own weak smoke; and raised, as the disc before it was, so that air flows in from below (on
    the floor the slot's smoke left in a few thin strands). The full-strength middle comes
    first (tracers start in the first source); a step that covers no cell of a coarse grid is
    left out (the middle always covers the cells either side of x = 0.5 m)."""
    from ..grids import Source

    x = (np.arange(n) + 0.5) * dx
    s = np.clip((np.abs(x - 0.5) - 0.04) / 0.04, 0.0, 1.0)
    level = np.round(16 * (1.0 - s * s * (3.0 - 2.0 * s))).astype(int)  # 16: the middle
    j0 = int(round(0.03 / dx))
    slot = np.zeros((n, ny), dtype=int)
    slot[:, j0 : max(j0 + 1, int(round(0.06 / dx)))] = level[:, None]
    return [
        Source(density=k / 16, temperature=k / 16, velocity=(0.0, 0.3 * k / 16), region=slot == k)
        for k in range(16, 0, -1)
        if (slot == k).any()
    ]


# From t = 2 s, when the plume has reached the disc and curls around it (from rest, the first
# frames were a lone puff rising through an empty box), to t = 4.5 s in 4 s of playback: later
# the smoke fills the box with a murk of one colour (and 120 frames to t = 5 s made 3.7 MB).
smoke.render_defaults = {"frames": 100, "fps": 25, "frame_time": 0.025, "lead_in": 2.0, "substeps": "auto", "size": (320, 480)}
smoke = _stamped(smoke, old_order=('n', 'buoyancy', 'vorticity', 'obstacle', 'tracers', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))


def cavity(
    n: int = 64,
    *,
    reynolds: float = 100.0,
    tracers: int = 0,
    dye: int = 6,
    dt: float | None = None,
    threads: int | None = None,
    device: str = "cpu",
) -> Scene:
    """The lid-driven cavity: a box of fluid stirred by its sliding top wall.

    A unit square whose top wall slides at 1 m/s (no-slip walls), at Reynolds number
    `reynolds` = U L / ν (:class:`~physcore.grids.StableFluid`). At
    Re = 100 the steady centreline profile is Ghia, Ghia & Shin (1982), Table I. The fluid starts
    at rest with `dye` horizontal bands of dye (its ``density``, 0 or 1; 0: none), which the
    vortex winds into a spiral as it spins up; drawn as that dye. `tracers` passive particles
    (spread over the box) can show the circulation too.
    ``device="gpu"`` (or ``"gpu:NAME"``) steps the fluid on a GPU in float32 (see :class:`~physcore.Scene`).
    """
    from ..grids import StableFluid

    n = _count(n, "n", 8)
    _cells("n", n * n, arrays=40)
    reynolds = _positive(reynolds, "reynolds")
    if not math.isfinite(1.0 / reynolds):
        raise InvalidInputError(f"reynolds: {reynolds:g} makes the viscosity 1/Re overflow float64")
    tracers = _check.int_in_range("tracers", tracers, 0, 1 << 20)
    dye = _check.int_in_range("dye", dye, 0, n)
    scene = Scene(2, dt=1e-2 if dt is None else dt, threads=threads, device=device)
    box = scene.add(
        StableFluid(
            (n, n), 1.0 / n, nu=1.0 / reynolds, walls="no_slip", lid=1.0, advection="maccormack",
            tracers=tracers, tolerance=1e-8, name="cavity",
        )
    )
    if dye:
        y = (np.arange(n) + 0.5) / n
        band = np.floor(y * (2 * dye)) % 2 == 1  # 2·dye equal layers, every other one dyed
        box.density = np.broadcast_to(band.astype(np.float64)[None, :], (n, n)).copy()
    return scene


# 12 s of the spin-up from rest in 3.6 s: the dye winds into the vortex to the last frame.
# Dithered: the dye's soft edges and the mixed middle are slow gradients, which the map's 24
# shades drew as flat bands with visible steps.
cavity.render_defaults = {
    "frames": 90, "fps": 25, "frame_time": 0.135, "substeps": "auto", "size": (400, 400), "field": "density", "style": "turing",
    "dither": True,
}
cavity = _stamped(cavity, old_order=('n', 'reynolds', 'tracers', 'dye', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))


def vortex_street(
    n: int = 10,
    *,
    reynolds: float = 120.0,
    length: float = 22.0,
    height: float = 10.0,
    dt: float | None = None,
    threads: int | None = None,
    device: str = "cpu",
) -> Scene:
    """A von Kármán vortex street: water flowing past a cylinder sheds vortices, drawn by dye.

    A channel `length` × `height` cylinder diameters (D = 1 cm) with a uniform inflow U = 1 cm/s
    on the left and an open outflow on the right (``StableFluid(inflow=U)``: pressure 0, zero
    normal gradient), free-slip top and bottom walls, and a no-slip cylinder (a disc of solid
    cells, `n` cells across) 5 D downstream of the inlet on the centre line. The viscosity is
    ν = U D / `reynolds` (m²/s; Re = 100 is water's 1e-6 m²/s), so times are in units of
    D/U = 1 s. Streaks of dye (the fluid's ``density``, 0 or 1, in bands D/4 wide)
    enter through the inlet within 2.5 D of the centre line and start laid through the whole
    channel; a small asymmetric puff of transverse velocity behind the cylinder at t = 0
    (v ≤ U/2, a Gaussian of width D/2, 1.5 D downstream) starts the shedding within a few
    periods instead of waiting for round-off.

    Above Re ≈ 47 the wake sheds vortices alternately from either side at the Strouhal number
    St = f D / U, which Roshko (1954, NACA Report 1191) measured as
    St = 0.212 (1 − 21.2 / Re) for 50 < Re < 150 (reviewed by Williamson 1996, Annu. Rev.
    Fluid Mech. 28, 477). The walls confine the flow: the blockage D/H = 1 / `height`
    (0.1 by default) raises St slightly above the unbounded value; tests/grids/test_vortex_street.py
    measures St against Roshko's curve at the default blockage and at 1/16.

    Parameters
    ----------
    n : int
        Cells per cylinder diameter (≥ 4; the channel is round(length·n) × round(height·n)).
    reynolds : float
        Re = U D / ν (> 0; the street forms for 47 ≲ Re ≲ 190, where the 2D flow is laminar).
    length, height : float
        The channel in diameters (length ≥ 8, height ≥ 3).
    device : str
        ``"gpu"`` (or ``"gpu:NAME"``) steps the fluid on a GPU in float32 (see :class:`~physcore.Scene`).

    Raises
    ------
    TypeError, InvalidInputError
        Naming the argument (a non-integer `n`, a non-positive `reynolds`, a channel too short
        or too low for the cylinder, or a grid too large for memory).
    """
    from ..grids import Source, StableFluid

    # A grid has at most 2**20 cells a side: a larger n is refused here, by name, before
    # length · n overflows float64 (n = 10**400 raised OverflowError).
    n = _check.int_in_range("n", n, 4, 1 << 20)
    reynolds = _positive(reynolds, "reynolds")
    length, height = _positive(length, "length"), _positive(height, "height")
    if length < 8.0:
        raise InvalidInputError(f"length: the channel must be at least 8 diameters long (5 D of inlet), got {length:g}")
    if height < 3.0:
        raise InvalidInputError(f"height: the channel must be at least 3 diameters high, got {height:g}")
    # Checked in float before any int(): length · n beyond float64 is refused by name (found by
    # the scene fuzz: 1.8e307 diameters overflowed the conversion).
    _cells("n, length, height", length * n * height * n, arrays=40)
    nx, ny = int(round(length * n)), int(round(height * n))
    D, U = 0.01, 0.01
    dx = D / n
    nu = U * D / reynolds
    if not (math.isfinite(nu) and nu > 0):
        raise InvalidInputError(f"reynolds: {reynolds:g} gives no finite viscosity U·D/Re > 0")
    xc, yc = 5.0 * D, 0.5 * ny * dx
    x = (np.arange(nx) + 0.5) * dx
    y = (np.arange(ny) + 0.5) * dx
    cylinder = (x[:, None] - xc) ** 2 + (y[None, :] - yc) ** 2 < (0.5 * D) ** 2
    # Streaks: bands D/4 wide, every other one dyed, within 2.5 D of the centre line.
    yy = y - yc
    streak = (np.abs(yy) < 2.5 * D) & (np.floor(yy / (0.25 * D)) % 2 == 0)
    inlet = np.zeros((nx, ny), bool)
    inlet[0] = True
    dyed, clear = inlet & streak[None, :], inlet & ~streak[None, :]
    sources = [Source(density=1.0, velocity=(U, 0.0), region=dyed), Source(density=0.0, velocity=(U, 0.0), region=clear)]
    scene = Scene(2, dt=0.5 * dx / U if dt is None else dt, threads=threads, device=device)
    fluid = scene.add(
        StableFluid(
            (nx, ny), dx, nu=nu, advection="maccormack", inflow=U, obstacles=cylinder, sources=sources,
            tolerance=1e-6, name="channel",
        )
    )
    X, Y = np.meshgrid(x, np.arange(ny + 1) * dx, indexing="ij")
    kick = 0.5 * U * np.exp(-((X - xc - 1.5 * D) ** 2 + (Y - yc) ** 2) / (2 * (0.5 * D) ** 2))
    fluid.set_velocity(np.full((nx + 1, ny), U), kick)
    fluid.density = np.broadcast_to(streak[None, :].astype(np.float64), (nx, ny)) * ~cylinder
    return scene


vortex_street.render_defaults = {
    "frames": 100, "fps": 25, "frame_time": 0.6, "substeps": "auto", "size": (528, 240), "field": "density", "style": "smoke",
}
vortex_street = _stamped(vortex_street, old_order=('n', 'reynolds', 'length', 'height', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))
