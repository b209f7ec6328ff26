"""Drawing a million-particle liquid: seconds to turn a 3D dam break's 120-frame recording into a
GIF (the lit surface in a glass tank, the default render's look), by drawing threads.

Run: python benches/render/bench_liquid_draw.py [--copies 5] [--frames 120] [--rounds 3]

The issue "GPU fluids, grains and batches" asks that a GIF of a 10⁶-particle scene be dominated
by the simulation, not the drawing. A CPU cannot simulate that scene in a bench's time, so the
recording is made from the default 3D dam break (n = 16, 8,192 particles, simulated here, about
4 s) with each particle replaced by copies³ particles at a spacing 1/copies of its own (copies = 5:
1,024,000, the device scene's n = 80) and the tank's walls those of ``dam_break(dim=3, n=80)``
(752,856 boundary particles, built, not stepped). Each round draws the GIF with 1 drawing thread
and then with the default count (``physcore.render._threads.workers()``: the cores, at most 8),
alternating; the table gives the medians and the ratio, and checks that both GIFs have the same
bytes.
"""
from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common

from _common import header, require_release, table  # first: sets up the environment before numpy loads
import numpy as np

import physcore as pc
from physcore.render import _threads


def recording(copies: int, frames: int):
    small = pc.scenes.dam_break(dim=3)
    rec = pc.render.record(small, frames=frames)
    big = pc.scenes.dam_break(dim=3, n=16 * copies)
    walls = np.asarray(big.boundary_points(), dtype=np.float64) - rec.origin
    dx = 1.0 / 16
    o = ((np.arange(copies) - (copies - 1) / 2) / copies * dx).astype(np.float32)
    off = np.stack(np.meshgrid(o, o, o, indexing="ij"), -1).reshape(-1, 3)
    f, n, _ = rec.positions.shape
    pos = (rec.positions[:, :, None, :] + off[None, None]).reshape(f, n * len(off), 3)
    return rec._replace(positions=pos, speeds=np.repeat(rec.speeds, len(off), axis=1), walls=walls,
                        pinned=np.zeros(n * len(off), bool), masses=None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--copies", type=int, default=5, help="copies per axis of each particle (5: 1,024,000)")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    require_release()
    default = _threads.workers()
    print(header() + f"; drawing threads: 1 and {default}")
    t0 = time.perf_counter()
    rec = recording(a.copies, a.frames)
    print(f"recording: {rec.positions.shape[1]:,} particles, {len(rec.walls):,} wall particles, "
          f"{rec.frames} frames (made in {time.perf_counter() - t0:.1f} s)")
    times: dict[int, list[float]] = {1: [], default: []}
    digests: dict[int, set[str]] = {1: set(), default: set()}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(a.rounds):
            for n in times:
                _threads.workers = lambda n=n: n
                path = os.path.join(tmp, f"{n}.gif")
                t = time.perf_counter()
                pc.render.gif(rec, path)
                times[n].append(time.perf_counter() - t)
                digests[n].add(hashlib.sha256(open(path, "rb").read()).hexdigest()[:12])
                size = os.path.getsize(path)
    med = {n: statistics.median(v) for n, v in times.items()}
    rows = [[str(n), f"{med[n]:.2f}", f"{min(v):.2f}–{max(v):.2f}", f"{med[1] / med[n]:.2f}", ", ".join(sorted(digests[n]))]
            for n, v in times.items()]
    print(table(["threads", "median s", "range s", "speed-up", "sha256"], rows))
    print(f"GIF {size:,} bytes; same bytes for every thread count: {len(digests[1] | digests[default]) == 1}")


if __name__ == "__main__":
    main()
