"""Ready-made scenes: functions returning a :class:`~physcore.Scene`. Each is also a CLI name
(``physcore render NAME``); keyword arguments are CLI ``--param key=value`` options.

Every function accepts ``integrator=`` and ``dt=`` (``None``: the scene's own choice) and
``threads=``. ``render_defaults`` on each function gives the CLI's animation defaults
(``frame_time`` is simulated seconds per frame).

Every function raises, before building anything, ``TypeError`` for an argument of the wrong type
(``str``, ``bool`` or ``None`` where a number is meant, anything but True/False for a flag) and
:class:`~physcore.InvalidInputError` (a ``ValueError``) for a value out of range or one whose
consequences float64 cannot hold: a particle mass whose reciprocal overflows, a spacing or
stable time step below the normal range, energy books beyond float64, or more particles than
fit in memory (about 512 B each and 256 B per spring, against half the physical memory). The
message names the arguments involved.

Layout
------
A package, one module per family of scenes. Each imports only ``_common`` (the shared argument
checks and ``_stamped``, which gives every scene function its ``render_defaults``) and
physcore's other modules, never this package. The scene functions are defined there and
re-exported here, with ``__module__`` set to this package, so that they read, pickle and
document as ``physcore.scenes.NAME``. The geometry they are built from (lattices, tanks, blobs,
Plummer spheres, cloth springs, mesh hinges) is public in :mod:`physcore.shapes`.

cloth        cloth, cloth_on_ball, xpbd_cloth
orbits       projectile, kepler, figure_eight, pythagorean, galaxies
charges      cyclotron
springs      spring_chain
fluids       dam_break, drop, droplets, crown (SPH), floating (with rigid bodies)
grids        ripple, double_slit, turing, smoke, cavity, vortex_street
flows        lorenz
grains       galton_board, galton_bins, billiards, newtons_cradle, jelly (DEM)
constraints  shape_matched_boxes (XPBD shape matching), double_pendulum (stiff rods)
bodies       dominoes, pyramid, tumbling_boxes, tablecloth (rigid bodies, rapier)
"""
from __future__ import annotations

from collections.abc import Callable

from .._errors import refusing_memory
from ..scene import Scene
from ..shapes import cloth_springs as cloth_springs
from ..shapes import mesh_edges_and_hinges as mesh_edges_and_hinges
from ..shapes import plummer_sphere
from .bodies import dominoes, pyramid, tablecloth, tumbling_boxes
from .charges import CHARGE_COLORS as CHARGE_COLORS
from .charges import cyclotron
from .cloth import cloth, cloth_on_ball, xpbd_cloth
from .constraints import double_pendulum, shape_matched_boxes
from .flows import lorenz
from .fluids import crown, dam_break, drop, droplets, floating
from .grains import GALTON_COLORS as GALTON_COLORS
from .grains import billiards, galton_bins, galton_board, jelly, newtons_cradle
from .grids import cavity, double_slit, ripple, smoke, turing, vortex_street
from .orbits import FIGURE_EIGHT_PERIOD as FIGURE_EIGHT_PERIOD
from .orbits import FIGURE_EIGHT_V3 as FIGURE_EIGHT_V3
from .orbits import FIGURE_EIGHT_X1 as FIGURE_EIGHT_X1
from .orbits import GALAXY_COLORS as GALAXY_COLORS
from .orbits import KEPLER_COLORS as KEPLER_COLORS
from .orbits import KEPLER_RANGE as KEPLER_RANGE
from .orbits import figure_eight, galaxies, kepler, projectile, pythagorean
from .springs import spring_chain

__all__ = [
    "cloth", "projectile", "kepler", "spring_chain", "dam_break", "drop", "droplets", "crown", "figure_eight", "pythagorean",
    "galaxies", "cyclotron", "lorenz", "plummer_sphere", "galton_board", "galton_bins", "billiards", "newtons_cradle", "jelly",
    "xpbd_cloth", "tumbling_boxes", "cloth_on_ball", "ripple", "double_slit", "turing", "smoke", "cavity", "vortex_street",
    "double_pendulum", "dominoes", "pyramid", "floating", "shape_matched_boxes", "tablecloth", "REGISTRY", "DEFAULT_SCENE",
]

#: Scene name → function, in the order ``physcore scenes`` lists them.
REGISTRY: dict[str, Callable[..., Scene]] = {
    "cloth": cloth,
    "projectile": projectile,
    "kepler": kepler,
    "figure_eight": figure_eight,
    "pythagorean": pythagorean,
    "galaxies": galaxies,
    "cyclotron": cyclotron,
    "spring_chain": spring_chain,
    "dam_break": dam_break,
    "drop": drop,
    "droplets": droplets,
    "crown": crown,
    "ripple": ripple,
    "double_slit": double_slit,
    "turing": turing,
    "smoke": smoke,
    "cavity": cavity,
    "lorenz": lorenz,
    "galton_board": galton_board,
    "billiards": billiards,
    "newtons_cradle": newtons_cradle,
    "jelly": jelly,
    "xpbd_cloth": xpbd_cloth,
    "tumbling_boxes": tumbling_boxes,
    "cloth_on_ball": cloth_on_ball,
    "double_pendulum": double_pendulum,
    "vortex_street": vortex_street,
    "dominoes": dominoes,
    "pyramid": pyramid,
    "floating": floating,
    "shape_matched_boxes": shape_matched_boxes,
    "tablecloth": tablecloth,
}
#: The scene `physcore render` and `physcore view` show when none is named.
DEFAULT_SCENE = "cloth"

# A bare MemoryError of numpy's while a scene's arrays are built becomes OutOfMemoryError naming
# the scene, as the core's refusals read (pyramid(rows=2000) under a memory limit raised numpy's).
for _name, _f in (*REGISTRY.items(), ("galton_bins", galton_bins)):
    _w = refusing_memory(f"scenes.{_name}", "the scene's arrays")(_f)
    globals()[_name] = _w
    if _name in REGISTRY:
        REGISTRY[_name] = _w
galton_bins = globals()["galton_bins"]
del _name, _f, _w

# Defined in the family modules, public here: they read, pickle and document as physcore.scenes.NAME.
for _public in (*REGISTRY.values(), galton_bins):
    _public.__module__ = __name__
del _public
