"""Rigid bodies in a recording and on the image. In 2D: each body's outline (a convex polygon in
its own frame) and colour, its pose every frame, and the drawing: a filled, shaded, antialiased
polygon with a darker rim (a ball also gets a spoke, so its rolling shows). In 3D: each body's
triangles in its own frame (flat-shaded faces for boxes, hulls and meshes; smooth for balls and
capsules, a ball's two halves in two shades so that its rolling shows), posed every frame and
lit and rasterised like the cloth (``_mesh``), in one depth buffer with it."""
from __future__ import annotations

import copy
from typing import Any

import numpy as np

__all__ = ["BodyTrack", "BodyTrack3", "body_track", "draw_bodies", "body_bounds", "body_bounds3", "body_geometry"]


class BodyTrack:
    """The bodies of a scene as recorded: ``outlines`` (B,) of (V, 2) float64 polygons (m, body
    frame, convex), ``colors`` (B, 3) uint8, ``balls`` (B,) bool (draw a spoke), ``poses``
    (F, B, 3) float32 ``(x, y, angle)`` with x, y relative to the recording's origin."""

    dim = 2

    def __init__(self, outlines: list[np.ndarray], colors: np.ndarray, balls: np.ndarray, frames: int,
                 chains: np.ndarray | None = None) -> None:
        self.outlines = outlines
        self.colors = colors
        self.balls = balls
        #: (B,) bool: the outline is an open chain of segments (a polyline), drawn segment by segment.
        self.chains = np.zeros(len(outlines), dtype=bool) if chains is None else chains
        self.poses = np.zeros((frames, len(outlines), 3), dtype=np.float32)
        self.reach = np.array([float(np.hypot(o[:, 0], o[:, 1]).max()) for o in outlines])

    def with_frames(self, frames: int) -> BodyTrack:
        """A copy holding `frames` frames, each frame 0's poses (the live painter's history)."""
        out = copy.copy(self)
        out.poses = np.repeat(self.poses[:1], frames, axis=0)
        return out


class BodyTrack3:
    """The bodies of a 3D scene as recorded: every body's triangles in its own frame, joined:
    ``local`` (V, 3) float64 vertices (m), ``normals`` (V, 3) their unit normals, ``faces``
    (T, 3) int64, ``owner`` (V,) int64 the body of each vertex, ``rgb`` (V, 3) float32 in
    [0, 1]; ``reach`` (B,) each body's farthest vertex from its centre (m); ``poses`` (F, B, 7)
    float32 ``(x, y, z, qx, qy, qz, qw)``, the centre relative to the recording's origin;
    ``fixed`` (B,) bool, the bodies that never move (all False unless given), and ``flat`` (V,)
    bool, the vertices of flat faces (each face its own corners and normal)."""

    dim = 3

    def __init__(self, meshes: list[tuple[np.ndarray, np.ndarray]], smooth: np.ndarray, colors: np.ndarray,
                 balls: np.ndarray, frames: int, fixed: np.ndarray | None = None) -> None:
        local, normals, faces, owner, rgb = [], [], [], [], []
        k = 0
        for b, (v, t) in enumerate(meshes):
            tri = v[t]  # (T, 3 corners, 3)
            fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            if smooth[b]:  # per-vertex normals: the area-weighted mean of the faces around
                vn = np.zeros_like(v)
                for c in range(3):
                    np.add.at(vn, t[:, c], fn)
                vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
                verts, norms, f = v, vn, t
            else:  # each face its own corners: flat faces with sharp edges
                fn = fn / np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
                verts, norms = tri.reshape(-1, 3), np.repeat(fn, 3, axis=0)
                f = np.arange(3 * len(t)).reshape(-1, 3)
            base = np.tile(colors[b].astype(np.float32) / 255.0, (len(verts), 1))
            if balls[b]:  # two shades, split along the body's x: a rolling ball shows it
                base[verts[:, 0] * verts[:, 1] > 0] *= 0.78
            local.append(verts)
            normals.append(norms)
            faces.append(f + k)
            owner.append(np.full(len(verts), b, dtype=np.int64))
            rgb.append(base)
            k += len(verts)
        self.local = np.concatenate(local)
        self.normals = np.concatenate(normals)
        self.faces = np.concatenate(faces).astype(np.int64)
        self.owner = np.concatenate(owner)
        self.rgb = np.concatenate(rgb).astype(np.float32)
        self.reach = np.array([float(np.linalg.norm(v, axis=1).max()) for v, _ in meshes])
        self.poses = np.zeros((frames, len(meshes), 7), dtype=np.float32)
        self.fixed = np.zeros(len(meshes), dtype=bool) if fixed is None else np.asarray(fixed, dtype=bool)
        self.flat = ~np.asarray(smooth, dtype=bool)[self.owner]

    def with_frames(self, frames: int) -> BodyTrack3:
        """A copy holding `frames` frames, each frame 0's poses (the live painter's history)."""
        out = copy.copy(self)
        out.poses = np.repeat(self.poses[:1], frames, axis=0)
        return out


