"""Contact sheets: several scenes' animations side by side in one GIF (the variants of a sweep).

Each tile is an ordinary :func:`gif` of its scene at the tile's size (so every default, theme,
trail and field style applies), rendered where the sweep's runs go (this process, or Dask
workers, which send back the small GIF files), then decoded, placed on a grid on the same
clock, labelled, and written with one palette fitted to the whole sheet.
"""
from __future__ import annotations

import io
import os
import pickle
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import _check
from .._atomic import atomic_write
from .._errors import InvalidInputError, InvalidTypeError
from ._checks import _check_fps, _check_path, _check_size, _check_writable
from ._colorbar import _font
from ._gif import _OPTIONS, _gif_delays_ms, _palette_frames, gif
from ._recording import scene_defaults

#: Pixels between tiles.
GAP = 2


def _render_tile(data: bytes, size: tuple[int, int], fps: float, options: dict[str, Any]) -> bytes:
    """One tile: the pickled scene drawn by gif() into a temporary file; its bytes."""
    scene = pickle.loads(data)
    with tempfile.TemporaryDirectory(prefix="physcore-sheet-") as tmp:
        out = gif(scene, os.path.join(tmp, "tile.gif"), size=size, fps=fps, **options)
        return out.read_bytes()


def _decode(data: bytes) -> tuple[list[np.ndarray], np.ndarray]:
    """A GIF's frames as RGB arrays and their start times, ms."""
    from PIL import Image, ImageSequence

    frames, starts, t = [], [], 0
    with Image.open(io.BytesIO(data)) as im:
        for fr in ImageSequence.Iterator(im):
            frames.append(np.asarray(fr.convert("RGB")))
            starts.append(t)
            t += int(fr.info.get("duration", 0))
    return frames, np.asarray(starts + [t])


