"""Rigid bodies (rapier, :mod:`physcore.bodies`): a row of dominoes (dominoes), a wrecking
ball on a chain demolishing a pyramid of crates (pyramid), boxes tumbling down a zig-zag of
ramps (tumbling_boxes) and, in 3D, a tablecloth pulled off a laid table (tablecloth)."""
from __future__ import annotations

import math

import numpy as np

from .. import _check
from .._errors import InvalidInputError
from ..bodies import BODY_BYTES, Bodies, Joints, Pins
from ..render import Mesh
from ..scene import Scene
from ..shapes import cloth_springs
from ..terms import Drag, Gravity, Springs
from ._common import (
    SKY_2D,
    _count,
    _finite_books,
    _flag,
    _nonneg,
    _optional,
    _particle_mass,
    _particles,
    _positive,
    _set_stable_dt,
    _stamped,
)


def _named(args: str, build):
    """``build()``, with what the bodies refuse (a size derived from the arguments that came out
    ≤ 0 or beyond float64) and a scene whose energy is beyond float64 (a density of 1e306 kg/m²
    gives a finite mass but an infinite potential) named by the scene's arguments `args`."""
    try:
        scene = build()
    except InvalidInputError as e:
        raise InvalidInputError(f"{args}: give bodies the core refuses ({e})") from None
    return _finite_books(scene, args)


# Warm wood, one tone a domino (so the wave reads as it runs), and the crates' pine.
_WOOD = np.array([[196, 132, 78], [214, 156, 96], [176, 112, 64], [226, 172, 110]], dtype=np.uint8)
_GROUND = (84, 92, 104)


def _grounded(x0: float, x1: float, depth: float) -> dict:
    """A 2D scene's look on the ground (issue 65: flat scenes on plain white read as diagrams):
    the sky-grey backdrop of the other 2D scenes, and a band of earth under the floor, which
    lies at y = 0, from ``x0`` to ``x1`` and ``depth`` m deep (a prop: it does not collide)."""
    earth = [[x0, 0.0], [x1, 0.0], [x1, -depth], [x0, -depth]]
    return {"backdrop": SKY_2D, "decor": [{"polygon": earth, "color": (216, 206, 190)}]}


def dominoes(
    n: int = 13,
    *,
    height: float = 0.05,
    growth: float = 1.25,
    spacing_ratio: float = 0.5,
    thickness_ratio: float = 0.18,
    friction: float = 0.4,
    push: float = 1.0,
    dt: float = 1 / 480,
    threads: int | None = None,
) -> Scene:
    """A row of ``n`` dominoes, each ``growth`` times taller than the one before, toppled by a
    push at the small end: domino amplification (Whitehead, Am. J. Phys. 51 (1983) 182), a
    5 cm domino bringing down one 15 times its height.

    Domino ``i`` is a box ``height · growth^i`` m tall and ``thickness_ratio`` of that thick
    (density 650 kg/m², wood), standing on a fixed floor; the gap to the next is
    ``spacing_ratio`` of its height; friction ``friction`` at every contact, restitution 0. The
    first starts turning about its front foot at ``push`` · √(g/h) rad/s, enough to tip it
    onto the second. With ``growth=1`` the row is uniform and the wave runs at a steady speed
    (``tests/bodies`` measures it). Rigid bodies by rapier, dt ``dt`` s.

    Raises TypeError / InvalidInputError naming the argument.
    """
    n = _count(n, "n", 2)
    _check.memory("n", n * BODY_BYTES, f"{n} dominoes")
    h0 = _positive(height, "height")
    k = _positive(growth, "growth")
    gap = _positive(spacing_ratio, "spacing_ratio")
    ratio = _positive(thickness_ratio, "thickness_ratio")
    mu = _nonneg(friction, "friction")
    w0 = _nonneg(push, "push")
    scene = Scene(2, integrator="semi_implicit_euler", dt=_positive(dt, "dt"), threads=threads)
    scene.add(Gravity([0.0, -9.81]))
    with np.errstate(all="ignore"):
        return _named("n, height, growth, spacing_ratio, thickness_ratio, push",
                      lambda: _dominoes(scene, n, h0, k, gap, ratio, mu, w0))


