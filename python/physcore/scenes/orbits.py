"""Scenes of bodies in flight and in orbit: projectiles, Kepler orbits, the figure-eight and
Pythagorean three-body problems, colliding galaxies."""
from __future__ import annotations

import math

import numpy as np

from .. import _check
from .._errors import InvalidInputError
from .._system import gpu_adapters
from ..scene import Scene, _best_gpu, _quiet_options
from ..terms import Drag, Gravity, PairwiseGravity, Plane, TreeGravity
from ._common import _count, _finite_books, _flag, _nonneg, _particle_mass, _particles, _positive, _stamped


def projectile(
    n: int = 7,
    *,
    speed: float = 20.0,
    drag: float = 0.0,
    restitution: float = 0.6,
    ground: bool = True,
    integrator: str = "verlet",
    dt: float | None = 1e-3,
    threads: int | None = None,
) -> Scene:
    """Projectiles: n balls (1 kg) launched from the origin at angles from 20° to 70°, bouncing.

    2D, gravity (0, -9.81) m/s², optional linear drag (kg/s), a ground plane y = 0 with the given
    restitution and friction 0.2. Without drag and ground the closed form is
    x = v0 cos θ t, y = v0 sin θ t - g t²/2. The render gives each ball its own colour (the
    "tab10" group colours, by launch angle from the lowest).

    Raises TypeError / InvalidInputError naming the argument (see the module docstring), e.g.
    for a speed whose kinetic energy overflows float64.
    """
    n = _count(n, "n", 1)
    _particles("n", n)
    speed = _positive(speed, "speed")
    drag = _nonneg(drag, "drag")
    restitution = _check.float_in_range("restitution", restitution, 0.0, 1.0)
    ground = _flag(ground, "ground")
    if not math.isfinite(0.5 * speed * speed * n):
        raise InvalidInputError(f"speed: the kinetic energy n · ½ (1 kg) speed² of {speed:.3g} m/s overflows float64")
    angles = np.radians(np.linspace(20.0, 70.0, n)) if n > 1 else np.radians([45.0])
    v = speed * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    scene = Scene(2, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    scene.add_particles(np.zeros((n, 2)), v, masses=1.0)
    scene.add(Gravity([0.0, -9.81]))
    if drag:
        scene.add(Drag(drag))
    if ground:
        scene.add(Plane([0.0, 0.0], [0.0, 1.0], restitution=restitution, friction=0.2))
    scene.render_defaults = {"colors": list(range(n))}  # one colour per ball: the angles read apart
    return _finite_books(scene, "speed")


# 4 s: the flights (up to 3.9 s at 70°) and the first bounces; the whole paths stay drawn. Wide:
# the 45° range (40.8 m) is 2.2 times the 70° apex (18.0 m).
projectile.render_defaults = {"antialias": True, "frames": 120, "fps": 30, "frame_time": 1 / 30, "size": (560, 300), "trail": 120,
                              "radius": 8, "color_by": "none"}
projectile = _stamped(projectile, old_order=('n', 'speed', 'drag', 'restitution', 'ground', 'integrator', 'dt', 'threads'), keep=1)


#: Range of a Kepler orbit's separations a(1 ∓ e), m: keeps r², 1/r³ and v² = GM/r inside float64.
KEPLER_RANGE = (1e-100, 1e100)

#: ``kepler``: colours of the star (warm yellow-white) and the planet (blue), RGB.
KEPLER_COLORS = ((255, 214, 120), (100, 175, 255))


def kepler(
    e: float = 0.5,
    *,
    a: float = 1.0,
    mass_ratio: float = 1e-3,
    steps_per_orbit: int = 1200,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Kepler orbit: two bodies under Newtonian gravity (G = 1, total mass 1), eccentricity e.

    The relative orbit has semi-major axis a and starts at pericentre r = a(1 - e) with speed
    sqrt(G M (1 + e) / (a (1 - e))); bodies are placed in the centre-of-mass frame. Period
    P = 2π sqrt(a³ / (G M)); total energy -G m1 m2 / (2a). ``mass_ratio = 0`` pins a unit-mass
    star at the origin and makes the planet (mass 1) a test particle: then E = -1/(2a) exactly.
    ``dt=None`` uses P / steps_per_orbit (the default 1200: the render's frames, 60 an orbit,
    fall on whole steps, so its two orbits close and the GIF loops without a seam). Particle 0
    is the star, 1 the planet; the render draws them in their own colours
    (:data:`KEPLER_COLORS`: warm yellow, blue).

    Raises TypeError / InvalidInputError naming the argument (see the module docstring); the
    separations a(1 - e) and a(1 + e) must lie in :data:`KEPLER_RANGE` (1e-100 to 1e100 m) so
    that r², 1/r³ and v² stay inside float64, and both masses must be usable (mass_ratio 0 or
    in about [2.2e-308, 4.5e307]).
    """
    e = _check.float_in_range("e", e, 0.0, 1.0, hi_open=True)
    a = _positive(a, "a")
    lo, hi = KEPLER_RANGE
    if not (a * (1 - e) >= lo and a * (1 + e) <= hi):
        raise InvalidInputError(
            f"a: the separations a(1 - e) = {a * (1 - e):.3g} m to a(1 + e) = {a * (1 + e):.3g} m must lie in "
            f"[{lo:g}, {hi:g}] m (so that r², 1/r³ and v² stay inside float64); check a and e"
        )
    q = _nonneg(mass_ratio, "mass_ratio")
    if q > 0:
        _particle_mass(min(1 / (1 + q), q / (1 + q)), "mass_ratio")
    steps_per_orbit = _count(steps_per_orbit, "steps_per_orbit", 1)
    period = 2 * math.pi * math.sqrt(a**3)
    # Ints beyond 2**1000 would overflow the conversion to float; any such step is 0 anyway.
    step = period / steps_per_orbit if steps_per_orbit <= 2**1000 else 0.0
    if dt is None and not step >= _check.MIN_NORMAL:
        raise InvalidInputError(
            f"steps_per_orbit: the step P / steps_per_orbit = {step:.3g} s is below float64's normal range (P = {period:.3g} s)"
        )
    rp = a * (1 - e)
    vp = math.sqrt((1 + e) / (a * (1 - e)))
    scene = Scene(2, integrator=integrator, dt=step if dt is None else dt, threads=threads)
    if q == 0:
        scene.add_particles([[0.0, 0.0], [rp, 0.0]], [[0.0, 0.0], [0.0, vp]], masses=[1.0, 1.0], pinned=[True, False])
    else:
        m1, m2 = 1 / (1 + q), q / (1 + q)
        x = np.array([[-m2 * rp, 0.0], [m1 * rp, 0.0]])
        v = np.array([[0.0, -m2 * vp], [0.0, m1 * vp]])
        scene.add_particles(x, v, masses=[m1, m2])
    scene.add(PairwiseGravity(G=1.0))
    # Plain lists: render_defaults compare with ==. The star (particle 0) glows.
    # Two whole orbits of this a in the render's 120 frames.
    scene.render_defaults = {"colors": list(KEPLER_COLORS), "halo": [0], "frame_time": 2 * period / 120}
    return scene


kepler.render_defaults = {"antialias": True,
    # The sun's glow under the translucent swept areas is a smooth gradient: ordered dither, not
    # rings of the GIF's 255 colours.
    "dither": True,
    "frames": 120,
    "fps": 30,
    "frame_time": 4 * math.pi / 120,
    "size": (380, 320),  # the e = 0.5 ellipse is 2a wide and 1.73a high
    "speed_unit": "(G=1)",  # G = 1, total mass 1, a = 1: no SI unit applies
    # A sixth of an orbit, fading: the trail's length is the planet's speed, long at perihelion.
    "trail": 10,
    "size_by": "mass",  # the star (3× the planet's 9 px) larger than the planet
    "radius": 9,
    # Bodies as objects (a sun, a planet: KEPLER_COLORS), not a speed map that turns the star at
    # rest into the map's darkest end; the night sky.
    "color_by": "none", "theme": "dark", "loop": True,  # two whole orbits: the GIF loops seamlessly
    "title": "equal areas in equal times",
    # Kepler's second law: the radius vector sweeps a wedge a sixth of a period long (10
    # frames) in alternating colours, the last orbit's six tiling the ellipse; equal areas
    # (tests/render/test_look.py measures them), fat at perihelion, thin at aphelion.
    "look": {"swept_areas": {"centre": 0, "body": 1, "frames": 10, "count": 6}, "trail_fade": 0.0, "trail_width": 3},
}
kepler = _stamped(kepler, old_order=('e', 'a', 'mass_ratio', 'steps_per_orbit', 'integrator', 'dt', 'threads'), keep=1)


#: Figure-eight choreography of three equal masses (G = m = 1): Chenciner & Montgomery, Ann.
#: Math. 152 (2000) 881; initial conditions and period from Simó (2002), as tabulated by
#: Chenciner & Montgomery's Fig. 1 caption: x₁ = −x₂, x₃ = 0, v₁ = v₂ = −v₃/2.
FIGURE_EIGHT_X1 = (0.97000436, -0.24308753)
FIGURE_EIGHT_V3 = (-0.93240737, -0.86473146)
FIGURE_EIGHT_PERIOD = 6.32591398


def figure_eight(
    *,
    steps_per_period: int = 2100,
    integrator: str = "yoshida4",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Three equal masses chasing each other around one figure-eight curve.

    G = m = 1: the choreography found by Moore (1993) and proved by Chenciner & Montgomery (2000), with
    Simó's initial conditions (:data:`FIGURE_EIGHT_X1`, :data:`FIGURE_EIGHT_V3`). Period
    T = 6.32591398; each body follows the one ahead by T/3. Total momentum 0, energy −1.287.
    ``dt=None`` uses T / steps_per_period, with Yoshida's fourth-order integrator (the default
    2100: 14 steps a frame of the render's 150, so its one period closes and the GIF loops
    without a seam).
    """
    steps_per_period = _count(steps_per_period, "steps_per_period", 1)
    step = FIGURE_EIGHT_PERIOD / steps_per_period if steps_per_period <= 2**1000 else 0.0
    if dt is None and not step >= _check.MIN_NORMAL:
        raise InvalidInputError(f"steps_per_period: the step T / steps_per_period = {step:.3g} is below float64's normal range")
    x1, v3 = np.array(FIGURE_EIGHT_X1), np.array(FIGURE_EIGHT_V3)
    scene = Scene(2, integrator=integrator, dt=step if dt is None else dt, threads=threads)
    scene.add_particles(np.stack([x1, -x1, np.zeros(2)]), np.stack([-v3 / 2, -v3 / 2, v3]), masses=1.0)
    scene.add(PairwiseGravity(G=1.0))
    scene.render_defaults = {"colors": [0, 1, 3]}  # tab10 blue, orange, red: three bodies, three hues
    return scene


# One period; the curve is 2.2 wide and 0.7 high, hence the wide frame.
figure_eight.render_defaults = {"antialias": True,
    "frames": 150, "fps": 30, "frame_time": FIGURE_EIGHT_PERIOD / 150, "size": (560, 300), "radius": 10,
    "speed_unit": "(G=1)", "trail": 50, "theme": "dark",  # each trail a third of the curve: the three close it
    "color_by": "none",  # equal speeds at equal phases: the bodies as objects, each its own colour
    "loop": True,  # one whole period: the trails run on across the GIF's loop
}
figure_eight = _stamped(figure_eight, old_order=('steps_per_period', 'integrator', 'dt', 'threads'), keep=0)


#: ``pythagorean``: colours of the masses 3, 4 and 5 (coral red, sky blue, gold), RGB.
PYTHAGOREAN_COLORS = ((255, 96, 96), (86, 168, 255), (255, 204, 72))

def pythagorean(
    *,
    rtol: float = 1e-10,
    integrator: str = "dopri5",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Burrau's three-body problem: masses 3, 4 and 5 released at rest, until one is thrown out.

    The masses start at the corners of a 3-4-5 right triangle (Burrau 1913), each opposite the side of its length (G = 1), at (1, 3), (−2, −1) and (1, −1).
    After a long dance of close encounters the lightest body is thrown out near t = 60 and the
    other two leave as a binary (Szebehely & Peters, Astron. J. 72 (1967) 876). The encounters
    are far closer than the start, so the adaptive ``"dopri5"`` (tolerance `rtol`) is the
    default; ``dt`` (default 0.1) is then the output interval.
    """
    rtol = _check.float_in_range("rtol", rtol, 1e-14, 1.0, hi_open=True)
    with _quiet_options():  # the scene's option is kept whatever the integrator
        scene = Scene(2, integrator=integrator, dt=0.1 if dt is None else dt, threads=threads, rtol=rtol, atol=rtol * 1e-3)
    x = np.array([[1.0, 3.0], [-2.0, -1.0], [1.0, -1.0]])
    scene.add_particles(x, np.zeros((3, 2)), masses=[3.0, 4.0, 5.0])
    scene.add(PairwiseGravity(G=1.0))
    scene.render_defaults = {"colors": [list(c) for c in PYTHAGOREAN_COLORS]}  # masses 3, 4, 5: red, blue, gold
    return scene


pythagorean.render_defaults = {"antialias": True,
    # To t = 62.4: the dance, then the ejection. The last close encounter (t ≈ 59) flings the
    # lightest body out of the top of the frame (by t ≈ 60.3, at 4.3 a time unit), and the 4-5
    # binary, recoiling at a third of that speed, reaches the bottom edge at the end. The camera
    # holds the dance (`extent`: every position to t = 58.5 lies within |x| ≤ 3.2,
    # -4.5 ≤ y ≤ 3.0), one scale throughout. Frames 0.2 apart (two output intervals of dopri5's
    # default dt) keep the close encounters smooth; trails of 8 time units fading to nothing,
    # so the current loops read over the older ones, each frame step drawn as 8 pieces of the
    # Hermite curve of the positions and velocities (a close pass turns through a right angle
    # or more between two frames: straight steps drew it as a corner).
    "frames": 313, "fps": 50, "frame_time": 0.2, "size": (400, 460), "speed_unit": "(G=1)", "trail": 40, "size_by": "mass",
    "radius": 8, "theme": "dark", "color_by": "none", "extent": [[-3.3, -4.7], [3.4, 3.2]],
    "title": "Burrau's problem: masses 3, 4, 5",
    "look": {"trail_fade": 0.0, "trail_width": 3, "trail_samples": 8},
}
pythagorean = _stamped(pythagorean, old_order=('rtol', 'integrator', 'dt', 'threads'), keep=0)


def _gpu_kind(device: object) -> str | None:
    """The kind ("discrete", "integrated", "virtual", "cpu", ...) of the adapter ``device``
    ("gpu" or "gpu:NAME") names, by the rule a scene picks its adapter with (docs/guide/gpu.md,
    "Choosing a device": "gpu" the best non-CPU one); None for anything else (the CPU, "auto", a
    bad value: the scene reports it) or where nothing matches."""
    if not isinstance(device, str) or not device.startswith("gpu"):
        return None
    adapters = gpu_adapters()
    if device == "gpu":
        best = _best_gpu(adapters)
        return None if best is None else str(best["kind"])
    name = device[4:].lower()
    name = "llvmpipe" if name == "lavapipe" else name  # lavapipe calls itself llvmpipe
    for a in adapters:
        if any(name in str(a[k]).lower() for k in ("name", "backend", "kind")):
            return str(a["kind"])
    return None


#: ``galaxies``: colours of the two galaxies' stars (pale blue, warm gold), RGB.
GALAXY_COLORS = ((150, 190, 255), (255, 196, 110))


def galaxies(
    n: int | None = None,
    *,
    pericentre: float = 1.6,
    prograde: bool = True,
    theta: float = 0.6,
    softening: float = 0.05,
    seed: int = 3,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
    device: str = "cpu",
) -> Scene:
    """Two disk galaxies pass on a parabolic orbit and throw out tidal tails and a bridge.

    The set-up of Toomre & Toomre, Astrophys. J. 178 (1972) 623: each galaxy is a central mass
    with a cold disk of stars on circular orbits around it, and the two centres fall towards
    each other on a parabola. G = 1. Each galaxy: a central body of mass 1 (one particle, the
    bulge and halo in one) and a disk of (n − 2)/2 stars of total mass 0.05 (near test
    particles, as Toomre's), spread with uniform surface density between radii 0.15 and 1
    (r = √U(0.15², 1)) at random azimuths, each on the circular orbit of the softened central
    mass plus the disk mass inside its radius taken as spherical,
    v_c² = G M_c r² / (r² + ε²)^{3/2} + G M_d(< r) / r (→ G M(< r)/r for r ≫ ε; the thin
    disk's own field departs from the spherical one by about M_d/M_c).

    The orbit of the centres is the Kepler parabola (eccentricity 1) r = 2q / (1 + cos f) of
    pericentre q = `pericentre` in the xy-plane about the total mass μ = 2 × 1.05 (radial and
    tangential speeds √(μ/2q) sin f and √(μ/2q)(1 + cos f), so the relative speed is the escape
    speed √(2μ/r) and the orbital energy 0), started at separation 4.5 (f ≈ −107° for q = 1.6);
    by Barker's equation (Kepler's equation for e = 1) the pericentre comes at
    t = √(2q³/μ)(τ + τ³/3), ``τ = tan(|f|/2)``: 4.27 for q = 1.6. The disks are tilted 15° and 45°
    about the x-axis from the orbital plane; with `prograde` both spin the way the orbit turns,
    which, Toomre & Toomre found, makes the long tails; ``prograde=False`` (both retrograde)
    leaves the disks nearly undisturbed. Everything is placed in the centre-of-mass frame.

    Forces by Barnes–Hut (:class:`~physcore.TreeGravity`, opening angle `theta`, Plummer
    `softening` ε). ``dt=None`` takes 0.0125: 32 steps per orbit at the inner edge of the disks
    (angular speed √(G M_c / (r² + ε²)^{3/2}) there). The total energy wanders over the render
    by up to 1e-3 of the initial kinetic energy K₀ (the largest deviation from E₀ of 16
    readings, n = 10 000: 9.9e-4 by the tree, 9.2e-4 by the direct sum). The direct sum's part
    is the step's, from the few stars that plunge through the other galaxy's centre
    (accelerations up to 0.385 G M_c/ε² ≈ 150): dt = 0.00625 takes it to 3.0e-5 (0.025 gives
    2.5e-2). The tree's is its own approximation (forces not exactly conservative, potential
    summed over the same lists): halving dt leaves it at 2.2e-3. (Before 2026-11-28 this said
    1e-5, read at the render's last frame alone.)

    ``device="gpu"`` (or ``"gpu:NAME"``) steps the stars on a GPU in float32 (see
    :class:`~physcore.Scene`) with the direct sum (:class:`~physcore.PairwiseGravity`, the same
    softening; `theta` is unused: the GPU path has no tree), N² pairs a step. ``n=None`` takes
    10,000 stars on the CPU and 100,000 on a discrete GPU (an integrated one, whose direct sum
    may be 100 times slower, and a CPU implementation such as lavapipe keep 10,000). Measured on
    an NVIDIA H200: the render's 952 steps at 10⁵ stars take 6.9 s (1.5e12 pairs/s) and the
    whole GIF 18–21 s (two runs), against 10 s for the CPU's 10⁴ by Barnes–Hut on its host's 16
    threads; 10⁶ stars would take 0.71 s a step, 11 minutes for the render (docs/guide/gpu.md).
    The render colours each galaxy's stars by origin (:data:`GALAXY_COLORS`:
    first blue, then gold). Particle order: centre A, its stars, centre B, its stars.
    :func:`plummer_sphere` samples a spherical cluster instead.
    """
    if n is None:
        n = 100_000 if _gpu_kind(device) == "discrete" else 10_000
    n = _count(n, "n", 4)
    q = _positive(pericentre, "pericentre")
    prograde = _flag(prograde, "prograde")
    theta = _nonneg(theta, "theta")
    # Beyond the disks' size (1) a softening only blurs the galaxies into each other; the bound
    # also keeps (r² + ε²)^{3/2} inside float64.
    softening = _check.float_in_range("softening", softening, 0.0, 10.0, lo_open=True)
    seed = _count(seed, "seed", 0)
    _particles("n", n)
    if not 1e-3 <= q < 2.25:  # the start at separation 4.5 must come before the pericentre
        raise InvalidInputError(f"pericentre: must be in [0.001, 2.25) (half the starting separation 4.5), got {q:.3g}")
    rng = np.random.default_rng(seed)
    m_centre, m_disk, r_in, r_out, sep = 1.0, 0.05, 0.15, 1.0, 4.5
    mu = 2.0 * (m_centre + m_disk)
    f = -math.acos(2.0 * q / sep - 1.0)  # true anomaly at the start: r = 2q / (1 + cos f)
    k = math.sqrt(mu / (2.0 * q))
    rhat = np.array([math.cos(f), math.sin(f), 0.0])
    rel = sep * rhat
    vrel = k * math.sin(f) * rhat + k * (1.0 + math.cos(f)) * np.array([-rhat[1], rhat[0], 0.0])
    spin = 1.0 if prograde else -1.0  # the orbit turns counter-clockwise (about +z)
    half = (n - 2) // 2
    xs, vs, ms = [], [], []
    for stars, side, tilt in ((half, -0.5, 15.0), (n - 2 - half, 0.5, 45.0)):
        r = np.sqrt(rng.uniform(r_in**2, r_out**2, stars))
        phi = rng.uniform(0.0, 2.0 * np.pi, stars)
        inside = m_disk * (np.argsort(np.argsort(r)) + 1) / stars  # M_d(≤ r)
        vc = spin * np.sqrt(m_centre * r * r / (r * r + softening**2) ** 1.5 + inside / r)
        c, s = math.cos(math.radians(tilt)), math.sin(math.radians(tilt))
        # Tilted about x: (x, y, 0) -> (x, c y, s y). Written out, not as a matrix product: BLAS
        # gave up with "OpenBLAS error: Memory allocation still failed" and exited the process
        # under a memory limit (n = 10^7), where numpy raises MemoryError (the same numbers).
        y = r * np.sin(phi)
        p = np.stack([r * np.cos(phi), c * y, s * y], axis=1)
        y = vc * np.cos(phi)
        u = np.stack([-vc * np.sin(phi), c * y, s * y], axis=1)
        xs += [np.zeros((1, 3)), p]
        vs += [np.zeros((1, 3)), u]
        ms += [[m_centre], np.full(stars, m_disk / stars)]
        xs[-2:] = [a + side * rel for a in xs[-2:]]
        vs[-2:] = [a + side * vrel for a in vs[-2:]]
    x, v, m = np.concatenate(xs), np.concatenate(vs), np.concatenate(ms)
    x -= m @ x / m.sum()  # the random disks' own small centre-of-mass offsets and momenta
    v -= m @ v / m.sum()
    scene = Scene(3, integrator=integrator, dt=0.0125 if dt is None else dt, threads=threads, device=device)
    scene.add_particles(x, v, masses=m)
    if scene.device.startswith("gpu"):
        scene.add(PairwiseGravity(G=1.0, softening=softening))
    else:
        scene.add(TreeGravity(G=1.0, softening=softening, theta=theta))
    # The central masses shine as bulges: the glow of the stars alone left a dark hole inside
    # the disks' inner edge (r = 0.15).
    scene.render_defaults = {"colors": [GALAXY_COLORS[0]] * (half + 1) + [GALAXY_COLORS[1]] * (n - 1 - half),
                             "halo": [0, half + 1]}
    return scene


# 120 frames of 8 steps (t = 0 to 11.9) played in 5 s: the approach, the pericentre at t ≈ 4.3,
# and the tails and bridge growing for about one orbit of the disks' edges (2π) after it. The view looks down
# on the orbital plane at 70°, with the separating pair across the frame; the camera frames 95 %
# of the stars (the centre of mass stays put), so a few stars flung far do not shrink the
# picture. One scale for the whole run would be set by the tails at the end, leaving the two
# disks of the first frame (the thumbnail) a sixth of the width and blurred: "zoom" starts on
# the disks (2.5 times closer) and widens, eased, as the tails grow, to that scale at the end;
# the scale bar shows each frame's scale.
galaxies.render_defaults = {
    "frames": 120, "fps": 24, "frame_time": 0.1, "size": (480, 400), "view": (30.0, 70.0), "radius": 0,
    "speed_unit": "(G=1)", "theme": "dark", "color_by": "density",  # glow: stars accumulate like an exposure
    "camera": "zoom",
}
galaxies = _stamped(galaxies, old_order=('n', 'pericentre', 'prograde', 'theta', 'softening', 'seed', 'integrator', 'dt', 'threads'), keep=1)
