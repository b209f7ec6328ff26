"""Grain (DEM) scenes: the Galton board, billiards, Newton's cradle and the jelly (a soft body
of grains)."""
from __future__ import annotations

import math

import numpy as np

from .. import _check
from .._errors import InvalidInputError, InvalidTypeError
from ..contacts import Contacts
from ..render import Mesh
from ..scene import Scene
from ..shapes import cloth_springs
from ..terms import Capsule, Drag, Gravity, Plane, Springs
from ._common import _count, _nonneg, _optional, _particles, _positive, _stamped


def _grain_scene(dt: float | None, integrator: str | None, threads: int | None) -> Scene:
    if integrator is not None and not isinstance(integrator, str):
        raise InvalidTypeError(f"integrator: expected a string or None, got {type(integrator).__name__}")
    if integrator not in (None, "semi_implicit_euler"):
        raise InvalidInputError(f"integrator: the grain scenes step with 'semi_implicit_euler' (the DEM scheme), got {integrator!r}")
    return Scene(2, integrator="semi_implicit_euler", dt=1e-4 if dt is None else dt, threads=threads)


def _auto_grain_dt(scene: Scene, dt: float | None, factor: float = 1.0) -> Scene:
    """The scene with dt = `factor` × its contacts' automatic step (a 50th of the contact
    duration) unless `dt` was given."""
    if dt is None:
        scene.dt = factor * scene.suggest_dt()
    return scene


