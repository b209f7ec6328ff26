"""Force terms and colliders: plain, immutable descriptions that a :class:`~physcore.Scene` adds.

A scene computes only the terms it holds. Every term validates its own arguments when it is
constructed; what depends on the scene (dimension, particle indices) is checked by
:meth:`Scene.add`, before anything changes.

Examples
--------
>>> import physcore as pc
>>> scene = pc.Scene(dim=2, dt=1e-3, threads=1)
>>> scene.add_particles([[0.0, 1.0]], [[1.0, 0.0]], masses=[2.0])
array([0])
>>> scene.add(pc.Gravity([0.0, -9.81]))
Gravity(g=array([ 0.  , -9.81]), name='gravity')
>>> _ = scene.add(pc.Plane(point=[0.0, 0.0], normal=[0.0, 1.0], restitution=0.5))
>>> scene.step(100)
>>> round(scene.time, 6), bool(scene.positions[0, 1] < 1.0)
(0.1, True)
>>> pc.Gravity([0.0, float("nan")])
Traceback (most recent call last):
...
physcore._errors.InvalidInputError: g: must be finite, got [0.0, nan]
"""
from __future__ import annotations

# The records' annotations are strings (PEP 563), which typing.get_type_hints resolves in the
# namespace of the record's __module__ (this package, below): it holds the names they use.
from dataclasses import KW_ONLY  # noqa: F401
from typing import Any, ClassVar  # noqa: F401

import numpy as np  # noqa: F401

# One module per family of records; a family imports ._base and physcore's own modules, never this
# package. They are imported here in the order their records were defined, which is the order of
# REGISTRY and of the scene-file parts (physcore._parts.PARTS):
#   _base       Term, REGISTRY and the argument checks the families share
#   fields      Gravity, Drag
#   springs     Springs
#   nbody       PairwiseGravity, TreeGravity
#   charges     ElectricField, Coulomb, COULOMB_K, MagneticField, GridElectricField, GridMagneticField
#   xpbd        XpbdConstraints
#   colliders   Plane, Box, Sphere
# isort: off
from . import _base, fields, springs, nbody, charges, xpbd, colliders, capsule, oriented_box  # noqa: F401 - in this order
# isort: on
from ._base import REGISTRY as REGISTRY
from ._base import ArrayLike as ArrayLike
from ._base import LiveParam as LiveParam
from ._base import Term
from ._base import _finite_float as _finite_float
from ._base import _hashable as _hashable
from ._base import _int_array as _int_array
from ._base import _per_spring as _per_spring
from ._base import _same as _same
from ._base import _same_dim as _same_dim
from ._base import _vector as _vector
from .capsule import Capsule
from .charges import COULOMB_K as COULOMB_K
from .charges import Coulomb, ElectricField, GridElectricField, GridMagneticField, MagneticField
from .charges import _axial as _axial
from .charges import _axial_for as _axial_for
from .charges import _grid_frame as _grid_frame
from .charges import _grid_values as _grid_values
from .charges import _GridField as _GridField
from .colliders import Box, Collider, Plane, Sphere
from .fields import Drag, Gravity
from .nbody import PairwiseGravity, TreeGravity
from .oriented_box import OrientedBox
from .springs import Springs
from .xpbd import XpbdConstraints
from .xpbd import _angles as _angles
from .xpbd import _cross2 as _cross2
from .xpbd import _index_rows as _index_rows
from .xpbd import _per_row as _per_row

__all__ = [
    "Term",
    "Gravity",
    "Drag",
    "Springs",
    "PairwiseGravity",
    "TreeGravity",
    "ElectricField",
    "Coulomb",
    "MagneticField",
    "GridElectricField",
    "GridMagneticField",
    "XpbdConstraints",
    "Plane",
    "Box",
    "Sphere",
    "Collider",
    "Capsule",
    "OrientedBox",
]


# Pickles record a class by its module path: the records keep the path they had as one module
# (physcore.terms), so old pickles load and new ones are byte-identical.
for _public in (Term, Gravity, Drag, Springs, PairwiseGravity, TreeGravity, ElectricField, Coulomb, MagneticField, GridElectricField, GridMagneticField, XpbdConstraints, Plane, Box, Sphere, Collider, Capsule, OrientedBox):
    _public.__module__ = __name__
del _public