def _rotations(q: np.ndarray) -> np.ndarray:
    """(B, 3, 3) rotation matrices of the unit quaternions q (B, 4), (x, y, z, w)."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], 1)


def body_geometry(track: BodyTrack3, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Frame k's 3D bodies as one mesh relative to the recording's origin: vertices (V, 3)
    float64 m, unit normals (V, 3), faces (T, 3) int64, colours (V, 3) float32 in [0, 1]; the
    faces of bodies whose pose is not finite are left out."""
    poses = track.poses[k].astype(np.float64)
    ok = np.isfinite(poses).all(axis=1)
    q = np.where(ok[:, None], poses[:, 3:], [0.0, 0.0, 0.0, 1.0])
    q /= np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-300)
    rot = _rotations(q)[track.owner]
    centre = np.where(ok[:, None], poses[:, :3], 0.0)[track.owner]
    verts = np.einsum("vij,vj->vi", rot, track.local) + centre
    normals = np.einsum("vij,vj->vi", rot, track.normals)
    faces = track.faces if ok.all() else track.faces[ok[track.owner[track.faces[:, 0]]]]
    return verts, normals, faces, track.rgb


def body_bounds3(track: BodyTrack3, cam: Any) -> tuple[np.ndarray, np.ndarray]:
    """The (2,) lower and upper corners, on the screen plane of `cam`, of every body over
    every frame: each centre ± its reach (m, relative to the origin); non-finite poses are
    skipped."""
    c = track.poses[:, :, :3].astype(np.float64).reshape(-1, 3)
    r = np.tile(track.reach, track.poses.shape[0])
    ok = np.isfinite(c).all(axis=1)
    if not ok.any():
        return np.full(2, np.inf), np.full(2, -np.inf)
    s, _ = cam.project(c[ok])
    return (s - r[ok, None]).min(axis=0), (s + r[ok, None]).max(axis=0)


def body_track(scene: Any, frames: int) -> tuple[BodyTrack | BodyTrack3 | None, Any]:
    """The scene's bodies (None if it has none) and ``grab()``: their poses now, (B, 3)
    float64 ``(x, y, angle)`` in 2D, (B, 7) ``(x, y, z, qx, qy, qz, qw)`` in 3D."""
    groups = [g for g in getattr(scene, "bodies", ()) if getattr(g, "first", None) is not None]
    if not groups:
        return None, None

    def flag(test: Any) -> np.ndarray:  # (B,) bool: test(group) for each body of every group
        return np.concatenate([np.full(g.n, bool(test(g))) for g in groups])

    colors = np.concatenate([np.broadcast_to(c, (g.n, 3)) if c.ndim == 1 else c
                             for g in groups for c in [np.asarray(g.color, dtype=np.uint8)]]).astype(np.uint8)
    balls = flag(lambda g: g.shape == "ball")
    track: BodyTrack | BodyTrack3
    if groups[0].dim == 3:
        meshes = [m for g in groups for m in g.meshes()]
        track = BodyTrack3(meshes, flag(lambda g: g.shape in ("ball", "capsule")), colors, balls, frames,
                           flag(lambda g: g.kind == "fixed"))
        names = ["x", "y", "z", "qx", "qy", "qz", "qw"]
    else:
        outlines = [o for g in groups for o in g.outline()]
        track = BodyTrack(outlines, colors, balls, frames, flag(lambda g: g.shape == "polyline"))
        names = ["x", "y", "angle"]
    # The groups may belong to several scenes (a batch's members overlaid): each scene's poses
    # are read once a frame, under its own lock.
    hosts = [g._bound() for g in groups]

    def grab() -> np.ndarray:
        full: dict[int, np.ndarray] = {}
        for h in hosts:
            if id(h) not in full:
                fields = h.exclusive(lambda sim: sim.system_fields("bodies", names))
                full[id(h)] = np.stack([np.asarray(v) for v in fields], axis=1)
        return np.concatenate([full[id(h)][g.first:g.first + g.n] for g, h in zip(groups, hosts, strict=True)])

    return track, grab


def body_bounds(track: BodyTrack) -> tuple[np.ndarray, np.ndarray]:
    """The (2,) lower and upper corners of every body's outline over every frame (m, relative
    to the origin); non-finite poses are skipped."""
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    poses = track.poses.astype(np.float64)
    for b, outline in enumerate(track.outlines):
        p = poses[:, b]
        p = p[np.isfinite(p).all(axis=1)]
        if not len(p):
            continue
        c, s = np.cos(p[:, 2])[:, None], np.sin(p[:, 2])[:, None]
        x = p[:, :1] + c * outline[None, :, 0] - s * outline[None, :, 1]
        y = p[:, 1:2] + s * outline[None, :, 0] + c * outline[None, :, 1]
        lo = np.minimum(lo, [x.min(), y.min()])
        hi = np.maximum(hi, [x.max(), y.max()])
    return lo, hi


