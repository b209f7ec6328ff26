"""Line segments drawn into an image, numpy only: what the rasteriser and the body outlines
share (its own module, so that neither imports the other)."""
from __future__ import annotations

import numpy as np


def _draw_lines(buf: np.ndarray, c0, r0, c1, r1, colors: np.ndarray) -> None:
    """Draw segments between (M,) float pixel endpoints, sampling about one point per pixel.

    colors is (M,) uint8, or (M, C) for an (H, W, C) image. Samples falling outside buf are
    dropped.
    """
    h, w = buf.shape[:2]
    ok = np.isfinite(c0) & np.isfinite(r0) & np.isfinite(c1) & np.isfinite(r1)
    # Segments wholly outside the image cost nothing.
    ok &= (np.maximum(c0, c1) >= 0) & (np.minimum(c0, c1) < w)
    ok &= (np.maximum(r0, r1) >= 0) & (np.minimum(r0, r1) < h)
    if not ok.all():
        c0, r0, c1, r1, colors = c0[ok], r0[ok], c1[ok], r1[ok], colors[ok]
    if c0.size == 0:
        return
    # Clip each segment to the image (grown by a pixel) first, in float64 (Liang & Barsky, ACM
    # TOG 3 (1984) 1): an end far beyond float32 (a scene about to diverge) then costs nothing.
    c0, r0, c1, r1 = (np.asarray(a, np.float64) for a in (c0, r0, c1, r1))
    dc, dr = c1 - c0, r1 - r0
    t0, t1 = np.zeros(c0.shape), np.ones(c0.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        for p, q in ((-dc, c0 + 1.0), (dc, w + 1.0 - c0), (-dr, r0 + 1.0), (dr, h + 1.0 - r0)):
            ratio = q / p
            t0 = np.where(p < 0, np.maximum(t0, ratio), t0)
            t1 = np.where(p > 0, np.minimum(t1, ratio), t1)
            t1 = np.where((p == 0) & (q < 0), -1.0, t1)
    keep = t0 <= t1
    if not keep.all():
        c0, r0, c1, r1, dc, dr = c0[keep], r0[keep], c1[keep], r1[keep], dc[keep], dr[keep]
        t0, t1, colors = t0[keep], t1[keep], colors[keep]
    if c0.size == 0:
        return
    # (Segments inside keep their own ends, bit for bit.)
    c1, r1 = np.where(t1 < 1, c0 + t1 * dc, c1), np.where(t1 < 1, r0 + t1 * dr, r1)
    c0, r0 = np.where(t0 > 0, c0 + t0 * dc, c0), np.where(t0 > 0, r0 + t0 * dr, r0)
    c0, r0 = c0.astype(np.float32), r0.astype(np.float32)
    dc, dr = c1.astype(np.float32) - c0, r1.astype(np.float32) - r0
    # One sample per pixel along the longer axis, capped (a segment crossing the image from far
    # outside would otherwise cost memory for nothing).
    n = np.minimum(np.ceil(np.maximum(np.abs(dc), np.abs(dr))), 2 * (w + h)).astype(np.int64) + 1
    first = np.cumsum(n) - n
    # Sample k of segment m sits at t = k / (n_m - 1); np.repeat spreads per-segment values.
    k = np.arange(int(first[-1] + n[-1]), dtype=np.int64) - np.repeat(first, n)
    t = k.astype(np.float32) * np.repeat((1.0 / np.maximum(n - 1, 1)).astype(np.float32), n)
    cc = np.floor(np.repeat(c0, n) + t * np.repeat(dc, n)).astype(np.int64)
    rr = np.floor(np.repeat(r0, n) + t * np.repeat(dr, n)).astype(np.int64)
    vals = np.repeat(colors, n, axis=0)
    inside = (cc >= 0) & (cc < w) & (rr >= 0) & (rr < h)
    if not inside.all():
        cc, rr, vals = cc[inside], rr[inside], vals[inside]
    if cc.size == 0:  # no sample in the image (reshape(0, -1) of the colours cannot be formed)
        return
    buf.reshape(h * w, -1)[rr * w + cc] = vals.reshape(vals.shape[0], -1)