def galton_board(
    balls: int = 120,
    *,
    rows: int = 8,
    restitution: float = 0.69,
    friction: float = 0.0,
    seed: int = 0,
    spacing: float = 12.0,
    width: float = 0.1,
    drag: float = 4e-3,
    integrator: str | None = None,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Galton board in a viscous liquid: a queue of balls sinks at terminal speed onto `rows`
    staggered rows of pegs and piles up in bins.

    2D; balls of radius 2 mm and 0.26 g, pegs of radius 2.3 mm spaced 9 mm (rows 7.8 mm apart,
    gaps of 1.1 ball diameters), linear contacts (:class:`~physcore.Contacts`, k = 10³ N/m)
    with the given restitution and friction; the pegs and the bins' dividers (columns of
    grains of radius 0.8 mm, 2.4 mm apart) are pinned grains, the floor and sides are walls.
    The board is `width` metres wide (at least rows + 1 pitches); the bins are deep enough for
    the binomial's fullest bin plus three of its standard deviations.

    The balls start at rest in one vertical column above the top peg, `spacing` ball diameters
    apart (a hair off the axis, by up to 0.02 radii, from `seed`). The board stands in a liquid,
    modelled as linear `drag` b (kg/s; a sphere's Stokes drag 6πηr at η ≈ 0.1 Pa·s, a
    water–glycerol mix; buoyancy left out): every ball sinks at the same terminal speed
    v = m g / b (0.64 m/s by default), so none catches up with the one below and they reach
    the pegs one by one, every spacing·2r / v (75 ms by default), all at that speed. Glycerine
    Galton boards are classroom demonstrations.

    An ideal board sends each ball left or right at every row, so its bin is
    Binomial(rows, ½) (Galton, *Natural Inheritance*, 1889), of variance rows/4 bins². This one
    comes close only by calibration: the spread depends steeply on restitution and drag
    (isolated balls, 8 rows, v = 0.64 m/s: variance 0.55 / 2.5 / 2.6 bins² at restitution
    0.6 / 0.75 / 0.9; at v = 1 m/s balls hop across columns, 4–6 bins²). The default stream (8 rows, 120 balls,
    seeds 0–3) gives variance 1.52–1.97 bins² (mean 1.72) at restitution 0.69, 1.75–2.65
    (mean 2.23, seeds 0–5) at 0.70 and 1.59–2.06 at 0.68, against the binomial's 2.0 (each run
    one ``advance`` to its end; a run split into calls steps at a slightly different dt, since
    each call divides its span into equal steps, so its balls bounce differently: seed 0 gives
    1.67 in one call of 11 s and 1.87 in eleven of 1 s, a spread like the seeds'); the
    test suite's variance and Pearson χ² tests (160 balls, significance 0.001) pass at the
    default. A ball takes about 0.9 s through the pegs, so several are on the board at once.
    Other restitutions, drags and spacings give other spreads. With friction balls can rest
    on the pegs. Particles: the balls first (indices
    0..balls-1), then the fixed ones; :func:`galton_bins` counts the balls per bin.

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    balls = _check.int_in_range("balls", balls, 1, 1 << 40)  # the particle count is then checked in float
    rows = _count(rows, "rows", 1)
    if rows > 40:
        raise InvalidInputError(f"rows: at most 40, got {rows}")
    restitution = _check.float_in_range("restitution", restitution, 0.0, 1.0)
    if restitution == 0.0:
        raise InvalidInputError("restitution: must be > 0 (a dashpot cannot stop a ball dead)")
    friction = _nonneg(friction, "friction")
    seed = _count(seed, "seed", 0)
    spacing = _check.float_in_range("spacing", spacing, 1.5, 50.0)
    width = _check.float_in_range("width", width, 0.02, 10.0)
    # Up to 1 kg/s: the balls' speed then relaxes in m/b = 0.26 ms, still 50 steps; beyond, the
    # automatic step would follow the drag down (1e303 kg/s made it subnormal).
    # > 0: the queue sinks at the terminal speed m g / drag.
    drag = _check.float_in_range("drag", drag, 0.0, 1.0, lo_open=True)
    dt = _optional(dt, "dt")
    # A tight lattice: gaps of 1.1 ball diameters, so a ball leaving a peg drops into the gap
    # beside it onto the peg below (with wider gaps, 1.9 d, balls skipped columns).
    rb, s, mass = 0.002, 0.009, 2.6e-4
    d = 2 * rb
    rp = 0.5 * (s - 1.1 * d)
    h = s * math.sqrt(3.0) / 2.0
    half = max(0.5 * (rows + 1) * s, 0.5 * width)  # the board spans x in [-half, half]
    r_g, p = 0.0008, 0.0024  # the dividers' grains, 0.8 mm gaps (a ball cannot pass)
    # The fullest bin of Binomial(rows, ½) plus 3 standard deviations, about 1.5 mm a ball (two
    # abreast in the 7.4 mm between dividers; measured), and a margin.
    full = balls * math.comb(rows, rows // 2) / 2.0**rows
    bin_depth = max(0.03, 0.0018 * (full + 3 * math.sqrt(full) + 3))
    _particles("balls, rows, width", balls + (2 * half / s + 1) * rows + (2 * half / s + 1) * bin_depth / p)
    fixed: list[tuple[float, float, float]] = []
    # Staggered rows across the whole width: row k has pegs at x = (j − k/2)·s, so a ball above
    # peg 0 of row 0 is shifted by ±s/2 a row.
    n_across = int(half / s) + rows + 2
    for k in range(rows):
        for j in range(-n_across, n_across + 1):
            x = (j - 0.5 * k) * s
            if abs(x) <= half + 1e-9:
                fixed.append((x, -k * h, rp))
    # Bins: dividers between the landing places (m − rows/2)s, from just under the last row.
    y_top_bins = -rows * h + 0.5 * h
    y_floor = y_top_bins - bin_depth
    for m in range(-n_across, n_across + 1):
        x = (m - 0.5 * rows - 0.5) * s
        if abs(x) < half - r_g:
            fixed.extend((x, float(y), r_g) for y in np.arange(y_top_bins - r_g, y_floor, -p))
    # The queue: ball i at rest 3 d above the top peg plus i spacings.
    rng = np.random.default_rng(seed)
    b = np.zeros((balls, 2))
    b[:, 0] = rng.uniform(-0.02, 0.02, balls) * rb
    b[:, 1] = rp + rb + 3 * d + spacing * d * np.arange(balls)
    f = np.array(fixed)
    x = np.concatenate([b, f[:, :2]])
    radius = np.concatenate([np.full(balls, rb), f[:, 2]])
    pinned = np.arange(len(x)) >= balls
    scene = _grain_scene(dt, integrator, threads)
    scene.add_particles(x, masses=mass, pinned=pinned)
    scene.set_attribute("radius", radius)
    scene.add(Gravity([0.0, -9.81]))
    scene.add(Drag(drag))
    scene.add(Contacts(stiffness=1e3, restitution=restitution, friction=friction,
                       walls=[Plane([0.0, y_floor], [0.0, 1.0], restitution=restitution, friction=friction),
                              Plane([-half, 0.0], [1.0, 0.0], restitution=restitution, friction=friction),
                              Plane([half, 0.0], [-1.0, 0.0], restitution=restitution, friction=friction)]))
    # Drawn as a diagram: grey pegs and dividers, balls in four warm hues, a pale liquid; the
    # camera holds the board (from the floor to 3 pitches above the top peg), so the queue
    # enters the picture ball by ball.
    hues = np.array(GALTON_COLORS, dtype=np.uint8)
    colors = np.concatenate([hues[np.arange(balls) % len(hues)], np.full((len(f), 3), 125, np.uint8)])
    scene.render_defaults = {"galton": {"balls": balls, "rows": rows, "pitch": s},
                             "colors": colors.tolist(),  # plain lists: render_defaults compare with ==
                             "extent": ((-half, y_floor), (half, rp + 3 * s))}
    return _auto_grain_dt(scene, dt)


GALTON_COLORS = ((230, 120, 30), (214, 62, 48), (240, 175, 40), (190, 80, 120))  # RGB: amber, red, gold, plum

# 10.2 s of simulated time at 1.6× speed: the default queue's last ball lands at about 10 s.
galton_board.render_defaults = {"antialias": True, "frames": 154, "fps": 25, "frame_time": 1 / 15, "size": (300, 560),
                                "size_by": "radius", "color_by": "none", "background": (226, 236, 244)}
galton_board = _stamped(galton_board, old_order=('balls', 'rows', 'restitution', 'friction', 'seed', 'spacing', 'width', 'drag', 'integrator', 'dt', 'threads'), keep=1)


def galton_bins(scene: Scene) -> np.ndarray:
    """Balls per bin of a :func:`galton_board` scene now: (rows + 1,) int64, bin m holding the
    balls that turned right m times (below the last row of pegs); balls still above are not
    counted."""
    g = (getattr(scene, "render_defaults", None) or {}).get("galton")
    if not g:
        raise InvalidInputError("scene: not a galton_board scene")
    x = scene.positions[: g["balls"]]
    rows, s = g["rows"], g["pitch"]
    below = x[:, 1] < -rows * s * math.sqrt(3.0) / 2.0 + 0.25 * s
    m = np.clip(np.rint(x[below, 0] / s + 0.5 * rows), 0, rows).astype(np.int64)
    return np.bincount(m, minlength=rows + 1)


def billiards(
    *,
    speed: float = 10.0,
    restitution: float = 0.93,
    cushion: float = 0.75,
    seed: int = 14,
    integrator: str | None = None,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Billiards break: a cue ball at `speed` (m/s; a firm break is 9 to 11) into a rack of 15
    balls on a pool table with six pockets, seen from above.

    Pool balls (radius 28.6 mm, 170 g) on a 2.54 × 1.27 m table, Hertz contacts
    (:class:`~physcore.Contacts`, so the touching rack passes the impulse through like a real
    one) with ball–ball `restitution` and friction 0.05; the cushions are rails
    (:class:`~physcore.terms.Capsule` walls, 12 mm round, their faces on the table's edges) of
    restitution `cushion` and friction 0.2, broken at the six pockets: mouths 12.7 cm wide
    between the cushions' ends, jaws narrowing them to 6.8 cm (corners) and 11 cm (sides), then
    a round cup 7.3 cm in inner radius (capsules of restitution 0.05 and friction 1). Seen from
    above a ball cannot drop, so the cup stops a ball that enters instead; one that only
    rattles in the jaws can come back out. The cloth's rolling resistance is linear drag 0.05 kg/s (speeds decay over m/b = 3.4 s, so the balls still
    roll at the end of the 5 s animation). Drawn on felt in a wooden frame, each ball in its
    colour (stripes in a lighter shade of their solid), lit as a ball. `seed` offsets the cue
    by a fraction of a millimetre, so each seed breaks differently (the default, 14, sinks a
    ball within 3 s and another by 5 s; of seeds 1–40, 11 pocket a ball, or the cue, within the 5 s).

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    speed = _positive(speed, "speed")
    if speed > 50:
        raise InvalidInputError(f"speed: at most 50 m/s (a cue ball's record is about 15), got {speed}")
    restitution = _check.float_in_range("restitution", restitution, 1e-3, 1.0)
    cushion = _check.float_in_range("cushion", cushion, 1e-3, 1.0)
    seed = _count(seed, "seed", 0)
    dt = _optional(dt, "dt")
    r, m, L, W = 0.028575, 0.17, 2.54, 1.27
    rack = []
    apex = np.array([0.75 * L, 0.5 * W])
    for row in range(5):
        for k in range(row + 1):
            rack.append(apex + [row * 2 * r * math.sqrt(3) / 2 * 1.0005, (k - row / 2) * 2 * r * 1.0005])
    rng = np.random.default_rng(seed)
    cue = np.array([0.25 * L, 0.5 * W + rng.uniform(-5e-4, 5e-4)])
    x = np.array([cue, *rack])
    v = np.zeros_like(x)
    v[0, 0] = speed
    scene = _grain_scene(dt, integrator, threads)
    scene.add_particles(x, v, masses=m)
    scene.set_attribute("radius", np.full(len(x), r))
    scene.add(Drag(0.05))
    rails, cups = _pool_table(L, W)
    walls = ([Capsule(a, b, _RAIL, restitution=cushion, friction=0.2) for a, b in rails]
             + [Capsule(a, b, _RAIL, restitution=0.05, friction=1.0) for a, b in cups])
    scene.add(Contacts(stiffness=5e9, restitution=restitution, friction=0.05, law="hertz", walls=walls))
    # Drawn as the table is: each ball its own colour (the cue white; the 1 ball at the apex,
    # the 8 in the middle of the third row), on felt in a wooden frame, the pockets dark.
    scene.render_defaults = {"colors": [_POOL_COLORS[k] for k in (0, 1, 9, 2, 10, 8, 3, 11, 4, 12, 5, 6, 13, 14, 7, 15)],
                             "background": (28, 110, 60),
                             "look": {"shading": "sphere", "backdrop": ((46, 40, 36), (22, 20, 18)), "decor": _pool_decor(L, W)}}
    return _auto_grain_dt(scene, dt)


#: The pool table's rails and pockets: capsule radius (m), the corner cushions' ends from the
#: corner (m, along each edge) and the side pockets' half-gap (m), and how far outside the table
#: the corner and side cups are centred (m).
_RAIL, _CORNER_END, _SIDE_HALF, _CORNER_CUP, _SIDE_CUP, _CUP = 0.012, 0.095, 0.0755, 0.042, 0.07, 0.085


def _pool_table(L: float, W: float) -> tuple[list, list]:
    """The cushions (six capsule axes, their faces on the table's edges, and two jaws a pocket
    from the cushions' ends into its cup) and the pockets' cups (arcs of 6 capsule axes round
    the back of each pocket, from jaw to jaw) of an L × W table: two lists of (a, b) points.
    Few walls: each costs the contacts about 50 ms to set up."""
    rc, mc, ms = _RAIL, _CORNER_END, _SIDE_HALF
    rails = [((mc, -rc), (L / 2 - ms, -rc)), ((L / 2 + ms, -rc), (L - mc, -rc)),
             ((mc, W + rc), (L / 2 - ms, W + rc)), ((L / 2 + ms, W + rc), (L - mc, W + rc)),
             ((-rc, mc), (-rc, W - mc)), ((L + rc, mc), (L + rc, W - mc))]
    cups = []
    for c, a, b, out in _pockets(L, W):
        radius = _CUP
        ja = np.add(c, radius * np.subtract(a, c) / np.hypot(*np.subtract(a, c)))  # the jaws' inner ends
        jb = np.add(c, radius * np.subtract(b, c) / np.hypot(*np.subtract(b, c)))
        rails += [(a, tuple(ja)), (b, tuple(jb))]
        t0 = math.atan2(ja[1] - c[1], ja[0] - c[0])
        sweep = (math.atan2(jb[1] - c[1], jb[0] - c[0]) - t0) % (2 * math.pi)
        if (out - t0) % (2 * math.pi) > sweep:  # go round the back of the pocket, away from the table
            sweep -= 2 * math.pi
        t = t0 + sweep * np.arange(7) / 6
        pts = np.stack([c[0] + radius * np.cos(t), c[1] + radius * np.sin(t)], axis=1)
        cups += [(tuple(pts[k]), tuple(pts[k + 1])) for k in range(6)]
    return rails, cups


def _pockets(L: float, W: float) -> list:
    """Each pocket's cup centre, the two cushion ends it joins, and the outward direction (rad)."""
    rc, mc, ms, a, b = _RAIL, _CORNER_END, _SIDE_HALF, _CORNER_CUP, _SIDE_CUP
    out = []
    for cx, cy, sx, sy in ((0.0, 0.0, -1, -1), (L, 0.0, 1, -1), (0.0, W, -1, 1), (L, W, 1, 1)):
        out.append(((cx + sx * a, cy + sy * a), (cx - sx * mc, cy + sy * rc), (cx + sx * rc, cy - sy * mc), math.atan2(sy, sx)))
    for cy, sy in ((0.0, -1), (W, 1)):
        out.append(((L / 2, cy + sy * b), (L / 2 - ms, cy + sy * rc), (L / 2 + ms, cy + sy * rc), math.atan2(sy, 0.0)))
    return out


def _pool_decor(L: float, W: float) -> list:
    """The table drawn under the balls: a wooden frame, the cushions' green, the pockets dark."""
    frame, rim = 0.16, 0.05
    def rect(x0, y0, x1, y1):
        return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    def disc(c, rad):
        t = np.arange(40) * (2 * math.pi / 40)
        return np.stack([c[0] + rad * np.cos(t), c[1] + rad * np.sin(t)], axis=1).tolist()
    decor = [{"polygon": rect(-frame, -frame, L + frame, W + frame), "color": (104, 60, 32)},
             {"polygon": rect(-frame + 0.025, -frame + 0.025, L + frame - 0.025, W + frame - 0.025), "color": (138, 84, 46)},
             {"polygon": rect(-rim, -rim, L + rim, W + rim), "color": (18, 84, 44)},
             {"polygon": rect(0.0, 0.0, L, W), "color": (28, 110, 60)}]
    for c, a, b, _ in _pockets(L, W):
        decor.append({"polygon": disc(c, _CUP + _RAIL), "color": (16, 14, 12)})
        ja, jb = (np.add(c, _CUP * np.subtract(e, c) / np.hypot(*np.subtract(e, c))) for e in (a, b))
        decor.append({"polygon": [list(a), ja.tolist(), jb.tolist(), list(b)], "color": (16, 14, 12)})
    for x in (L / 8, L / 4, 3 * L / 8, 5 * L / 8, 3 * L / 4, 7 * L / 8):  # the rails' diamonds
        for y in (-0.5 * (frame + rim), W + 0.5 * (frame + rim)):
            decor.append({"polygon": disc((x, y), 0.012), "color": (236, 226, 200)})
    for y in (W / 4, W / 2, 3 * W / 4):
        for x in (-0.5 * (frame + rim), L + 0.5 * (frame + rim)):
            decor.append({"polygon": disc((x, y), 0.012), "color": (236, 226, 200)})
    return decor


#: Pool balls' colours (RGB) by number, 0 the cue ball: the solids 1–7, the 8 and the stripes
#: 9–15 drawn in their solid's colour, lightened (a disc has no stripe).
_POOL_COLORS = {0: (246, 244, 236), 1: (250, 200, 30), 2: (30, 70, 190), 3: (215, 35, 35), 4: (120, 50, 160),
                5: (245, 125, 25), 6: (20, 150, 80), 7: (140, 35, 30), 8: (18, 18, 18)}
_POOL_COLORS.update({k + 8: tuple(int(c + 0.35 * (255 - c)) for c in _POOL_COLORS[k]) for k in range(1, 8)})


billiards.render_defaults = {"antialias": True, "frames": 150, "fps": 30, "frame_time": 1 / 30, "size": (600, 340),
                             "size_by": "radius", "trail": 12, "color_by": "none"}
billiards = _stamped(billiards, old_order=('speed', 'restitution', 'cushion', 'seed', 'integrator', 'dt', 'threads'), keep=0)


def newtons_cradle(
    balls: int = 5,
    *,
    lift: int = 1,
    angle: float = 30.0,
    law: str = "hertz",
    gap: float = 2e-4,
    integrator: str | None = None,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Newton's cradle: `balls` steel balls (radius 2 cm, 0.26 kg) hanging in a row on 40 cm
    strings, a hair's breadth apart (`gap`, m), the first `lift` pulled out by `angle` degrees
    and let go.

    The balls' Hertz stiffness is 5·10⁹ N/m^{3/2}, a third of polished steel's (k = (4/3) E* √R*
    ≈ 1.5·10¹⁰ for two balls of 2 cm): each impact lasts about 1.5 times as long as steel's
    (t_c ∝ k^{-2/5}). The strings are stiff springs
    (stretch 0.01 % under a ball's weight) from pinned anchors
    (radius 2.5 mm, 40 cm above the balls: they touch nothing) spaced one diameter plus `gap`;
    the balls touch through :class:`~physcore.Contacts` with the `law` given and restitution
    0.999. With ``law="hertz"`` each impact is over before the next ball is reached, so the
    impulse passes down the row as a chain of two-ball collisions, as many balls leave the far
    end as were let go and the others stay at rest, touching; the soft linear law of
    ``law="linear"`` compresses each contact by more than the gap and spreads it (try
    ``--param law=linear``).

    The gap is the cradle's: with ``gap=0`` (balls pressed exactly together) the Hertz pulse,
    some five balls wide, is as long as the row, which fragments (Hinch & Saint-Jean, Proc. R.
    Soc. A 455 (1999) 3201; Hutzler et al., Am. J. Phys. 72 (2004) 1508): the ball before the
    last follows it at 13 % of the speed and the striker recoils at 7 %, so the resting balls
    swing apart within a swing. The default 0.2 mm is 1.5 times the deepest Hertz compression
    of an 80° release (0.14 mm; 0.06 mm at 30°) and a tenth of a pixel in the default render.

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    balls = _count(balls, "balls", 2)
    if balls > 50:
        raise InvalidInputError(f"balls: at most 50, got {balls}")
    lift = _count(lift, "lift", 1)
    if lift >= balls:
        raise InvalidInputError(f"lift: must be less than balls ({balls}), got {lift}")
    angle = _check.float_in_range("angle", angle, 0.0, 80.0)
    law = _check.choice("law", law, ("hertz", "linear"))
    gap = _check.float_in_range("gap", gap, 0.0, 0.02)
    dt = _optional(dt, "dt")
    r, m, L = 0.02, 0.26, 0.4
    k_string = m * 9.81 / (1e-4 * L)
    th = math.radians(angle)
    pitch = 2 * r + gap
    anchors = np.array([[pitch * i, 0.0] for i in range(balls)])
    hang = anchors + [0.0, -L]
    for i in range(lift):  # the lifted ones swing out together, `gap` apart
        hang[i] = anchors[i] + L * np.array([-math.sin(th), -math.cos(th)])
    x = np.concatenate([hang, anchors])
    scene = _grain_scene(dt, integrator, threads)
    scene.add_particles(x, masses=m, pinned=np.arange(2 * balls) >= balls)
    # The anchors are small pivots (2.5 mm, drawn as marks): 4 cm apart and 40 cm above the
    # balls, they touch nothing.
    scene.set_attribute("radius", np.concatenate([np.full(balls, r), np.full(balls, 0.125 * r)]))
    scene.add(Gravity([0.0, -9.81]))
    scene.add(Springs(np.arange(balls), np.arange(balls, 2 * balls), stiffness=k_string, damping=0.0, rest_length=L))
    stiffness = 5e9 if law == "hertz" else 1e6
    scene.add(Contacts(stiffness=stiffness, restitution=0.999, friction=0.0, law=law))
    # Polished steel balls on fine strings from brass pivots, in the cradle's frame (a top bar
    # on two posts over a base, clear of the swing) before a dark backdrop: the impulse shows in
    # the balls' motion, not in a colour map.
    reach = L * math.sin(th) + 2.5 * r  # the swing's reach beyond the row, and a margin
    left, right = -reach, pitch * (balls - 1) + reach
    floor = -L - r - 0.03
    post = 0.008
    decor = [
        {"polygon": _rect(left - 0.02, floor - 0.022, right + 0.02, floor), "color": (84, 56, 40)},  # a walnut base
        {"line": [[left - 0.02, floor], [right + 0.02, floor]], "color": (150, 110, 80), "width": 1},  # its lit edge
        {"polygon": _rect(left - post, floor, left, 0.012), "color": (150, 156, 170)},  # the posts
        {"polygon": _rect(right, floor, right + post, 0.012), "color": (150, 156, 170)},
        {"polygon": _rect(left - post, 0.0, right + post, 0.012), "color": (172, 178, 192)},  # the top bar
    ]
    scene.render_defaults = {
        "colors": [(206, 212, 224)] * balls + [(214, 170, 82)] * balls,
        "look": {"shading": "sphere", "spring_width": 1, "backdrop": ((64, 74, 98), (14, 16, 24)), "decor": decor},
    }
    return _auto_grain_dt(scene, dt)


def _rect(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    """The corners of the rectangle [x0, x1] × [y0, y1], in order around (a render prop)."""
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


newtons_cradle.render_defaults = {"antialias": True, "frames": 150, "fps": 30, "frame_time": 1 / 30, "size": (440, 300),
                                  "size_by": "radius", "color_by": "none"}
newtons_cradle = _stamped(newtons_cradle, old_order=('balls', 'lift', 'angle', 'law', 'integrator', 'dt', 'threads'), keep=1)


def jelly(
    n: int = 12,
    *,
    size: float = 0.3,
    mass: float = 1.0,
    stiffness: float = 120.0,
    damping: float = 0.1,
    height: float = 1.9,
    spin: float = -3.0,
    integrator: str | None = None,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Jelly: a soft square (n×n particles on springs) tumbling down a hill: it lands on one
    face after another, squashing and springing back, and bounces out onto the flat.

    2D. The body is the cloth's spring network (structural, shear and bend springs of
    `stiffness` N/m and `damping` N·s/m, rest lengths as built) over `mass` kg; its particles
    are grains of radius half their spacing under :class:`~physcore.Contacts` (k = 4·10⁴ N/m,
    restitution 0.3, friction 0.6), so it lands, squashes, rolls and wobbles on the ground,
    and cannot fold through itself. The ground is a 25° slope down to the floor y = 0 at x = 0,
    the floor, and a wall 8 sizes beyond the slope's foot (contact planes). The jelly starts on
    the slope, the middle of its lower side `height` m above the floor, turned 0.3 rad from
    the slope, moving down it at 1 m/s and turning at `spin` rad/s (negative: clockwise, the
    way it rolls). Drawn as a shaded surface (:class:`~physcore.render.Mesh`) in four layers of
    colour, a layered dessert's, so its bending and shear show (``--color-by strain`` shows the
    strain itself), followed by the camera.

    The springs carry the body's weight: standing on its lowest row, a body of springs alone
    shortens its lowest cells by 7 % at the default 120 N/m, and by 31 % at 30 N/m, the default
    before 2026-11-30. There most of the weight fell on the contacts of its own particles, which
    touch at rest: a square packing, which buckles, so its edges crumpled on each landing and
    stayed kinked (the sharpest bend along an edge at rest, t = 8 s: 9° then, 0° now).

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    n = _count(n, "n", 2)
    if n > 100:
        raise InvalidInputError(f"n: at most 100, got {n}")
    size = _check.float_in_range("size", size, 0.01, 10.0)
    mass = _check.float_in_range("mass", mass, 1e-6, 1e6)
    stiffness = _check.float_in_range("stiffness", stiffness, 1e-3, 1e7)
    # Bounded like the stiffness: the automatic step falls as 1/damping (3e303 gave dt = 2e-308).
    damping = _check.float_in_range("damping", damping, 0.0, 1e6)
    height = _check.float_in_range("height", height, 0.0, 100.0)
    spin = _check.float_in_range("spin", spin, -100.0, 100.0)
    s = size / (n - 1)
    m = mass / (n * n)
    g = (np.arange(n) - 0.5 * (n - 1)) * s
    gx, gy = np.meshgrid(g, g)
    local = np.stack([gx.ravel(), gy.ravel()], axis=1)
    slope = math.radians(25.0)
    normal = np.array([math.sin(slope), math.cos(slope)])  # the slope's, out of the ground
    downhill = np.array([math.cos(slope), -math.sin(slope)])
    th = 0.3 - slope
    rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    r = local @ rot.T
    along = height / math.sin(slope)  # from the slope's foot up to the start
    centre = along * -downhill + 0.9 * size * normal
    v = spin * np.stack([-r[:, 1], r[:, 0]], axis=1) + 1.0 * downhill
    scene = _grain_scene(dt, integrator, threads)
    scene.add_particles(centre + r, v, masses=m)
    scene.set_attribute("radius", np.full(n * n, 0.5 * s))
    i, j = cloth_springs(n)
    scene.add(Springs(i, j, stiffness=stiffness, damping=damping))
    scene.add(Gravity([0.0, -9.81]))
    # tangential_ratio 2/7 (the disc default is 1/3): its grains are nodes of one soft body, not
    # rolling discs, and at 1/3 the jelly of before issue 65 (dropped into a box) wobbled out to
    # 0.20 of the motion by the end (gallery budget 0.3); 2/7 kept the look it was measured with.
    ground = [Plane([0.0, 0.0], normal.tolist(), restitution=0.3, friction=0.6),
              Plane([0.0, 0.0], [0.0, 1.0], restitution=0.3, friction=0.6),
              Plane([8.0 * size, 0.0], [-1.0, 0.0], restitution=0.3, friction=0.6)]
    scene.add(Contacts(stiffness=4e4, restitution=0.3, friction=0.6, tangential_ratio=2.0 / 7.0, walls=ground))
    # A layered jelly (raspberry, orange, lemon, lime from the bottom row of the body up): the
    # bands bend and shear with it, where one colour showed a flat, featureless square
    # (--color-by strain shows the strain). Before a sky over the hill.
    layers = [(196, 28, 72), (240, 120, 40), (248, 204, 64), (110, 180, 60)]
    rows = np.repeat(np.arange(n), n) * len(layers) // n  # particle j·n + i is in row j
    scene.render_defaults = {"mesh": Mesh.grid(n, n), "colors": [layers[b] for b in rows.tolist()],
                             "look": {"backdrop": ((226, 236, 248), (250, 246, 240))}}
    # A 100th of a contact: the dashpots' rectangle-rule books then stay within 1e-3 of the
    # energy over the fall and the bounces (1.2e-3 at a 50th).
    return _auto_grain_dt(scene, dt, 0.5)


# 2.5 s: the tumble down the hill, one face after another, and the first bounces on the flat,
# with the camera following (it would leave a thumbnail-sized jelly in a wide, still view); the
# loop starts it again at the top.
jelly.render_defaults = {"antialias": True, "frames": 75, "fps": 30, "frame_time": 1 / 30, "size": (480, 320),
                         "color_by": "none", "camera": "follow"}
jelly = _stamped(jelly, old_order=('n', 'size', 'mass', 'stiffness', 'damping', 'height', 'spin', 'integrator', 'dt', 'threads'), keep=1)