def _dominoes(scene: Scene, n: int, h0: float, k: float, gap: float, ratio: float, mu: float, w0: float) -> Scene:
    h = h0 * k ** np.arange(n)
    t = ratio * h
    x = np.concatenate([[0.0], np.cumsum(t[:-1] / 2 + gap * h[:-1] + t[1:] / 2)])
    ends = (x[0] - 2 * h[0], x[-1] + 1.15 * h[-1])
    floor = 0.02 * h[-1]
    scene.add(Bodies("box", size=[(0.5 * (ends[1] - ends[0]), floor)], positions=[(0.5 * (ends[0] + ends[1]), -floor)],
                     kind="fixed", friction=mu, restitution=0.0, color=_GROUND, name="floor"))
    # The first turns about its front foot (clockwise, towards the row): ω and the centre's
    # velocity ω × (centre − foot), so the floor is not pushed at the start.
    w = np.zeros(n)
    v = np.zeros((n, 2))
    w[0] = -w0 * math.sqrt(9.81 / h[0])
    v[0] = (-w[0] * h[0] / 2, -w[0] * t[0] / 2)
    scene.add(Bodies("box", size=np.stack([t / 2, h / 2], 1), positions=np.stack([x, h / 2], 1), velocities=v,
                     angular_velocities=w, density=650.0, friction=mu, restitution=0.0,
                     color=_WOOD[np.arange(n) % len(_WOOD)], name="dominoes"))
    scene.render_defaults = {"look": _grounded(ends[0], ends[1], 0.3 * h[-1])}
    return scene


# 110 frames: the last domino lands at about 3.3 s and the GIF ends 0.4 s later (130 frames
# showed a second of settling after it: a fading end).
dominoes.render_defaults = {"frames": 110, "fps": 30, "frame_time": 1 / 30, "size": (480, 270), "color_by": "none", "antialias": True}
dominoes = _stamped(dominoes)


