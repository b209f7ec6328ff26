"""The gallery measure: render every ready-made scene with its defaults, as a user would, and say
how each GIF fares against the gallery's budgets.

    python benches/render/gallery.py                  # every registered scene, into ./gallery/
    python benches/render/gallery.py kepler galaxies  # a subset
    python benches/render/gallery.py --out DIR

Each scene is rendered by the command a user types, ``physcore render NAME -o DIR/NAME.gif``, in
a fresh process (so the wall time includes the import and the scene's build). Then the GIF is
read back and measured:

- wall (s), frames, resolution, bytes;
- *motion to the end*: the mean absolute frame-to-frame difference over the last quarter of the
  animation divided by that over the rest (frames are resampled at the GIF's own playing clock,
  so frames Pillow merged count for the time they show). A GIF that freezes half-way scores ~0;
- *still tail* (s): how long the animation shows no change at its end (a frame step that
  changes the image by under 5 % of the median step before the last quarter counts as still, so
  a small subject's motion counts and a ticking clock does not);
- *active area*: the fraction of pixels whose colour changes at any time during the animation
  (static labels, colour bars, floors and backgrounds do not count);
- *coverage*: the mean fraction of pixels that differ from the background (the most common
  colour of the first frame).

The budgets (issue "A gallery people share"): wall ≤ 20 s on the project's 2-core machine,
GIF ≤ 3 MB, active area ≥ 15 %, and motion to the end ≥ 0.3 unless the scene's point is coming
to rest, in which case the GIF must end within 0.5 s of rest (still tail ≤ 0.5 s).

Writes, into the output folder: each GIF, a contact sheet ``NAME_sheet.png`` (frames at
5/35/65/99 %), ``index.html`` showing every GIF with its figures, ``gallery.md`` (the table)
and ``gallery.json``. Look at every sheet: the numbers catch heavy, slow and frozen GIFs, not
dull ones.
"""
from __future__ import annotations

import argparse
import html
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

BUDGET_WALL = 20.0  # s
BUDGET_BYTES = 3_000_000
BUDGET_ACTIVE = 0.15
BUDGET_MOTION = 0.3
BUDGET_TAIL = 0.5  # s of stillness allowed at the end of a scene that comes to rest
SHEET_AT = (0.05, 0.35, 0.65, 0.99)


def read_gif(path: Path) -> tuple[list[np.ndarray], list[float]]:
    """Every frame of the GIF at `path` as (H, W, 3) uint8 RGB, and each frame's duration (s)."""
    from PIL import Image, ImageSequence

    frames, durations = [], []
    with Image.open(path) as im:
        for fr in ImageSequence.Iterator(im):
            frames.append(np.asarray(fr.convert("RGB")))
            durations.append(fr.info.get("duration", 100) / 1000.0)
    return frames, durations


def resample(frames: list[np.ndarray], durations: list[float]) -> tuple[list[np.ndarray], float]:
    """The frames shown at a steady clock (the shortest frame's duration, at least 20 ms): a
    frame Pillow merged from identical ones shows for as many ticks as it lasted."""
    tick = max(0.02, min(durations))
    out = []
    for f, d in zip(frames, durations, strict=True):
        out.extend([f] * max(1, round(d / tick)))
    return out, tick


