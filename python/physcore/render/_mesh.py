"""Shaded triangle meshes: cloth and soft bodies drawn as surfaces rather than discs and lines.

A :class:`Mesh` names triangles over a scene's particles (and optionally texture coordinates).
:class:`_MeshShader` lights the mesh every frame (Gouraud shading: per-vertex normals, Lambert
diffuse plus a Blinn–Phong highlight, back faces in a darker colour) and rasterises it with
the core (``_core.rasterise_mesh``: a depth buffer, 2×2 supersamples per pixel so that the
edges are antialiased, blended by coverage over the caller's RGB image of the background).

Sources: H. Gouraud, "Continuous shading of curved surfaces", IEEE Trans. Computers C-20 (1971)
623–629 (per-vertex intensities, interpolated); J. F. Blinn, "Models of light reflection for
computer synthesized pictures", SIGGRAPH 1977 (the half-vector highlight); J. Pineda, "A parallel
algorithm for polygon rasterization", SIGGRAPH 1988 (edge functions, in the core).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .._errors import InvalidInputError, InvalidTypeError


class Mesh(NamedTuple):
    """Triangles over a scene's particles, drawn as a lit surface.

    Attributes
    ----------
    faces : (T, 3) int64
        Particle indices of each triangle's corners (any winding: both sides are drawn, the
        back side darker).
    uv : (N, 2) float64 or None
        Texture coordinates of each particle in [0, 1]² (u to the right, v up the image), for
        ``texture=``; None draws the mesh in one colour.

    Examples
    --------
    >>> import physcore as pc
    >>> m = pc.render.Mesh.grid(3, 2)
    >>> m.faces.shape, m.uv.shape
    ((4, 3), (6, 2))
    """

    faces: np.ndarray
    uv: np.ndarray | None = None

    def __eq__(self, other: object) -> bool:
        """Equal faces and uv, element by element (a tuple's == would compare arrays)."""
        if not isinstance(other, Mesh):
            return NotImplemented
        same_uv = (self.uv is None and other.uv is None) or (
            self.uv is not None and other.uv is not None and np.array_equal(self.uv, other.uv)
        )
        return bool(same_uv and np.array_equal(self.faces, other.faces))

    def __ne__(self, other: object) -> bool:
        eq = self.__eq__(other)
        return eq if eq is NotImplemented else not eq

    __hash__ = None  # type: ignore[assignment]  # arrays: not hashable

    @classmethod
    def grid(cls, nx: int, ny: int) -> Mesh:
        """The mesh of an `nx` × `ny` particle grid indexed ``row · nx + col`` (as
        :func:`physcore.scenes.cloth` lays out its sheet, with nx = ny = n): two triangles per
        cell, and uv running 0 → 1 along the columns (u) and the rows (v).

        Raises InvalidInputError (ValueError) if nx or ny is below 2, InvalidTypeError
        (TypeError) if either is not an integer.
        """
        for name, v in (("nx", nx), ("ny", ny)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise InvalidTypeError(f"{name} must be an int, got {type(v).__name__}")
            if v < 2:
                raise InvalidInputError(f"{name} must be at least 2, got {v}")
        nx, ny = int(nx), int(ny)
        idx = np.arange(nx * ny, dtype=np.int64).reshape(ny, nx)
        a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
        # Alternate the diagonal cell by cell, so a sheet folding along a diagonal stays symmetric.
        flip = ((np.arange(ny - 1)[:, None] + np.arange(nx - 1)[None, :]) % 2).ravel().astype(bool)
        t1 = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
        t2 = np.where(flip[:, None], np.stack([a, d, c], 1), np.stack([b, d, c], 1))
        faces = np.concatenate([t1, t2])
        u, v = np.meshgrid(np.linspace(0.0, 1.0, nx), np.linspace(0.0, 1.0, ny))
        return cls(faces, np.stack([u.ravel(), v.ravel()], axis=1))


def check_mesh(mesh: Any, n: int) -> Mesh | None:
    """`mesh` (a Mesh, a (T, 3) integer array of faces, None or False) checked against a scene of
    `n` particles; None or False -> None."""
    if mesh is None or mesh is False:
        return None
    if isinstance(mesh, Mesh):
        faces, uv = mesh.faces, mesh.uv
    else:
        faces, uv = mesh, None
    if not isinstance(faces, (np.ndarray, list, tuple)):
        raise InvalidTypeError(f"mesh must be a physcore.render.Mesh or a (T, 3) integer array, got {type(mesh).__name__}")
    try:
        f = np.asarray(faces)
    except ValueError:  # ragged nested lists
        raise InvalidInputError("mesh: faces must have shape (T, 3)") from None
    if f.dtype == bool or not np.issubdtype(f.dtype, np.integer):
        raise InvalidTypeError(f"mesh: faces must be integers, got dtype {f.dtype}")
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
        raise InvalidInputError(f"mesh: faces must have shape (T, 3) with T >= 1, got {f.shape}")
    if f.min() < 0 or f.max() >= n:
        raise InvalidInputError(f"mesh: face indices must lie in [0, {n}) (the scene's particles), got [{f.min()}, {f.max()}]")
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape != (n, 2) or not np.isfinite(uv).all():
            raise InvalidInputError(f"mesh: uv must be a finite ({n}, 2) array, got shape {uv.shape}")
    return Mesh(f.astype(np.int64), uv)


def check_texture(texture: Any, mesh: Mesh | None) -> np.ndarray | None:
    """`texture` (None or False, an image path, an (H, W, 3) uint8 array, or nested lists of
    such an array's values, as a scene's render_defaults keep it: they compare with ==) ->
    (H, W, 3) float32 in [0, 1], or None."""
    if texture is None or texture is False:
        return None
    if mesh is None or mesh.uv is None:
        raise InvalidInputError("texture: needs a mesh with texture coordinates (mesh=Mesh(faces, uv), or a scene with a grid mesh)")
    if isinstance(texture, (str, os.PathLike)):
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(Path(texture)) as im:
                arr = np.asarray(im.convert("RGB"))
        except (OSError, UnidentifiedImageError) as e:
            raise InvalidInputError(f"texture: cannot read the image {str(texture)!r}: {e}") from None
        except Image.DecompressionBombError as e:  # a hostile image: its size alone would fill memory
            raise InvalidInputError(f"texture: the image {str(texture)!r} is too large to load safely: {e}") from None
    elif isinstance(texture, (np.ndarray, list, tuple)):
        arr = texture
        if not isinstance(arr, np.ndarray):
            try:
                arr = np.asarray(texture)
            except ValueError:  # ragged
                raise InvalidInputError("texture: nested lists must be (H, W, 3) values in 0..255") from None
            if arr.dtype.kind not in "iu" or arr.size == 0 or arr.min() < 0 or arr.max() > 255:
                raise InvalidInputError(f"texture: nested lists must be (H, W, 3) integers in 0..255, got {arr.dtype} values")
            arr = arr.astype(np.uint8)
        if arr.dtype != np.uint8 or arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] < 1 or arr.shape[1] < 1:
            raise InvalidInputError(f"texture: an array must be (H, W, 3) uint8, got {arr.shape} {arr.dtype}")
    else:
        raise InvalidTypeError(f"texture must be an image path or an (H, W, 3) uint8 array (or nested lists), got {type(texture).__name__}")
    return arr.astype(np.float32) / 255.0


#: Surface colours (RGB in [0, 1]) by theme: the front of the sheet, and its back, the same
#: fabric a shade darker (a second hue read as a second material, and a hanging cloth shows
#: mostly its back).
_FRONT = {"light": (0.86, 0.38, 0.26), "dark": (0.95, 0.52, 0.32)}
_BACK = {"light": (0.64, 0.26, 0.19), "dark": (0.74, 0.38, 0.24)}
#: Lighting: ambient floor, diffuse weight with "wrap" (n·l + w)/(1 + w), which lets light
#: reach a little past the terminator so that folds facing away do not go black, and a
#: Blinn–Phong highlight.
_AMBIENT, _DIFFUSE, _WRAP, _SPECULAR, _SHININESS = 0.30, 0.70, 0.3, 0.30, 24.0
#: The back of a textured or coloured sheet: its own colours, this much darker.
_BACK_SHADE = 0.8
_SS = 2  # supersampling factor per axis (antialiased edges)
#: Sphere colliders (a ball under a cloth) by theme: a neutral grey-blue, a second material that
#: the warm fabric reads against; and the rings and meridians of their triangulation.
_BALL = {"light": (0.50, 0.58, 0.68), "dark": (0.52, 0.60, 0.72)}
#: A 3D plane collider (a floor) is drawn as a square patch this many times the scene's widest
#: extent across, centred under it (wider than most views), in checks of two shades (the eye
#: reads distance and tilt from them), with a soft contact shadow under each ball, a little
#: below the plane (so a sheet lying on it does not fight it for the depth buffer).
_FLOOR = {"light": ((0.84, 0.82, 0.78), (0.74, 0.72, 0.68)), "dark": ((0.26, 0.27, 0.31), (0.20, 0.21, 0.25))}
_FLOOR_SPAN, _FLOOR_CELLS, _FLOOR_INSET = 4.0, 24, 0.004


def _floor_geometry(planes: Any, lo: np.ndarray, hi: np.ndarray, theme: str,
                    balls: Any = (), rods: Any = ()) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The 3D plane colliders ``(point, unit normal)`` (relative to the recording's origin) as
    square patches of _FLOOR_CELLS² checks around the projection of the box [lo, hi]'s centre,
    _FLOOR_SPAN times its widest side across, each check its own four vertices and shade,
    darkened under each ball ``(centre, radius)`` near the plane: vertices (V, 3), normals
    (V, 3), faces (T, 3), colours (V, 3) in [0, 1]."""
    if not planes or len(lo) != 3:
        return None
    centre, extent = 0.5 * (lo + hi), max(float(np.max(hi - lo)), 1e-9)
    span = _FLOOR_SPAN * extent
    shades = np.array(_FLOOR.get(theme, _FLOOR["light"]), dtype=np.float64)
    verts, norms, faces, rgb = [], [], [], []
    nc = _FLOOR_CELLS
    g = np.linspace(-0.5, 0.5, nc + 1) * span
    ci, cj = np.meshgrid(np.arange(nc), np.arange(nc), indexing="ij")
    ci, cj = ci.reshape(-1), cj.reshape(-1)
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    for p, n in planes:
        n = np.asarray(n, dtype=np.float64)
        c = centre - ((centre - p) @ n) * n - _FLOOR_INSET * extent * n  # under the box's centre
        a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        u = g[(ci[:, None] + corners[None, :, 0]).reshape(-1)]
        v = g[(cj[:, None] + corners[None, :, 1]).reshape(-1)]
        x = c + u[:, None] * a + v[:, None] * b
        shade = np.repeat(shades[(ci + cj) % 2], 4, axis=0)
        for bc, br in balls:  # a soft shadow under a ball resting on (or near) the plane
            height = float((bc - p) @ n)
            if 0.0 < height < 2.0 * br:
                d2 = np.sum((x - (bc - height * n)) ** 2, axis=1) - ((x - (bc - height * n)) @ n) ** 2
                shade = shade * (1.0 - 0.45 * np.exp(-1.5 * d2 / (br * br)) * (1.0 - 0.5 * (height - br) / br))[:, None]
        for ra, rb, rr in rods:  # a rod's: each floor point shaded by the rod's nearest point above it
            ab = rb - ra
            axis = ab - (ab @ n) * n  # the rod's shadow line on the plane
            l2 = float(axis @ axis)
            t = np.clip(((x - ra) @ axis) / l2, 0.0, 1.0) if l2 > 0 else np.zeros(len(x))
            near = ra + t[:, None] * ab
            height = (near - p) @ n
            rel = x - near
            d2 = np.sum(rel**2, axis=1) - (rel @ n) ** 2
            near_floor = (height > 0.0) & (height < 2.0 * rr)
            dark = 0.45 * np.exp(-1.5 * d2 / (rr * rr)) * (1.0 - 0.5 * (height - rr) / rr)
            shade = shade * (1.0 - np.where(near_floor, dark, 0.0))[:, None]
        k = sum(len(q) for q in verts)
        q = k + 4 * np.arange(len(ci))
        verts.append(x)
        norms.append(np.tile(n, (len(x), 1)))
        faces.append(np.concatenate([np.stack([q, q + 1, q + 2], 1), np.stack([q, q + 2, q + 3], 1)]))
        rgb.append(shade)
    return (np.concatenate(verts), np.concatenate(norms), np.concatenate(faces).astype(np.int64),
            np.concatenate(rgb).astype(np.float32))


_BALL_RINGS, _BALL_MERIDIANS = 32, 64
#: A ball is drawn this fraction of its radius inside the collider: a sheet lying on it has its
#: vertices on the surface and its triangles a chord below it (s²/8r: 0.4 mm for 3 cm cells on a
#: 30 cm ball), which would otherwise let the ball show through in speckles.
_BALL_INSET = 0.015


def _ball_geometry(spheres: Any, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The 3D sphere colliders that keep particles out, ``(centre, radius, inside)`` in m, as one
    static UV-sphere mesh relative to `origin`: vertices (V, 3) float64 m, their outward unit
    normals (V, 3), faces (T, 3) int64 (fans at the poles, two triangles per quad between the
    rings); None if there is none."""
    parts = [(np.asarray(c, dtype=np.float64) - origin, float(r)) for c, r, inside in spheres or () if not inside]
    if not parts or len(origin) != 3:
        return None
    nr, nm = _BALL_RINGS, _BALL_MERIDIANS
    theta = np.linspace(0.0, np.pi, nr + 1)[1:-1]  # polar angles of the rings, poles apart
    phi = np.arange(nm) * (2.0 * np.pi / nm)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack([st * np.cos(phi), st * np.sin(phi), np.broadcast_to(ct, (nr - 1, nm))], -1)
    unit = np.concatenate([[[0.0, 0.0, 1.0]], ring.reshape(-1, 3), [[0.0, 0.0, -1.0]]])
    idx = 1 + np.arange((nr - 1) * nm).reshape(nr - 1, nm)
    nxt = np.roll(idx, -1, axis=1)
    south = len(unit) - 1
    faces = np.concatenate([
        np.stack([np.zeros(nm, np.int64), idx[0], nxt[0]], 1),  # north fan
        np.stack([idx[:-1].ravel(), idx[1:].ravel(), nxt[1:].ravel()], 1),
        np.stack([idx[:-1].ravel(), nxt[1:].ravel(), nxt[:-1].ravel()], 1),
        np.stack([np.full(nm, south), nxt[-1], idx[-1]], 1),  # south fan
    ]).astype(np.int64)
    k = len(unit)
    verts = np.concatenate([c + (1.0 - _BALL_INSET) * r * unit for c, r in parts])
    return verts, np.tile(unit, (len(parts), 1)), np.concatenate([faces + j * k for j in range(len(parts))])


def _rod_geometry(rods: Any, origin: np.ndarray, edge: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Rods ``(a, b, radius)`` (m; a capsule collider draws as one) as one static mesh relative
    to `origin`: the ball's UV sphere about the rod's axis with its northern half moved to b
    and its southern half to a, the equator ring twice, so the band between is the cylinder
    (its normals exact). Drawn inside by _BALL_INSET of its radius, as the balls are, or by 1.5
    times the chord depth s²/8r of a sheet of edge `edge` (m) lying on it if that is more (a
    thin rod under a coarse sheet: 3.5 % for 5 cm cells on a 12 cm rod, where 1.5 % speckled
    along the ridge), at most a quarter. None if there is none."""
    if not rods or len(origin) != 3:
        return None
    nr, nm = _BALL_RINGS, _BALL_MERIDIANS
    theta = np.linspace(0.0, np.pi, nr + 1)[1:-1]
    theta = np.sort(np.concatenate([theta, [0.5 * np.pi]]))  # the equator twice: north, south
    north = np.arange(len(theta)) <= nr // 2 - 1
    phi = np.arange(nm) * (2.0 * np.pi / nm)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack([st * np.cos(phi), st * np.sin(phi), np.broadcast_to(ct, (len(theta), nm))], -1)
    unit = np.concatenate([[[0.0, 0.0, 1.0]], ring.reshape(-1, 3), [[0.0, 0.0, -1.0]]])
    up = np.concatenate([[True], np.repeat(north, nm), [False]])
    nring = len(theta)
    idx = 1 + np.arange(nring * nm).reshape(nring, nm)
    nxt = np.roll(idx, -1, axis=1)
    south = len(unit) - 1
    faces = np.concatenate([
        np.stack([np.zeros(nm, np.int64), idx[0], nxt[0]], 1),
        np.stack([idx[:-1].ravel(), idx[1:].ravel(), nxt[1:].ravel()], 1),
        np.stack([idx[:-1].ravel(), nxt[1:].ravel(), nxt[:-1].ravel()], 1),
        np.stack([np.full(nm, south), nxt[-1], idx[-1]], 1),
    ]).astype(np.int64)
    verts, norms = [], []
    for a, b, r in rods:
        a, b = np.asarray(a, np.float64) - origin, np.asarray(b, np.float64) - origin
        ab = b - a
        length = float(np.linalg.norm(ab))
        w = ab / length if length > 0 else np.array([0.0, 0.0, 1.0])
        e1 = np.cross(w, [1.0, 0.0, 0.0] if abs(w[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(w, e1)
        n = unit[:, :1] * e1 + unit[:, 1:2] * e2 + unit[:, 2:] * w  # the unit sphere about the axis
        inset = min(max(_BALL_INSET * r, 1.5 * edge * edge / (8.0 * r)), 0.25 * r)
        verts.append(np.where(up[:, None], b, a) + (r - inset) * n)
        norms.append(n)
    k = len(unit)
    return np.concatenate(verts), np.concatenate(norms), np.concatenate([faces + j * k for j in range(len(rods))])


def _pow24(a: np.ndarray) -> np.ndarray:
    """a ** _SHININESS (24) by five multiplications: a float power of 6·10⁴ values cost more
    than the rest of the lighting."""
    a2 = a * a
    a8 = (a2 * a2) ** 2
    return a8 * a8 * a8


def _light(right: np.ndarray, up: np.ndarray, toward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The unit light direction (from the viewer's upper left, in world coordinates) and the
    Blinn half vector, from the camera's right, up and toward-the-viewer axes."""
    light = -0.35 * right + 0.45 * up + 0.82 * toward
    light /= np.linalg.norm(light)
    half = light + toward
    half /= np.linalg.norm(half)
    return light, half


def _lit(normals: np.ndarray, rgb: np.ndarray, light: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Static geometry's vertices lit on their front: (V, 4) float32, the diffuse colour
    (wrapped Lambert times `rgb`) and the specular highlight."""
    out = np.empty((len(normals), 4), dtype=np.float32)
    out[:, :3] = (_AMBIENT + _DIFFUSE * np.maximum((normals @ light + _WRAP) / (1.0 + _WRAP), 0.0))[:, None] * rgb
    out[:, 3] = _SPECULAR * _pow24(np.maximum(normals @ half, 0.0))
    return out


class _MeshShader:
    """Lights and rasterises a mesh frame by frame (into the caller's image, at its size)."""

    def __init__(self, mesh: Mesh, theme: str, texture: np.ndarray | None = None, spheres: Any = (),
                 origin: np.ndarray | None = None, planes: Any = (), bounds: tuple[np.ndarray, np.ndarray] | None = None,
                 rods: Any = (), edge: float = 0.0):
        """`spheres`: the recording's sphere colliders ``(centre, radius, inside)``, m; in 3D the
        balls (not the bowls) are drawn with the mesh, shaded alike and in the same depth
        buffer, in their own colour; `origin`: the recording's origin (the mesh's positions
        are relative to it); `planes`: the recording's plane colliders ``(point, unit normal)``
        relative to the origin, drawn in 3D as floor patches around `bounds` (lo, hi), the
        scene's extent relative to the origin, in the same depth buffer."""
        self.faces = mesh.faces
        self.faces_u32 = np.ascontiguousarray(mesh.faces, dtype=np.uint32)
        self.uv = None if mesh.uv is None else np.ascontiguousarray(mesh.uv, dtype=np.float32)
        self.texture = texture
        self.front = np.array(_FRONT.get(theme, _FRONT["light"]), dtype=np.float32)
        self.back = np.array(_BACK.get(theme, _BACK["light"]), dtype=np.float32)
        o = None if origin is None else np.asarray(origin, dtype=np.float64)
        balls = None if o is None else _ball_geometry(spheres, o)
        spheres_rel = [] if o is None or len(o) != 3 else [(np.asarray(c, np.float64) - o, float(r)) for c, r, inside in spheres or () if not inside]
        rods_rel = [] if o is None or len(o) != 3 else [(np.asarray(a, np.float64) - o, np.asarray(b, np.float64) - o, float(r)) for a, b, r in rods]
        floors = None if bounds is None else _floor_geometry(planes, *bounds, theme, spheres_rel, rods_rel)
        bars = None if o is None else _rod_geometry(rods, o, edge)
        # Static geometry, one draw call with the sheet: floors and balls, each vertex its colour.
        parts = []
        # Floors seen from below are left out (they would hide everything): per floor, its
        # faces' range in the static faces and its normal, tested against the view each frame.
        self._floor_faces: list[tuple[int, int, np.ndarray]] = []
        if floors is not None:
            parts.append((floors[:3], floors[3]))
            per = 2 * _FLOOR_CELLS * _FLOOR_CELLS
            for j, (_, n) in enumerate(planes):
                self._floor_faces.append((j * per, (j + 1) * per, np.asarray(n, dtype=np.float64)))
        for geometry in (balls, bars):
            if geometry is not None:
                parts.append((geometry, np.tile(np.array(_BALL.get(theme, _BALL["light"]), np.float32), (len(geometry[0]), 1))))
        self.ball = None
        self.ball_rgb, self.ball_uv = np.zeros((0, 3), np.float32), None
        #: Vertices of each floor patch (they come first in the static geometry, floor after floor).
        self.floor_verts = 0 if floors is None else 4 * _FLOOR_CELLS * _FLOOR_CELLS
        if parts:
            k = np.cumsum([0] + [len(g[0]) for g, _ in parts])
            self.ball = (np.concatenate([g[0] for g, _ in parts]), np.concatenate([g[1] for g, _ in parts]),
                         np.concatenate([g[2] + k[j] for j, (g, _) in enumerate(parts)]))
            self.ball_rgb = np.concatenate([c for _, c in parts]).astype(np.float32)
        if self.ball is not None and texture is not None:
            self.ball_rgb, self.ball_uv = self._untextured(self.ball, self.ball_rgb)
        self._joined: tuple[Any, np.ndarray, np.ndarray | None] | None = None  # (key, faces, uv) with the balls

    def _untextured(self, geometry: tuple[np.ndarray, np.ndarray, np.ndarray], rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Colours and uv for static geometry (balls, floors, bodies) drawn with a textured
        sheet: the rasteriser multiplies by the texel at each vertex's uv, so every vertex
        samples the texture's brightest texel and its colour is divided by it (exact unless a
        channel of it is nearly 0)."""
        tex = self.texture
        h, w = tex.shape[:2]  # type: ignore[union-attr]
        ty, tx = np.unravel_index(int(np.argmax(tex.sum(axis=2))), (h, w))  # type: ignore[union-attr]
        uv = (tx / max(w - 1, 1), 1.0 - ty / max(h - 1, 1))
        return (rgb / np.maximum(tex[ty, tx], 0.05)).astype(np.float32), np.tile(np.array(uv, np.float32), (len(geometry[0]), 1))

    def draw(self, out: np.ndarray, x: np.ndarray, cam: Any, base: np.ndarray | None = None,
             solids: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None) -> None:
        """Frame `x` ((N, dim) positions relative to the recording's origin) lit, rasterised and
        blended by coverage over `out`, an (H, W, 3) uint8 C-contiguous RGB image, in place.

        `base`: optional (N, 3) per-vertex colours in [0, 1] (a colour map), replacing the front
        colour. `solids`: this frame's rigid bodies (3D), ``(vertices, normals, faces, rgb)`` as
        :func:`._bodies.body_geometry` gives them, drawn in the same depth buffer.
        """
        from .. import _core

        s, depth = cam.project(x)
        col, row = cam.pixels(s)
        xs = np.asarray(x, dtype=np.float64)
        if not np.isfinite(xs).all():  # a diverged vertex: its triangles are skipped, its normal 0
            xs = np.nan_to_num(xs, nan=0.0, posinf=0.0, neginf=0.0)
        # Light from the viewer's upper left, in world coordinates: the camera basis columns are
        # right, up and toward the viewer (a 2D scene lies in its screen plane, lit head-on).
        if xs.shape[1] == 3:
            right, up, toward = cam.basis[:, 0], cam.basis[:, 1], cam.basis[:, 2]
        else:
            xs = np.concatenate([xs, np.zeros((xs.shape[0], 1))], axis=1)
            right, up, toward = np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0])
        light, half = _light(right, up, toward)
        n = _core.mesh_normals(np.ascontiguousarray(xs), self.faces_u32)
        nl, nh = n @ light, n @ half
        # Each vertex lit on both sides: the front along n, the back along -n; the rasteriser
        # uses the side each triangle shows.
        front = np.empty((xs.shape[0], 4), dtype=np.float32)
        back = np.empty_like(front)
        diff_f = (_AMBIENT + _DIFFUSE * np.maximum((nl + _WRAP) / (1.0 + _WRAP), 0.0))[:, None]
        diff_b = (_AMBIENT + _DIFFUSE * np.maximum((_WRAP - nl) / (1.0 + _WRAP), 0.0))[:, None]
        # A texture or colours of one's own: the back is the same colour a shade darker (a tint
        # towards the fabric's back turned a flag's white stripe salmon pink).
        if self.texture is not None:
            front[:, :3] = diff_f
            back[:, :3] = diff_b * _BACK_SHADE
        elif base is not None:
            front[:, :3] = diff_f * base
            back[:, :3] = diff_b * _BACK_SHADE * base
        else:
            front[:, :3] = diff_f * self.front
            back[:, :3] = diff_b * self.back
        front[:, 3] = _SPECULAR * _pow24(np.maximum(nh, 0.0))
        back[:, 3] = _SPECULAR * _pow24(np.maximum(-nh, 0.0))
        verts = np.empty((xs.shape[0], 3), dtype=np.float32)
        with np.errstate(over="ignore"):  # a blown-up scene's far points: inf, off the picture
            verts[:, 0], verts[:, 1] = col, row
            verts[:, 2] = 0.0 if depth is None else depth
        faces, uv = self.faces_u32, self.uv if self.texture is not None else None
        static = self.ball
        ball_rgb, ball_uv = self.ball_rgb, self.ball_uv
        if solids is not None and depth is not None:
            # The bodies join the static geometry for this frame (after it: the floors' face
            # ranges stay where they are).
            sx, sn, sf, srgb = solids
            if static is None:
                static, ball_rgb = (sx, sn, sf), srgb
            else:
                static = (np.concatenate([static[0], sx]), np.concatenate([static[1], sn]),
                          np.concatenate([static[2], sf + len(static[0])]))
                ball_rgb = np.concatenate([ball_rgb, srgb])
            if uv is not None:
                ball_rgb, ball_uv = self._untextured(static, ball_rgb)
            self._joined = None
        if static is not None and depth is not None:
            # The balls: static vertices, lit like the sheet's front, appended to the one draw
            # call so that the depth buffer sorts sheet and balls per sample.
            bx, bn, bf = static
            nb = len(bx)
            bs, bd = cam.project(bx)
            bc, br = cam.pixels(bs)
            bl = _lit(bn, ball_rgb, light, half)
            bv = np.empty((nb, 3), dtype=np.float32)
            bv[:, 0], bv[:, 1], bv[:, 2] = bc, br, bd
            n = xs.shape[0]
            hidden = tuple(j for j, (_, _, fn) in enumerate(self._floor_faces) if fn @ toward <= 0)
            if self._joined is None or self._joined[0] != (n, hidden):
                keep = np.ones(len(bf), dtype=bool)
                for j in hidden:
                    a, b, _ = self._floor_faces[j]
                    keep[a:b] = False
                joined_uv = None if uv is None else np.ascontiguousarray(np.concatenate([uv, ball_uv]))
                self._joined = ((n, hidden), np.ascontiguousarray(np.concatenate([faces, (bf[keep] + n).astype(np.uint32)])),
                                joined_uv)
            _, faces, uv = self._joined
            verts, front, back = (np.concatenate([a, b]) for a, b in ((verts, bv), (front, bl), (back, bl)))
        self.drawn = (verts, faces)
        _core.rasterise_mesh(
            verts, faces, front, back, out, _SS,
            uv=uv, texture=self.texture,
        )

    def coverage(self, labels: np.ndarray, count: int, shape: tuple[int, int]) -> np.ndarray:
        """(count, H, W) float32: for each label 0 … count − 1, whether (1) or not (0) the
        last frame :meth:`draw` drew shows, at each pixel's centre of an image of `shape`, a
        triangle whose corners carry that label, in front of everything else drawn (the same
        triangles and depth buffer: the sheet, the balls and the bodies hide what lies behind
        them; one sample a pixel, a quarter of the drawing's). `labels`: (V,) int, one per
        vertex drawn (the sheet's, the static geometry's, then the bodies'), −1 for none.
        Three labels a pass, as the colour channels of a black image."""
        from .. import _core

        verts, faces = self.drawn
        h, w = shape
        out = np.zeros((count, h, w), dtype=np.float32)
        for first in range(0, count, 3):
            ink = np.zeros((len(verts), 4), dtype=np.float32)
            for c in range(min(3, count - first)):
                ink[labels == first + c, c] = 1.0
            img = np.zeros((h, w, 3), dtype=np.uint8)
            _core.rasterise_mesh(verts, faces, ink, ink, img, 1)
            for c in range(min(3, count - first)):
                out[first + c] = img[..., c] * np.float32(1.0 / 255.0)
        return out


def shade_solids(out: np.ndarray, cam: Any, solids: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]) -> None:
    """Lights and rasterises solid geometry ``(vertices, normals, faces, rgb)`` (3D, m relative
    to the recording's origin; :func:`._bodies.body_geometry`) over the RGB image `out`, in
    place, with the mesh shader's light, in a depth buffer of its own."""
    from .. import _core

    verts, normals, faces, rgb = solids
    if not len(faces):
        return
    light, half = _light(cam.basis[:, 0], cam.basis[:, 1], cam.basis[:, 2])
    s, depth = cam.project(verts)
    col, row = cam.pixels(s)
    lit = _lit(normals, rgb, light, half)
    v = np.empty((len(verts), 3), dtype=np.float32)
    v[:, 0], v[:, 1], v[:, 2] = col, row, depth
    _core.rasterise_mesh(v, np.ascontiguousarray(faces, dtype=np.uint32), lit, lit, out, _SS)
