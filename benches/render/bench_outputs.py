"""File size and render time of each output format for the default cloth animation (4 s, 120
frames, 480×360, as `physcore render cloth`: a shaded sheet; and as discs and springs), beside the seed's own approach: matplotlib
``FuncAnimation`` + ``PillowWriter`` drawing the same recorded frames (a scatter of the particles
coloured by speed, the springs as a LineCollection, same size and fps).

    python benches/render/bench_outputs.py [--repeats 3]

The scene is recorded once; every writer then draws that recording (the times are drawing and
encoding only, median of the repeats). Writes the files into a temporary directory, and a
contact sheet of the two GIFs side by side when --sheet PATH.gif is given.
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

import _common

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import physcore as pc


def matplotlib_gif(rec, path: Path, size=(480, 360), fps=30.0) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.collections import LineCollection

    dpi = 100
    fig, ax = plt.subplots(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
    x = rec.positions.astype(np.float64)
    lo, hi = x.reshape(-1, x.shape[2]).min(0), x.reshape(-1, x.shape[2]).max(0)
    # The cloth is 3D: the same oblique view as physcore's default camera would be a projection;
    # for a fair cost comparison, draw x against z (a side view), as a seed script would.
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[-1], hi[-1])
    ax.set_aspect("equal")
    ax.axis("off")
    i, j = rec.pairs
    lines = LineCollection([], linewidths=0.5, colors="0.6")
    ax.add_collection(lines)
    vmax = float(np.percentile(rec.speeds, 99)) or 1.0
    dots = ax.scatter(x[0, :, 0], x[0, :, -1], c=rec.speeds[0], s=6, cmap="viridis", vmin=0, vmax=vmax)

    def update(k):
        p = x[k][:, [0, -1]]
        lines.set_segments(np.stack([p[i], p[j]], axis=1))
        dots.set_offsets(p)
        dots.set_array(rec.speeds[k])
        return lines, dots

    anim = FuncAnimation(fig, update, frames=rec.frames, blit=False)
    anim.save(str(path), writer=PillowWriter(fps=fps))
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sheet", default=None, help="also write a contact sheet of both GIFs here (.gif)")
    args = ap.parse_args()
    _common.require_release()
    scene = pc.scenes.cloth()
    t0 = time.perf_counter()
    # Speeds recorded too (for the matplotlib peer and the discs); the sheet is drawn in its
    # default fabric colour (color_by="none").
    rec = pc.render.record(scene, color_by="speed")
    record_s = time.perf_counter() - t0
    tmp = Path(tempfile.mkdtemp(prefix="bench-outputs-"))
    writers = [
        ("physcore GIF (shaded sheet, the default)", "cloth.gif", lambda p: pc.render.save(rec, p, color_by="none")),
        ("physcore GIF, discs and springs by speed (mesh=False)", "discs.gif", lambda p: pc.render.save(rec, p, mesh=False)),
        ("physcore MP4 (H.264, CRF 26)", "cloth.mp4", lambda p: pc.render.save(rec, p, color_by="none")),
        ("physcore WebM (VP9, CRF 32)", "cloth.webm", lambda p: pc.render.save(rec, p, color_by="none")),
        ("physcore PNG frames", "cloth.png", lambda p: pc.render.save(rec, p, color_by="none")),
        ("physcore frames() (RGB arrays)", None, lambda p: sum(f.nbytes for f in pc.render.frames(rec, color_by="none"))),
        ("matplotlib FuncAnimation + PillowWriter GIF", "mpl.gif", lambda p: matplotlib_gif(rec, p)),
    ]
    times: dict[str, list[float]] = {w[0]: [] for w in writers}
    for _ in range(args.repeats):
        for name, fname, write in writers:
            t = time.perf_counter()
            write(tmp / fname if fname else None)
            times[name].append(time.perf_counter() - t)
    rows = []
    for name, fname, _ in writers:
        if fname is None:
            size = "–"
        elif fname.endswith(".png"):
            size = _common.si(sum(p.stat().st_size for p in tmp.glob("cloth_*.png"))) + "B (120 files)"
        else:
            size = _common.si((tmp / fname).stat().st_size) + "B"
        med = statistics.median(times[name])
        rows.append([name, size, f"{med:.2f}", f"{1e3 * med / rec.frames:.1f}"])
    print(_common.header())
    print(f"Default cloth: {rec.frames} frames, 480x360, 30 fps; recorded once in {record_s:.1f} s (not counted); "
          f"median of {args.repeats}\n")
    print(_common.table(["writer", "file size", "draw + encode, s", "per frame, ms"], rows))
    if args.sheet:
        # Both GIFs side by side, on one clock: decode and tile them.
        from PIL import Image, ImageSequence

        ims = []
        for f in ("cloth.gif", "mpl.gif"):
            with Image.open(tmp / f) as im:
                ims.append([np.asarray(fr.convert("RGB")) for fr in ImageSequence.Iterator(im)])
        n = min(len(a) for a in ims)
        h = max(a[0].shape[0] for a in ims)
        frames = []
        for k in range(n):
            tiles = [np.pad(a[k], ((0, h - a[k].shape[0]), (0, 2), (0, 0)), constant_values=128) for a in ims]
            frames.append(Image.fromarray(np.concatenate(tiles, axis=1)).quantize(colors=255))
        frames[0].save(args.sheet, save_all=True, append_images=frames[1:], duration=int(1000 / 30), loop=0)
        print(f"\nwrote {args.sheet} (left: physcore, right: matplotlib)")
    for p in tmp.iterdir():
        os.unlink(p)
    tmp.rmdir()


if __name__ == "__main__":
    main()