def measure(path: Path) -> dict:
    frames, durations = read_gif(path)
    h, w, _ = frames[0].shape
    seq, tick = resample(frames, durations)
    stack = np.stack(seq).astype(np.int16)  # (T, H, W, 3)
    diff = np.abs(np.diff(stack, axis=0)).mean(axis=(1, 2, 3)) if len(seq) > 1 else np.zeros(0)
    if diff.size >= 4:
        q = diff.size * 3 // 4
        rest = diff[:q].mean()
        motion_end = float(diff[q:].mean() / rest) if rest > 0 else 0.0
    else:
        motion_end = 0.0
    # Still: a frame step changing under 5 % of the typical (median) step before the last
    # quarter, so a small subject's motion counts and a ticking clock does not.
    typical = float(np.median(diff[: max(1, diff.size * 3 // 4)])) if diff.size else 0.0
    still = 0
    for c in diff[::-1]:
        if c > 0.05 * typical:
            break
        still += 1
    first = stack[0].reshape(-1, 3)
    colours, counts = np.unique(first, axis=0, return_counts=True)
    bg = colours[np.argmax(counts)]
    coverage = float((np.abs(stack - bg).max(axis=3) > 0).mean())
    active = float((stack != stack[0]).any(axis=(0, 3)).mean())
    return {
        "frames": len(frames), "size": f"{w}x{h}", "seconds": round(sum(durations), 2), "bytes": path.stat().st_size,
        "motion_end": round(motion_end, 3), "still_tail_s": round(still * tick, 2), "active": round(active, 3),
        "coverage": round(coverage, 3),
    }


def contact_sheet(path: Path, out: Path) -> None:
    from PIL import Image

    frames, durations = read_gif(path)
    seq, _ = resample(frames, durations)
    picks = [seq[min(len(seq) - 1, int(a * len(seq)))] for a in SHEET_AT]
    h, w, _ = picks[0].shape
    sheet = np.full((h, 4 * w + 3 * 4, 3), 128, np.uint8)
    for k, p in enumerate(picks):
        sheet[:, k * (w + 4) : k * (w + 4) + w] = p
    Image.fromarray(sheet).save(out)


#: The README's thumbnails together (docs/gallery/*.gif; tests/scenes/test_docs.py holds them to
#: 5 MB): each scene gets an equal share of this, at most THUMB_MAX_BYTES, so the gallery fits with
#: room to spare however the scenes change, and every thumbnail is made by one rule.
THUMBS_BUDGET = 4_800_000
THUMB_MAX_BYTES = 200_000


def thumb_share(n_scenes: int | None = None) -> int:
    """Bytes one README thumbnail may take: an equal share of THUMBS_BUDGET among `n_scenes`
    (default: every registered scene), at most THUMB_MAX_BYTES (32 scenes: 150 000)."""
    if n_scenes is None:
        import physcore as pc

        n_scenes = len(pc.scenes.REGISTRY)
    return min(THUMB_MAX_BYTES, THUMBS_BUDGET // max(1, n_scenes))


def thumbnail(path: Path, out: Path, width: int = 240, max_bytes: int | None = None) -> int:
    """A small copy of the GIF at `path` for the README's gallery, at most `max_bytes` (default:
    `thumb_share()`): the first of these that fits, `width` pixels wide with 255 then 64 colours
    (one palette fitted to the whole animation), every frame or every 2nd or 3rd at the same
    playing time, then narrower (5/6, 2/3, 1/2 of `width`) and sparser. Returns its size in bytes.

    The palette is cut by median cut at 255 colours and by octree below: median cut splits by
    pixel count, so at 64 or 32 colours it merged small saturated subjects into the background's
    shades (tumbling_boxes' boxes grey, pythagorean's bodies beige); octree keeps them."""
    from PIL import Image

    if max_bytes is None:
        max_bytes = thumb_share()
    frames, durations = read_gif(path)
    h, w, _ = frames[0].shape
    tries = [(width, c, k) for c in (255, 64) for k in (1, 2, 3)]
    tries += [(width * 5 // 6, 64, k) for k in (2, 3, 4)] + [(width * 2 // 3, 32, k) for k in (3, 4, 5, 6, 7, 8)]
    tries += [(width // 2, 32, 4), (width // 2, 16, 8)]
    cache: dict[int, list[np.ndarray]] = {}
    for wide, colours, stride in tries:
        if wide not in cache:
            size = (wide, max(16, round(h * wide / w)))
            cache[wide] = [np.asarray(Image.fromarray(f).resize(size, Image.Resampling.LANCZOS)) for f in frames]
        small = cache[wide]
        picks = list(range(0, len(small), stride))
        mosaic = Image.fromarray(np.concatenate([small[k] for k in picks[:: max(1, len(picks) // 12)]], axis=0))
        method = Image.Quantize.MEDIANCUT if colours > 128 else Image.Quantize.FASTOCTREE
        pal = mosaic.quantize(colours, method=method, dither=Image.Dither.NONE)
        seq = [Image.fromarray(small[k]).quantize(palette=pal, dither=Image.Dither.NONE) for k in picks]
        dur = [round(1000 * sum(durations[k : k + stride])) for k in picks]
        seq[0].save(out, save_all=True, append_images=seq[1:], duration=dur, loop=0, optimize=False, disposal=1)
        if out.stat().st_size <= max_bytes:
            break
    return out.stat().st_size


#: The README's gallery order: the showcase first.
README_ORDER = ("galaxies", "dam_break", "double_pendulum", "cloth_on_ball", "vortex_street", "drop", "lorenz", "turing",
                "smoke", "crown", "kepler", "figure_eight", "pythagorean", "cyclotron", "billiards", "newtons_cradle",
                "galton_board", "cloth", "xpbd_cloth", "projectile", "droplets", "jelly", "tumbling_boxes", "spring_chain",
                "ripple", "double_slit", "cavity")


def readme_block(names: list[str], columns: int = 3) -> str:
    """The README's gallery: an HTML table of thumbnails (docs/gallery/NAME.gif), each over the
    one command that makes it, `columns` to a row."""
    order = [n for n in README_ORDER if n in names] + [n for n in names if n not in README_ORDER]
    rows = []
    for k in range(0, len(order), columns):
        cells = "".join(f'<td align="center"><img src="docs/gallery/{n}.gif" width="240" alt="{n}"><br>'
                        f"<code>physcore render {n}</code></td>" for n in order[k : k + columns])
        rows.append(f"<tr>{cells}</tr>")
    return "<table>\n" + "\n".join(rows) + "\n</table>"


def write_readme(readme: Path, names: list[str]) -> None:
    """Replace the README's gallery (between ``<!-- gallery -->`` and ``<!-- /gallery -->``)."""
    text = readme.read_text()
    a, b = text.index("<!-- gallery -->") + len("<!-- gallery -->"), text.index("<!-- /gallery -->")
    readme.write_text(text[:a] + "\n" + readme_block(names) + "\n" + text[b:])


def verdict(row: dict) -> list[str]:
    """The budgets `row` misses, as short phrases (empty: within every budget)."""
    miss = []
    if row["wall_s"] > BUDGET_WALL:
        miss.append(f"wall {row['wall_s']:.0f} s")
    if row["bytes"] > BUDGET_BYTES:
        miss.append(f"{row['bytes'] / 1e6:.1f} MB")
    if row["active"] < BUDGET_ACTIVE:
        miss.append(f"active {row['active']:.0%}")
    # Motion to the end, or a scene that comes to rest (a still tail) and ends within 0.5 s of it.
    if row["motion_end"] < BUDGET_MOTION and not 0 < row["still_tail_s"] <= BUDGET_TAIL:
        what = "frozen end" if row["still_tail_s"] > BUDGET_TAIL else "fading end"
        miss.append(f"{what} (motion {row['motion_end']:.2f}, still {row['still_tail_s']:.1f} s)")
    return miss


def render(name: str, out: Path) -> dict:
    gif = out / f"{name}.gif"
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "physcore", "render", name, "-o", str(gif), "-q"],
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        return {"scene": name, "error": (proc.stderr or proc.stdout).strip().splitlines()[-1:], "wall_s": round(wall, 1)}
    row = {"scene": name, "wall_s": round(wall, 1), **measure(gif)}
    contact_sheet(gif, out / f"{name}_sheet.png")
    row["misses"] = verdict(row)
    return row


def table(rows: list[dict]) -> str:
    lines = ["| scene | wall s | frames | size | GIF MB | motion to end | still tail s | active | coverage | budgets |",
             "|---|---:|---:|---|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['scene']} | {r['wall_s']} | | | | | | | | error: {' '.join(r['error'])} |")
            continue
        lines.append(
            f"| {r['scene']} | {r['wall_s']:.1f} | {r['frames']} | {r['size']} | {r['bytes'] / 1e6:.2f} | "
            f"{r['motion_end']:.2f} | {r['still_tail_s']:.1f} | {r['active']:.0%} | {r['coverage']:.0%} | "
            f"{'ok' if not r['misses'] else '; '.join(r['misses'])} |"
        )
    return "\n".join(lines)


def page(rows: list[dict]) -> str:
    cells = []
    for r in rows:
        if "error" in r:
            cells.append(f"<figure><figcaption>{html.escape(r['scene'])}: error</figcaption></figure>")
            continue
        figs = (f"{r['wall_s']:.1f} s · {r['bytes'] / 1e6:.2f} MB · motion {r['motion_end']:.2f} · "
                f"active {r['active']:.0%} · coverage {r['coverage']:.0%}")
        cells.append(f'<figure><img src="{html.escape(r["scene"])}.gif" loading="lazy">'
                     f"<figcaption><b>{html.escape(r['scene'])}</b><br><code>physcore render {html.escape(r['scene'])}</code>"
                     f"<br>{html.escape(figs)}</figcaption></figure>")
    return ("<!doctype html><meta charset=utf-8><title>physcore gallery</title><style>"
            "body{font-family:sans-serif;background:#f4f4f4}main{display:flex;flex-wrap:wrap;gap:12px}"
            "figure{margin:0;background:#fff;padding:8px}img{display:block;max-width:480px}</style>"
            "<h1>physcore gallery</h1><main>" + "".join(cells) + "</main>")


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import physcore as pc

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benches/: _common
    from _common import header

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", help="scene names (default: every registered scene)")
    ap.add_argument("--out", default="gallery", help="output folder (default ./gallery)")
    ap.add_argument("--thumbs", metavar="DIR", help="also write README thumbnails (240 px, an equal share of 4.8 MB each) into DIR")
    ap.add_argument("--readme", metavar="README", help="with --thumbs: rewrite README's gallery table (between its markers)")
    args = ap.parse_args(argv)
    names = args.scenes or list(pc.scenes.REGISTRY)
    unknown = [n for n in names if n not in pc.scenes.REGISTRY]
    if unknown:
        ap.error(f"unknown scene(s): {', '.join(unknown)}; choose from {', '.join(pc.scenes.REGISTRY)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(header(), flush=True)
    rows = []
    for name in names:
        row = render(name, out)
        rows.append(row)
        print(f"{name:16s} " + ("error" if "error" in row else f"{row['wall_s']:6.1f} s  {row['bytes'] / 1e6:5.2f} MB  "
              f"motion {row['motion_end']:.2f}  active {row['active']:.0%}  coverage {row['coverage']:.0%}  "
              f"{'ok' if not row['misses'] else '; '.join(row['misses'])}"), flush=True)
    if args.thumbs:
        thumbs = Path(args.thumbs)
        thumbs.mkdir(parents=True, exist_ok=True)
        for r in rows:
            if "error" not in r:
                r["thumb_bytes"] = thumbnail(out / f"{r['scene']}.gif", thumbs / f"{r['scene']}.gif")
        print(f"thumbnails: {sum(r.get('thumb_bytes', 0) for r in rows) / 1e6:.2f} MB in {thumbs}")
        if args.readme:
            write_readme(Path(args.readme), [r["scene"] for r in rows if "thumb_bytes" in r])
    text = table(rows)
    ok = sum(1 for r in rows if "error" not in r and not r["misses"])
    summary = f"{ok} of {len(rows)} scenes within every budget"
    (out / "gallery.md").write_text(header() + "\n\n" + text + "\n\n" + summary + "\n")
    (out / "gallery.json").write_text(json.dumps(rows, indent=1))
    (out / "index.html").write_text(page(rows))
    print("\n" + text + "\n\n" + summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
