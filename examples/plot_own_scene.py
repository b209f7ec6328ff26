"""
Your own scene in ten lines
===========================

A chain of particles joined by springs, pinned at one end, swinging down under gravity
onto a floor. A :class:`physcore.Scene` is particles plus parts: here
:class:`physcore.Springs`, :class:`physcore.Gravity` and a floor, :class:`physcore.Plane`.
:func:`physcore.render.gif` steps it and writes the animation.

The build uses 60 frames of 240 x 180 pixels to stay quick; leave ``frames`` and ``size``
out for the defaults (90 frames, 480 x 360).
"""
import numpy as np

import physcore as pc

n = 12
scene = pc.Scene(dim=2, dt=1e-3)
scene.add_particles(np.column_stack([np.linspace(0.0, 1.1, n), np.full(n, 1.0)]),
                    pinned=[True] + [False] * (n - 1))
scene.add(pc.Springs(np.arange(n - 1), np.arange(1, n), stiffness=2000.0, damping=0.5))
scene.add(pc.Gravity([0.0, -9.81]))
scene.add(pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=0.3, friction=0.2))

pc.render.gif(scene, "own_scene.gif", frames=60, size=(240, 180))
print(f"t = {scene.time:.2f} s, energy drift {scene.energy_drift():+.2%}")