def contact_sheet(
    scenes: Sequence[Any] | Mapping[str, Any],
    path: str | os.PathLike,
    *,
    labels: Sequence[str] | None = None,
    columns: int | None = None,
    tile: tuple[int, int] = (240, 180),
    fps: float | None = None,
    client: Any = "serial",
    workers: int | None = None,
    progress: bool = False,
    **options: Any,
) -> Path:
    """Animate several scenes side by side in one GIF: a grid of tiles on one clock.

    Each tile is what :func:`gif` draws for its scene at the tile's size, with `options`
    (``frames``, ``frame_time``, ``steps_per_frame``, ``color_by``, ``theme``, ``trail``, ...)
    passed to every tile. A shorter animation holds its last frame. The sheet has one colour
    palette fitted to all tiles (so tiles of different themes or field styles can sit
    together).

    Parameters
    ----------
    scenes : sequence of Scene, or dict of label -> Scene
        The variants, in reading order (left to right, top to bottom). Each is stepped on a
        copy (pickled): the scenes given are left as they are.
    path : str or os.PathLike
        Output ``.gif``, written atomically (its directory is checked before rendering).
    labels : sequence of str, optional
        A caption per tile (top left); default: the dict's keys, else none. Characters outside
        Latin-1 (the bitmap font's) are drawn as "?".
    columns : int, optional
        Tiles per row, >= 1; default ``ceil(sqrt(len(scenes)))``.
    tile : (int, int), default (240, 180)
        Width and height of each tile in pixels, each >= 16.
    fps : float, optional
        Playback rate of every tile and of the sheet; default: the first scene's
        ``render_defaults`` fps, else 30.
    client, workers
        Where the tiles are rendered, as for :func:`physcore.sweep`; default ``"serial"`` (this
        process).
    progress : bool, default False
        A tqdm bar of tiles done.
    **options
        Keyword arguments of :func:`gif` for every tile (not `size`, `fps` or `progress`).

    Returns
    -------
    pathlib.Path
        `path`.

    Raises
    ------
    TypeError, ValueError
        A bad argument, naming it (an unknown option names the option), before any rendering.
    physcore.SimulationDiverged
        A tile's scene diverged (a note on the exception names the tile); no file is written.
    OSError
        The file cannot be written; no partial file is left.

    Examples
    --------
    >>> import os, tempfile, physcore as pc
    >>> variants = {f"e = {e}": pc.scenes.kepler(e=e) for e in (0.0, 0.5, 0.8)}
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     out = pc.render.contact_sheet(variants, os.path.join(tmp, "orbits.gif"), frames=10, tile=(96, 72))
    ...     out.stat().st_size > 0
    True
    """
    from ..scene import Scene
    from ..sweeps import _check_client, _map

    if isinstance(scenes, Mapping):
        if labels is None:
            labels = [str(k) for k in scenes]
        scenes = list(scenes.values())
    if isinstance(scenes, (str, bytes)) or not isinstance(scenes, Sequence):
        raise InvalidTypeError(f"scenes: expected a list of Scenes or a dict of label -> Scene, got {type(scenes).__name__}")
    scenes = list(scenes)
    if not scenes:
        raise InvalidInputError("scenes: no scenes to show")
    for i, s in enumerate(scenes):
        if not isinstance(s, Scene):
            raise InvalidTypeError(f"scenes[{i}]: expected a physcore.Scene, got {type(s).__name__}")
    if labels is not None:
        if isinstance(labels, (str, bytes)) or not isinstance(labels, Sequence):
            raise InvalidTypeError(f"labels: expected a list of str, got {type(labels).__name__}")
        # The bitmap font has Latin-1 only: other characters are drawn as "?".
        labels = [str(x).encode("latin-1", "replace").decode("latin-1") for x in labels]
        if len(labels) != len(scenes):
            raise InvalidInputError(f"labels: {len(labels)} labels for {len(scenes)} scenes")
    n = len(scenes)
    cols = int(np.ceil(np.sqrt(n))) if columns is None else _check.int_in_range("columns", columns, 1, n)
    rows = -(-n // cols)
    w, h = _check_size(tile)
    fps = _check_fps(scene_defaults(scenes[0]).get("fps", 30.0) if fps is None else fps)
    for bad in ("size", "fps", "progress"):
        if bad in options:
            raise InvalidInputError(f"{bad}: set by contact_sheet for every tile (use tile= / fps=)")
    known = set(_OPTIONS)
    for k in options:
        if k not in known:
            raise InvalidTypeError(f"contact_sheet() got an unexpected option {k!r} (gif() takes {', '.join(sorted(known))})")
    client = _check_client(client)
    progress = _check.flag("progress", progress)
    sheet_w, sheet_h = cols * w + (cols - 1) * GAP, rows * h + (rows - 1) * GAP
    path = _check_path(path)
    _check_writable(path)

    data = [pickle.dumps(s) for s in scenes]
    out: list[Any] = [None] * n
    from tqdm.auto import tqdm

    bar = tqdm(total=n, desc="tiles", unit="tile", disable=not progress, leave=False)

    def done(i: int, value: Any) -> None:
        out[i] = value
        bar.update(1)

    try:
        _map(_catch_tile, [(d, (w, h), fps, options) for d in data], client, workers, done)
    finally:
        bar.close()
    for i, v in enumerate(out):
        if isinstance(v, BaseException):
            if hasattr(v, "add_note"):  # Python >= 3.11: the traceback says which tile
                v.add_note(f"while rendering scenes[{i}]" + (f" ({labels[i]!r})" if labels else "") + " of the contact sheet")
            raise v
    tiles = [_decode(v) for v in out]

    total = max(int(t[1][-1]) for t in tiles)
    delays = _gif_delays_ms(fps, max(1, round(total * fps / 1000.0)))
    starts = np.concatenate([[0], np.cumsum(delays)[:-1]])
    _check.memory("scenes, tile", len(starts) * (sheet_w * sheet_h * 4 + n * w * h * 3),
                  f"a sheet of {len(starts)} frames of {sheet_w}x{sheet_h} pixels")
    background = tiles[0][0][0][0, 0]
    font = _font()
    frames = []
    from PIL import Image, ImageDraw

    for t in starts:
        canvas = np.empty((sheet_h, sheet_w, 3), dtype=np.uint8)
        canvas[:] = background // 2 + 64  # the gaps: a mid tone of the first tile's background
        for i, (fr, st) in enumerate(tiles):
            k = min(int(np.searchsorted(st, t, side="right")) - 1, len(fr) - 1)
            img = fr[k]
            r, c = divmod(i, cols)
            y, x = r * (h + GAP), c * (w + GAP)
            th, tw = min(h, img.shape[0]), min(w, img.shape[1])
            y, x = y + (h - th) // 2, x + (w - tw) // 2  # a field's square image sits centred
            canvas[y:y + th, x:x + tw] = img[:th, :tw]
        im = Image.fromarray(canvas)
        if labels:
            draw = ImageDraw.Draw(im)
            for i, text in enumerate(labels):
                r, c = divmod(i, cols)
                x, y = c * (w + GAP) + 4, r * (h + GAP) + 3
                bbox = draw.textbbox((x, y), text, font=font)
                draw.rectangle((bbox[0] - 2, bbox[1] - 1, bbox[2] + 2, bbox[3] + 1), fill=(20, 20, 30))
                draw.text((x, y), text, fill=(235, 235, 240), font=font)
        frames.append(im)
    # One palette for the whole sheet (its flat colours exact); no dithering.
    images, colours = _palette_frames([np.asarray(f) for f in frames])
    atomic_write(path, lambda fh: images[0].save(fh, format="GIF", save_all=True, append_images=images[1:],
                                                 duration=delays, loop=0, palette=colours))
    return path


def _catch_tile(data: bytes, size: tuple[int, int], fps: float, options: dict[str, Any]) -> Any:
    """:func:`_render_tile`, with its exception as the value (the sheet raises it, naming the
    tile)."""
    try:
        return _render_tile(data, size, fps, options)
    except Exception as exc:  # noqa: BLE001 - raised again by contact_sheet with the tile's name
        return exc