def pyramid(
    rows: int = 8,
    *,
    box: float = 0.5,
    chain: int = 10,
    ball_radius: float = 0.6,
    ball_density: float = 8000.0,
    dt: float = 1 / 240,
    threads: int | None = None,
) -> Scene:
    """A wrecking ball on a chain swings into a pyramid of crates.

    The pyramid has ``rows`` rows of square crates ``box`` m wide (pine, 500 kg/m², friction 0.6),
    stacked with no gaps on a fixed floor; a ball of ``ball_radius`` m (steel-like density
    ``ball_density`` kg/m²) hangs from a chain of ``chain`` capsule links joined by revolute
    joints to a fixed pivot, and starts raised level with the pivot, so it swings down through
    the pyramid's side. Rigid bodies by rapier, dt ``dt`` s.

    Raises TypeError / InvalidInputError naming the argument.
    """
    rows = _count(rows, "rows", 1)
    b = _positive(box, "box")
    links = _count(chain, "chain", 1)
    _check.memory("rows, chain", (rows * (rows + 1) // 2 + links) * BODY_BYTES, "the crates and the chain's links")
    r = _positive(ball_radius, "ball_radius")
    rho = _positive(ball_density, "ball_density")
    scene = Scene(2, integrator="semi_implicit_euler", dt=_positive(dt, "dt"), threads=threads)
    scene.add(Gravity([0.0, -9.81]))
    with np.errstate(all="ignore"):
        return _named("rows, box, chain, ball_radius, ball_density", lambda: _pyramid(scene, rows, b, links, r, rho))


def _pyramid(scene: Scene, rows: int, b: float, links: int, r: float, rho: float) -> Scene:
    width = rows * b
    # A floor between two walls high enough that no crate the ball throws leaves the picture
    # (one flew 6.9 m high at the defaults: the walls are 7.2 m).
    lo, hi = -1.6 * width, 1.9 * width
    wall = 0.15 * b
    scene.add(Bodies("box", size=[(0.5 * (hi - lo) + 2 * wall, wall), (wall, 0.9 * width), (wall, 0.9 * width)],
                     positions=[(0.5 * (lo + hi), -wall), (lo - wall, 0.9 * width), (hi + wall, 0.9 * width)], kind="fixed",
                     friction=0.6, restitution=0.0, color=_GROUND, name="floor"))
    pos = [((k - 0.5 * (rows - 1 - i)) * b, (i + 0.5) * b) for i in range(rows) for k in range(rows - i)]
    pos_a = np.array(pos) + np.array([0.5 * width, 0.0])
    tones = _WOOD[np.arange(len(pos)) * 7 % len(_WOOD)]
    scene.add(Bodies("box", size=[(0.5 * b * 0.98, 0.5 * b * 0.98)], positions=pos_a, density=500.0, friction=0.6,
                     restitution=0.0, color=tones, name="crates"))
    # The chain: from the pivot high to the left of the pyramid, laid out horizontally (raised).
    height = rows * b
    pivot = np.array([0.5 * width - 0.5 * height - 0.2 * b, height * 1.9])
    reach = height * 1.9 - 0.55 * height
    link = (reach - r) / links
    xs = pivot[0] - (np.arange(links) + 0.5) * link
    scene_links = scene.add(Bodies("capsule", size=[(0.5 * link - 0.08 * b, 0.08 * b)],
                                   positions=np.stack([xs, np.full(links, pivot[1])], 1), density=2000.0,
                                   friction=0.3, restitution=0.0, color=(150, 156, 168), name="chain"))
    ball = scene.add(Bodies("ball", size=[r], positions=[(pivot[0] - links * link - r, pivot[1])], density=rho,
                            friction=0.3, restitution=0.1, color=(70, 74, 86), name="ball"))
    ends = pivot[0] - np.arange(links + 1) * link
    # The pivot: a fixed hub the chain hangs from (joined bodies do not collide).
    hub = scene.add(Bodies("ball", size=[0.16 * b], positions=[pivot], kind="fixed", color=_GROUND, name="pivot"))
    scene.add(Joints("revolute", hub[0], scene_links[0], anchors=pivot))
    if links > 1:
        scene.add(Joints("revolute", scene_links[:-1], scene_links[1:], anchors=np.stack([ends[1:-1], np.full(links - 1, pivot[1])], 1)))
    scene.add(Joints("revolute", scene_links[links - 1], ball[0], anchors=(ends[-1], pivot[1])))
    scene.render_defaults = {"look": _grounded(lo - 2 * wall, hi + 2 * wall, 0.3 * width)}
    return scene


pyramid.render_defaults = {"frames": 150, "fps": 30, "frame_time": 1 / 30, "size": (480, 360), "color_by": "none", "antialias": True}
pyramid = _stamped(pyramid)



# The tumbling boxes' colours: coral, sand, saffron, teal, slate (one per body, in turn).
_TUMBLE = np.array([[231, 111, 81], [244, 162, 97], [233, 196, 106], [42, 157, 143], [52, 86, 110]], dtype=np.uint8)


def tumbling_boxes(
    n: int = 16,
    *,
    ramps: int = 3,
    slope: float = 0.5,
    box: float = 0.2,
    friction: float = 0.3,
    restitution: float = 0.3,
    density: float = 500.0,
    seed: int = 8,
    dt: float = 1 / 240,
    threads: int | None = None,
) -> Scene:
    """Boxes tumbling down a zig-zag of ramps: ``n`` bodies dropped, spinning, in a loose heap
    onto the top of ``ramps`` fixed ramps that alternate in direction between two walls; they
    slide down each ramp, tip over its end onto the next and pile up on the floor.

    The walls stand 4.2 m apart; the ramps are inclined at ``slope`` rad (default 0.5, 29°:
    steeper than the friction angle atan(``friction``), 17° at the default 0.3, so a box slides;
    a body stops on a ramp only in a jam), each ramp's low end 1.4 m short of the facing wall
    (1.1 m let three boxes arch across the gap and jam half the heap on the first ramp) and 0.9 m
    above the next ramp (the last one's 1.8 m above the floor of the bin).
    Every body but each 8th from the 4th (a capsule) and each 8th from the 7th (a hexagon) is a box of half-width ``box`` m times 0.75–1.15 and aspect 0.55–1 (drawn from
    ``seed``), turned at random and spinning at up to 4 rad/s; all of density ``density`` kg/m²
    (2D), friction ``friction`` and restitution ``restitution`` at every contact (the ramps,
    walls and floor have 0.1 of their own; a contact takes the larger e). Their shapes and
    speeds spread them out down the ramps, so the cascade lasts: at the defaults the first
    bodies reach the floor at about 3.3 s and 11 of the 16 are still moving at 6 s (the
    default GIF's end; all rest by about 9 s). The cascade is chaotic: at e = 0.3, 3 of seeds
    1–8 jam on a ramp before 6 s.
    Gravity (0, −9.81) m/s²; rigid bodies by rapier, dt ``dt`` s. Energy books: see :mod:`physcore.bodies` (what the contacts take out is
    ``"bodies: contacts and joints"``).

    Returns
    -------
    Scene
        Bodies groups ``"ramps"`` (fixed: the ramps, floor and walls), ``"boxes"``, and, where
        ``n`` reaches them, ``"capsules"`` and ``"hexagons"``.

    Raises
    ------
    TypeError, InvalidInputError
        Naming the argument: ``n`` or ``ramps`` below 1 or more bodies than memory holds, ``slope``
        outside (0, 1.2] rad, ``box`` ≤ 0 or too large for a ramp (above 0.35 m), ``friction``
        < 0, ``restitution`` outside [0, 1], ``density`` or ``dt`` ≤ 0, ``seed`` < 0.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.scenes.tumbling_boxes(n=8)
    >>> [(g.name, g.shape, len(g)) for g in scene.bodies][1:]
    [('boxes', 'box', 6), ('capsules', 'capsule', 1), ('hexagons', 'polygon', 1)]
    """
    n = _count(n, "n", 1)
    ramps = _count(ramps, "ramps", 1)
    _check.memory("n, ramps", (n + ramps + 3) * BODY_BYTES, f"{n} bodies and {ramps} ramps")
    theta = _check.float_in_range("slope", slope, 0.0, 1.2, lo_open=True, unit="rad")
    b = _check.float_in_range("box", box, 0.0, 0.35, lo_open=True, unit="m")
    mu = _nonneg(friction, "friction")
    e = _check.float_in_range("restitution", restitution, 0.0, 1.0)
    rho = _positive(density, "density")
    seed = _count(seed, "seed", 0)
    scene = Scene(2, integrator="semi_implicit_euler", dt=_positive(dt, "dt"), threads=threads)
    scene.add(Gravity([0.0, -9.81]))
    with np.errstate(all="ignore"):
        return _named("n, ramps, slope, box, density", lambda: _tumbling(scene, n, ramps, theta, b, mu, e, rho, seed))


def _segment(a: tuple[float, float], b: tuple[float, float], t: float) -> tuple[tuple[float, float], tuple[float, float], float]:
    """A slab of thickness 2t whose top face runs from a to b: (half extents, centre, angle)."""
    d = np.subtract(b, a)
    length = float(np.hypot(d[0], d[1]))
    up = np.array([-d[1], d[0]]) / length
    c = 0.5 * (np.add(a, b)) - t * up
    return (0.5 * length, t), (float(c[0]), float(c[1])), math.atan2(d[1], d[0])


def _tumbling(scene: Scene, n: int, ramps: int, theta: float, b: float, mu: float, e: float, rho: float, seed: int) -> Scene:
    width, gap, drop, t = 4.2, 1.4, 0.9, 0.05
    run = width - gap
    fall = run * math.tan(theta)
    top = ramps * (fall + drop)
    slabs = []
    for i in range(ramps):
        y = top - i * (fall + drop)
        ends = ((0.0, y), (run, y - fall)) if i % 2 == 0 else ((width, y), (width - run, y - fall))
        slabs.append(_segment(*ends, t))
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    # A loose heap over the top ramp: rows of four, 0.45 m apart, each body clear of the ramp.
    x = 0.4 + (k % 4) * 0.75 + rng.uniform(-0.05, 0.05, n)
    y = top - x * math.tan(theta) + 0.45 + 0.45 * (k // 4)
    # The floor, a bin under the last ramp (its low end two drops above it), and walls that rise
    # above the heap, so nothing bounces out.
    floor, high = -drop, float(y.max()) + 0.5
    slabs += [_segment((width + 2 * t, floor), (-2 * t, floor), t),
              _segment((0.0, floor), (0.0, high), t), _segment((width, high), (width, floor), t)]
    scene.add(Bodies("box", size=[s[0] for s in slabs], positions=[s[1] for s in slabs], angles=[s[2] for s in slabs],
                     kind="fixed", friction=mu, restitution=0.1, color=_GROUND, name="ramps"))
    half = b * rng.uniform(0.75, 1.15, n)
    aspect = rng.uniform(0.55, 1.0, n)
    angles = rng.uniform(0.0, math.pi, n)
    spin = rng.uniform(-4.0, 4.0, n)
    colors = _TUMBLE[k % len(_TUMBLE)]
    capsule, hexagon = k % 8 == 3, k % 8 == 6
    boxes = ~(capsule | hexagon)
    common = {"density": rho, "friction": mu, "restitution": e}
    scene.add(Bodies("box", size=np.stack([half[boxes], half[boxes] * aspect[boxes]], 1), positions=np.stack([x, y], 1)[boxes],
                     angles=angles[boxes], angular_velocities=spin[boxes], color=colors[boxes], name="boxes", **common))
    if capsule.any():
        scene.add(Bodies("capsule", size=np.stack([0.7 * half[capsule], 0.5 * half[capsule]], 1),
                         positions=np.stack([x, y], 1)[capsule], angles=angles[capsule], angular_velocities=spin[capsule],
                         color=colors[capsule], name="capsules", **common))
    if hexagon.any():
        turn = np.arange(6) * math.pi / 3
        scene.add(Bodies("polygon", vertices=np.stack([np.cos(turn), np.sin(turn)], 1) * b, positions=np.stack([x, y], 1)[hexagon],
                         angles=angles[hexagon], angular_velocities=spin[hexagon], color=colors[hexagon], name="hexagons",
                         **common))
    return scene


# 6 s at 30 fps, one simulated second a second: the heap lands, slides and tips down the ramps;
# the last bodies are still tumbling at the end. Portrait: the zig-zag is taller than wide.
# The other 2D scenes' sky-grey backdrop (issue 65: on plain white the bin read as a diagram).
tumbling_boxes.render_defaults = {"frames": 180, "fps": 30, "frame_time": 1 / 30, "size": (320, 480), "color_by": "none",
                                  "antialias": True, "look": {"backdrop": SKY_2D}}
tumbling_boxes = _stamped(tumbling_boxes)


# Oak for the table, a brass bar, china, a wooden floor before a warm wall.
_OAK, _BRASS, _FLOOR3 = (150, 98, 60), (196, 160, 70), (122, 92, 70)


def _bistro_check(cells: int = 12, px: int = 8) -> list:
    """A red-and-white checked tablecloth, (cells·px)² RGB as nested lists (render_defaults
    compare with ==): white checks, pink where a red band crosses a white one, red where two
    cross (the folds and the slide read in its lines)."""
    band = (np.arange(cells * px) // px) % 2
    red = 0.5 * (band[:, None] + band[None, :])
    white, crimson = np.array((250, 246, 240), np.float64), np.array((196, 40, 44), np.float64)
    return np.rint(white * (1 - red)[..., None] + crimson * red[..., None]).astype(np.uint8).tolist()
_DISHES = np.array([[232, 236, 240], [200, 72, 60], [46, 98, 186], [236, 200, 90]], dtype=np.uint8)


def tablecloth(
    n: int = 24,
    *,
    size: float = 1.2,
    mass: float = 0.6,
    stiffness: float = 800.0,
    bar: float = 0.3,
    pull: float = 4.0,
    pull_at: float = 0.15,
    friction: float = 0.2,
    dishes: bool = True,
    integrator: str = "rk4",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """The tablecloth trick (3D): a laid table, its cloth yanked out from under the dishes. An
    n×n mass-spring sheet of `size` m and `mass` kg lies on a table 1.0 × 0.7 m, falling over
    its +x and y edges, a brass bar of `bar` kg sewn along the +x hem (:class:`~physcore.Pins`).
    At `pull_at` s a rope from the bar to a hand moving away at `pull` m/s (a kinematic body
    out of the picture, pulling out and 15° down) goes taut and yanks the cloth off. The
    dishes (a plate, three bowls and a loaf, rigid bodies) rest on the cloth: the sheet
    between a dish and the table bears the dish's weight N = m g, so while the cloth slides
    under a dish, Coulomb friction drags the dish with μ N, and in the time Δt the cloth takes
    to leave it, the dish gains only μ g Δt of speed (½ μ g Δt² of travel; as much again
    sliding on the bare table): a fast pull leaves the dishes where they stood, give or take
    a few centimetres (the two bowls nearest the pulled edge, where the sheet lifts as it
    bends over it, slide 15–25 cm); a slow one (a small `pull`: the dish keeps up with the
    cloth) drags them along with it.

    The sheet is :func:`~physcore.scenes.cloth`'s (structural, shear and bend springs of
    `stiffness` N/m, stepped by `integrator`), its particles 4 mm in radius against the bodies
    (``"bodies ⇄ particles"``: the table's, the dishes' and the floor's Coulomb `friction`),
    its bend springs at a tenth of `stiffness` (cloth bends far more easily than it stretches),
    with dashpots of 0.3 N·s/m (the yank's shock dies out instead of ringing). The table, its legs and the floor are fixed boxes; the bar a capsule; ``pull=0`` leaves the
    bar hanging (``bar=0``: no bar, no pull). Gravity (0, 0, −9.81) m/s²; ``dt=None`` takes
    :meth:`Scene.suggest_dt` (half of the springs' fastest time scale).

    The sheet is stepped by RK4, not velocity Verlet: the pins and the contacts move particles
    between steps, every step, so Verlet's symplectic advantage is lost (each move restarts it)
    and its error in the books is third order, concentrated in the landings.

    Raises TypeError / InvalidInputError naming the argument.
    """

    n = _count(n, "n", 4)
    _particles("n", n * n, 6 * n * n)
    size, mass, k = _positive(size, "size"), _positive(mass, "mass"), _positive(stiffness, "stiffness")
    bar_mass = _nonneg(bar, "bar")
    # A bar lighter than a gram is no hem, and one of 1e-320 kg underflows the body's mass.
    if bar_mass != 0 and not (1e-3 <= bar_mass <= 1e6):
        raise InvalidInputError(f"bar: a bar of {bar_mass:g} kg is no tablecloth's hem (0 for none, or 1e-3 to 1e6 kg)")
    speed = _nonneg(pull, "pull")
    if speed > 100.0:
        raise InvalidInputError(f"pull: a hand pulls at most 100 m/s, got {speed:g}")
    t_pull = _nonneg(pull_at, "pull_at")
    if t_pull > 60.0:
        raise InvalidInputError(f"pull_at: the pull starts within 60 s, got {t_pull:g}")
    mu = _nonneg(friction, "friction")
    dishes = _flag(dishes, "dishes")
    dt = _optional(dt, "dt")
    if not (0.2 <= size <= 10.0):
        raise InvalidInputError(f"size: the cloth must be 0.2 to 10 m across to cover the table, got {size}")
    s = size / (n - 1)
    m = _particle_mass(mass / (n * n), "mass, n")
    scene = Scene(3, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    top = 0.76  # the table top's upper face, m
    hx, hy, ht = 0.5, 0.35, 0.025
    r = 0.004  # the particles' radius: the cloth lies 2r thick
    # The sheet, laid flat on the table: its far hem 5 cm inside the table's −x edge, the rest
    # reaching past the +x edge (0.25 m for the default size) and 0.25 m past the y edges; what
    # lies past an edge falls over it as the scene starts. (A hem hanging down the far side
    # had to be dragged up over that edge, and the sheet, stretched to twice its length, held
    # to the table by the friction of its own flutter: the dishes went with it.)
    u, w = np.meshgrid(-hx + 0.05 + np.arange(n) * s, np.arange(n) * s - 0.5 * size)
    u, w = u.ravel(), w.ravel()
    x = np.stack([u, w, np.full(n * n, top + r)], axis=1)
    scene.add_particles(x, masses=m)
    scene.set_attribute("radius", np.full(n * n, r))
    i, j = cloth_springs(n)
    # Cloth bends far more easily than it stretches: the bend springs (two cells long) at a
    # tenth of the others' stiffness, so it falls in soft folds rather than as card.
    bend = np.hypot(u[i] - u[j], w[i] - w[j]) > 1.5 * s
    scene.add(Springs(i, j, stiffness=np.where(bend, 0.1 * k, k), damping=0.3))
    scene.add(Gravity([0.0, 0.0, -9.81]))
    scene.add(Drag(0.3 * mass / (n * n)))
    # A wide floor (what rolls off the table stays on it) and the camera fitted to the table's
    # surroundings (render_defaults' extent), not to the floor.
    scene.add(Bodies("box", size=[(6.0, 3.5, 0.05)], positions=[(0.4, -2.5, -0.05)], kind="fixed", friction=0.6,
                     restitution=0.1, color=_FLOOR3, name="floor"))
    legs = [(sx * (hx - 0.05), sy * (hy - 0.05), 0.5 * (top - 2 * ht)) for sx in (-1, 1) for sy in (-1, 1)]
    scene.add(Bodies("box", size=[(hx, hy, ht)] + [(0.025, 0.025, 0.5 * (top - 2 * ht))] * 4,
                     positions=[(0.0, 0.0, top - ht)] + legs, kind="fixed", friction=mu, restitution=0.0,
                     color=_OAK, name="table"))
    if dishes:
        on = top + 2 * r  # the cloth's upper face: the dishes stand on it
        scene.add(Bodies("box", size=[(0.11, 0.11, 0.006)], positions=[(-0.12, 0.02, on + 0.006)], density=1000.0,
                         friction=mu, restitution=0.0, color=_DISHES[0], name="plate"))
        # A bowl: a 16-sided frustum (a convex hull) 5 cm tall, 5 cm in radius at its foot and
        # 7 cm at its rim: wide enough to stand on the sheet's particles (5 cm apart at n = 24).
        a = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
        ring = np.stack([np.cos(a), np.sin(a)], 1)
        bowl = np.concatenate([np.c_[0.05 * ring, np.full(16, -0.025)], np.c_[0.07 * ring, np.full(16, 0.025)]])
        bowls = [(0.1, 0.15, on + 0.025), (0.12, -0.14, on + 0.025), (-0.28, -0.17, on + 0.025)]
        scene.add(Bodies("hull", vertices=bowl, positions=bowls, density=500.0, friction=mu, restitution=0.0,
                         color=_DISHES[2], name="bowls"))
        scene.add(Bodies("box", size=[(0.07, 0.045, 0.04)], positions=[(-0.32, 0.17, on + 0.04)], density=300.0,
                         friction=mu, restitution=0.0, color=(214, 150, 70), name="loaf"))
    if bar_mass > 0:
        # The bar along the +x hem.
        hem = np.flatnonzero(np.isclose(u, u.max()))
        rb = 0.012
        half = 0.5 * size
        volume = math.pi * rb * rb * (2 * half) + 4.0 / 3.0 * math.pi * rb**3
        along_y = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))
        at = (float(u.max()), 0.0, top + r)
        rod = scene.add(Bodies("capsule", size=[(half, rb)], positions=[at], orientations=[along_y],
                               density=bar_mass / volume, friction=mu, restitution=0.0, color=_BRASS, name="bar"))
        scene.add(Pins(hem, rod[0]))
        if speed > 0:
            # The hand: a small kinematic ball 5 cm from the bar, moving away out and down; the
            # rope goes taut when it has moved speed × pull_at more.
            way = np.array([math.cos(math.radians(15.0)), 0.0, -math.sin(math.radians(15.0))])
            start = np.asarray(at) + 0.05 * way
            hand = scene.add(Bodies("ball", size=[0.002], positions=[tuple(start)], velocities=[tuple(speed * way)],
                                    kind="kinematic", color=_BRASS, name="hand"))
            scene.add(Joints("rope", rod[0], hand[0], anchors=at, anchors_b=tuple(start), length=0.05 + speed * t_pull))
    if dt is None:
        # suggest_dt(), not twice it as cloth() takes: the cloth lands on the table and the
        # floor, and the pins snap the hem to the bar, every step moving particles between the
        # integrator's steps.
        _set_stable_dt(scene, 1.0, "stiffness, mass")
    scene.render_defaults = {"mesh": Mesh.grid(n, n)}
    return _finite_books(scene, "size, mass, bar")


# The trick in slow motion: 0.6 s of simulated time over 2.4 s (a quarter of real speed): the
# flaps fall over the edges, the yank at 0.15 s, the cloth off the table by about 0.35 s and
# falling past its edge to the end, the dishes' slide over by about 0.6 s (0.7 s ended on 0.9 s
# of a still table, the cloth gone from the view by 0.47 s). A checked cloth (its lines show it
# slide and fold) in a room: a wooden floor wider than the view, before a warm wall; the camera
# on the table, the view wide enough on the pull's side to follow the cloth off it.
tablecloth.render_defaults = {"frames": 72, "fps": 30, "frame_time": 0.7 / 84, "size": (480, 360), "color_by": "none",
                              "texture": _bistro_check(), "title": "the tablecloth trick, 1/4 speed",
                              "look": {"backdrop": ((236, 226, 212), (200, 186, 170))},
                              "view": (-50.0, 20.0), "extent": ((-0.6, -0.55, 0.3), (1.5, 0.55, 0.85))}
tablecloth = _stamped(tablecloth)
