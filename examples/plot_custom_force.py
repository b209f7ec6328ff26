"""
A force of your own from existing parts
=======================================

A potential landscape written as a function, sampled on a grid and handed to
:class:`physcore.PotentialGrid`: the double well ``phi = 3 (x^2 - 1)^2 + 2 y^2`` (J/kg).
Thirty charged particles fall into it; :class:`physcore.Coulomb` makes them repel each
other and :class:`physcore.Drag` lets them settle, so they end as two charged clusters, one
in each well, each spread out by the repulsion. Every part books its energy:
``scene.energy()`` shows the landscape's, the charges' and what the drag took.

The build uses 60 frames of 240 x 180 pixels to stay quick.
"""
import numpy as np

import physcore as pc

ax = np.linspace(-2.0, 2.0, 81)
X, Y = np.meshgrid(ax, ax, indexing="ij")
landscape = pc.PotentialGrid(3 * (X**2 - 1) ** 2 + 2 * Y**2, spacing=ax[1] - ax[0], origin=-2.0)

rng = np.random.default_rng(1)
scene = pc.Scene(dim=2, dt=2e-3)
scene.add_particles(rng.uniform(-1.5, 1.5, (30, 2)), masses=1.0)
scene.set_attribute("charge", np.full(30, 1.0))  # C, in units where k = 1
scene.add(landscape)
scene.add(pc.Coulomb(k=0.02, softening=0.05))
scene.add(pc.Drag(0.8))

pc.render.gif(scene, "custom_force.gif", frames=60, frame_time=0.1, size=(240, 180), trail=8)
energy = scene.energy()
print(f"potential: {energy.potential}, taken by the drag: {energy.dissipated['drag']:.2f} J")
