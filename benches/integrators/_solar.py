"""Shared initial conditions: the outer Solar System (Sun + Jupiter, Saturn, Uranus, Neptune).

Units: G = 1, M_sun = 1, AU, time unit = yr / 2pi (REBOUND's default G = 1 system). Masses
(M_sun) and approximate J2000 heliocentric elements (a AU, e, inc, Omega, omega, M in degrees)
are fixed constants, turned into Cartesian coordinates once by REBOUND and moved to the
barycentre; both codes start from these exact float64 arrays."""
from __future__ import annotations

import math

import numpy as np

YEAR = 2 * math.pi  # time units per year

PLANETS = [  # m, a, e, inc, Omega, omega, M
    (9.547919e-4, 5.2026, 0.04839, 1.3053, 100.47, 273.87, 20.02),   # Jupiter
    (2.858860e-4, 9.5549, 0.05551, 2.4845, 113.66, 339.39, 317.02),  # Saturn
    (4.366244e-5, 19.2184, 0.04630, 0.7699, 74.01, 96.99, 142.24),   # Uranus
    (5.151389e-5, 30.1104, 0.00899, 1.7692, 131.78, 273.19, 256.23), # Neptune
]


def initial_state(n_planets: int = 4):
    """(x, v, m): barycentric positions, velocities (N, 3) and masses (N,)."""
    import rebound

    sim = rebound.Simulation()
    sim.G = 1.0
    sim.add(m=1.0)
    d = math.radians
    for m, a, e, inc, Om, om, M in PLANETS[:n_planets]:
        sim.add(m=m, a=a, e=e, inc=d(inc), Omega=d(Om), omega=d(om), M=d(M))
    sim.move_to_com()
    xv = np.zeros((sim.N, 6))
    sim.serialize_particle_data(xyzvxvyvz=xv)
    m = np.array([p.m for p in sim.particles])
    return xv[:, :3].copy(), xv[:, 3:].copy(), m