def _fill(out: np.ndarray, poly: np.ndarray, color: np.ndarray) -> None:
    """Fills the convex polygon `poly` ((V, 2) pixel coordinates col, row) on the RGB image
    `out`: antialiased by the signed distance to its edges, lit from above (lighter at its top,
    darker at its foot) and rimmed darker. The reference of ``_core.fill_polygons``, which
    draws the bodies (the same bytes, tested); used where `out` is not C-contiguous."""
    h, w = out.shape[:2]
    c0, r0 = np.floor(poly.min(axis=0) - 1).astype(int)
    c1, r1 = np.ceil(poly.max(axis=0) + 1).astype(int)
    c0, r0, c1, r1 = max(c0, 0), max(r0, 0), min(c1, w), min(r1, h)
    if c0 >= c1 or r0 >= r1:
        return
    cols = np.arange(c0, c1) + 0.5
    rows = np.arange(r0, r1) + 0.5
    centre = poly.mean(axis=0)
    nxt = np.roll(poly, -1, axis=0)
    e = nxt - poly
    length = np.hypot(e[:, 0], e[:, 1])
    keep = length > 1e-9
    poly, e, length = poly[keep], e[keep], length[keep]
    if len(poly) < 3:
        return
    n = np.stack([e[:, 1], -e[:, 0]], axis=1) / length[:, None]
    flip = ((centre - poly) * n).sum(axis=1) > 0  # point outward, whatever the winding
    n[flip] *= -1
    # Signed distance (px), > 0 outside: the largest of the edges' half-plane distances.
    d = np.full((rows.size, cols.size), -np.inf)
    for (px, py), (nx, ny) in zip(poly, n, strict=True):
        d = np.maximum(d, (cols[None, :] - px) * nx + (rows[:, None] - py) * ny)
    cover = np.clip(0.5 - d, 0.0, 1.0)[..., None]
    if not cover.any():
        return
    top, foot = poly[:, 1].min(), poly[:, 1].max()
    t = ((rows - top) / max(foot - top, 1.0)).clip(0, 1)[:, None, None]
    base = color.astype(np.float32)[None, None, :]
    lit = base * (1.18 - 0.33 * t)
    rim = np.clip(-d, 0, None)[..., None]
    shade = np.where(rim < 1.6, base * 0.55, lit)
    region = out[r0:r1, c0:c1].astype(np.float32)
    out[r0:r1, c0:c1] = np.clip(region * (1 - cover) + shade * cover, 0, 255).astype(np.uint8)


def draw_bodies(out: np.ndarray, cam: Any, track: BodyTrack, k: int) -> None:
    """Draws frame k's bodies on the RGB image `out` through the 2D camera `cam`: each filled as
    :func:`_fill` does, by the core (``_core.fill_polygons``, the same bytes in one call instead
    of a numpy pass per body), in order; a ball's direction line over it before the next."""
    from .. import _core

    polys: list[np.ndarray] = []
    colours: list[np.ndarray] = []

    def flush() -> None:
        if polys and not out.flags.c_contiguous:  # the core writes a C-contiguous image only
            for q, col in zip(polys, colours, strict=True):
                _fill(out, q, col)
            polys.clear()
            colours.clear()
        if polys:
            starts = np.concatenate([[0], np.cumsum([len(q) for q in polys])]).astype(np.uint64)
            _core.fill_polygons(out, np.ascontiguousarray(np.concatenate(polys), dtype=np.float64), starts,
                                np.ascontiguousarray(np.stack(colours), dtype=np.uint8))
            polys.clear()
            colours.clear()

    poses = track.poses[k].astype(np.float64)
    for b, (outline, (x, y, a)) in enumerate(zip(track.outlines, poses, strict=True)):
        if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(a)):
            continue
        c, s = np.cos(a), np.sin(a)
        world = np.stack([x + c * outline[:, 0] - s * outline[:, 1], y + s * outline[:, 0] + c * outline[:, 1]], axis=1)
        col, row = cam.pixels(cam.project(world)[0])
        poly = np.stack([col, row], axis=1).astype(np.float64)
        if not np.isfinite(poly).all():
            continue
        if track.chains[b]:  # a polyline: each segment a quad 4 px thick
            for p0, p1 in zip(poly[:-1], poly[1:], strict=True):
                d = p1 - p0
                n = np.array([-d[1], d[0]]) * (2.0 / max(float(np.hypot(*d)), 1e-9))
                polys.append(np.array([p0 - n, p1 - n, p1 + n, p0 + n]))
                colours.append(track.colors[b])
            continue
        polys.append(poly)
        colours.append(track.colors[b])
        if track.balls[b]:
            from ._lines import _draw_lines

            flush()  # the line goes over this ball and under the bodies after it
            r = float(np.hypot(outline[:, 0], outline[:, 1]).max())
            ends = np.array([[x, y], [x + 0.8 * r * c, y + 0.8 * r * s]])
            ec, er = cam.pixels(cam.project(ends)[0])
            dark = (track.colors[b].astype(np.float32) * 0.55).astype(np.uint8)[None, :]
            _draw_lines(out, ec[:1], er[:1], ec[1:], er[1:], dark)
    flush()
