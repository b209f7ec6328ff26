"""glTF 2.0 output: :func:`gltf` writes a Recording (or a scene, recorded first) as a binary glTF
(``.glb``) or a ``.gltf`` with its buffer embedded, through pygltflib (an optional extra,
``physcore[web]``); :func:`glb_bytes` is the file's content, which :mod:`._html`'s player embeds.

What the file holds (metres; the scene's +z up turned to glTF's +y up by the root node, a 2D
scene in the z = 0 plane, unturned):

- rigid bodies: one node each, its triangles in its own frame, a LINEAR translation and
  rotation animation (bodies that never move get none); one material per colour;
- a mesh over particles (cloth: the scene's ``render_defaults`` mesh, or ``mesh=``): one
  triangle primitive whose vertex motion is one morph target per frame after the first, the
  weights animated LINEAR (so a player interpolates between frames), with its normals;
- the particles no mesh covers: a POINTS primitive, moving by the same morph targets, and the
  springs between them as LINES;
- what stands still: sphere and capsule colliders (UV meshes), 3D planes (a checked floor patch),
  a fluid's boundary particles (grey points), a 2D scene's planes (a strip of their solid side)
  and box colliders (flat polygons).

The animation's clock is the playback's (frame k at k / fps s, as the GIF plays it); the scene's
own times, the recording's bounds, the view and a point size for players are in the scene's
``extras["physcore"]``.
"""
from __future__ import annotations

import base64
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError, InvalidTypeError, refusing_memory
from . import _recording
from ._camera import DEFAULT_VIEW, _view_basis
from ._checks import _check_colors, _check_fps, _check_int, _check_view
from ._mesh import _BALL, _FRONT, _ball_geometry, _floor_geometry, _rod_geometry, check_mesh
from ._palette import _BACKGROUND, _CMAPS, _PLANE_LINE, GROUP_COLORS, THEMES, theme_palette

#: The extra to install for glTF and HTML output.
INSTALL = 'pip install "physcore[web]"'

#: Extensions :func:`gltf` writes: binary glTF, or JSON with the buffer embedded as a data URI.
GLTF_FORMATS = (".glb", ".gltf")

#: Quaternion (x, y, z, w) turning a scene's +z up to glTF's +y up: -90 degrees about x,
#: (x, y, z) -> (x, z, -y).
_Z_UP = (-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))
#: The vertical field of view (radians) of the camera in the file, and of the player's (35 degrees).
_YFOV = math.radians(35.0)
#: Grey of boundary particles and 2D colliders.
_WALL_RGB = (150, 150, 150)
#: Opacity of a fluid's boundary particles (drawn half the size of the moving ones).
_WALL_ALPHA = 0.12
#: Particles from which the players' bounds leave out the farthest 0.5 % on each side (_bounds).
_CLOUD = 500

_GRID = ("scene: a grid scene (a field on a grid, no particles or bodies) has no glTF export; "
         "render it as a GIF or video")

_FLOAT, _UINT16, _UINT32 = 5126, 5123, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_POINTS, _LINES, _LINE_STRIP, _TRIANGLES = 0, 1, 3, 4


def pygltflib_module() -> Any:
    """pygltflib, or ImportError naming the extra that brings it."""
    try:
        import pygltflib
    except ImportError:
        raise ImportError(f"glTF and HTML output need pygltflib: {INSTALL}") from None
    return pygltflib


def _linear(rgb: Any) -> list[float]:
    """sRGB colour (3,) in [0, 255] -> glTF's linear baseColorFactor (4,)."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return [float(v) for v in lin] + [1.0]


def _to_linear(rgb01: np.ndarray) -> np.ndarray:
    """(V, 3) sRGB in [0, 1] -> linear (glTF's vertex colours are linear), float32."""
    c = np.clip(np.asarray(rgb01, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _pad3(x: np.ndarray) -> np.ndarray:
    """(..., 2 or 3) -> (..., 3), z = 0 for 2D."""
    if x.shape[-1] == 3:
        return x
    return np.concatenate([x, np.zeros((*x.shape[:-1], 1), dtype=x.dtype)], axis=-1)


def _held(x: np.ndarray) -> np.ndarray:
    """(F, ...) float array with non-finite entries replaced by that entry's last finite value
    (0 before any): glTF accessors hold finite numbers; a particle that left float32's range is
    shown where it was last seen."""
    if np.isfinite(x).all():
        return x
    out = np.array(x, copy=True)
    out[0][~np.isfinite(out[0])] = 0
    for k in range(1, len(out)):
        bad = ~np.isfinite(out[k])
        out[k][bad] = out[k - 1][bad]
    return out


class _Builder:
    """Accumulates a glTF document and its one binary buffer."""

    def __init__(self, g: Any) -> None:
        self.lib = pygltflib_module()
        self.g = g
        self.blob = bytearray()
        self.materials: dict[tuple, int] = {}

    def view(self, data: bytes, target: int | None = None) -> int:
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        self.g.bufferViews.append(self.lib.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data), target=target))
        self.blob.extend(data)
        return len(self.g.bufferViews) - 1

    def floats(self, a: np.ndarray, minmax: bool = False, vertex: bool = True) -> int:
        """An accessor of float32 rows (SCALAR, VEC3 or VEC4) in a view of its own."""
        a = np.ascontiguousarray(a, dtype=np.float32)
        kind = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}[1 if a.ndim == 1 else a.shape[1]]
        lo = hi = None
        if minmax:
            rows = a.reshape(len(a), -1)
            lo, hi = rows.min(axis=0).tolist(), rows.max(axis=0).tolist()
        v = self.view(a.tobytes(), _ARRAY_BUFFER if vertex else None)
        self.g.accessors.append(self.lib.Accessor(bufferView=v, componentType=_FLOAT, count=len(a), type=kind, min=lo, max=hi))
        return len(self.g.accessors) - 1

    def indices(self, idx: np.ndarray) -> int:
        idx = np.asarray(idx).reshape(-1)
        small = idx.size == 0 or int(idx.max()) < 65535
        a = np.ascontiguousarray(idx, dtype=np.uint16 if small else np.uint32)
        v = self.view(a.tobytes(), _ELEMENT_ARRAY_BUFFER)
        self.g.accessors.append(self.lib.Accessor(bufferView=v, componentType=_UINT16 if small else _UINT32,
                                                  count=int(a.size), type="SCALAR"))
        return len(self.g.accessors) - 1

    def material(self, rgb: Any, name: str, double: bool = False, lit: bool = True, alpha: float = 1.0) -> int:
        key = (tuple(int(c) for c in rgb), double, lit, alpha)
        if key not in self.materials:
            pbr = self.lib.PbrMetallicRoughness(baseColorFactor=_linear(rgb)[:3] + [alpha], metallicFactor=0.0, roughnessFactor=0.85)
            ext = {"KHR_materials_unlit": {}} if not lit else {}
            self.g.materials.append(self.lib.Material(name=name, pbrMetallicRoughness=pbr, doubleSided=double, extensions=ext,
                                                      alphaMode="BLEND" if alpha < 1 else "OPAQUE"))
            self.materials[key] = len(self.g.materials) - 1
            if not lit and "KHR_materials_unlit" not in self.g.extensionsUsed:
                self.g.extensionsUsed.append("KHR_materials_unlit")
        return self.materials[key]

    def node(self, name: str, **kw: Any) -> int:
        self.g.nodes.append(self.lib.Node(name=name, **kw))
        return len(self.g.nodes) - 1


def _static_mesh(b: _Builder, name: str, verts: np.ndarray, normals: np.ndarray | None, faces: np.ndarray | None,
                 material: int, mode: int = _TRIANGLES, colors: np.ndarray | None = None) -> int:
    lib = b.lib
    attrs = lib.Attributes(POSITION=b.floats(_pad3(np.asarray(verts, np.float64)), minmax=True))
    if normals is not None:
        attrs.NORMAL = b.floats(_pad3(np.asarray(normals, np.float64)))
    if colors is not None:
        attrs.COLOR_0 = b.floats(colors)
    prim = lib.Primitive(attributes=attrs, material=material, mode=mode,
                         indices=None if faces is None else b.indices(faces))
    b.g.meshes.append(lib.Mesh(name=name, primitives=[prim]))
    return len(b.g.meshes) - 1


def _normals(x: np.ndarray, faces_u32: np.ndarray) -> np.ndarray:
    """(N, 3) unit vertex normals of the triangles `faces_u32` over the (N, 3) vertices `x`."""
    from .. import _core

    return np.asarray(_core.mesh_normals(np.ascontiguousarray(x, dtype=np.float64), faces_u32))


def _morph_set(b: _Builder, name: str, x: np.ndarray, prims: list[tuple[int, np.ndarray | None, int, np.ndarray | None]],
               faces_for_normals: np.ndarray | None) -> int:
    """A mesh whose primitives share the moving vertices `x` (F, V, 3) float32 (relative to the
    origin): the base is frame 0, each later frame one morph target (its displacement), with
    normals when `faces_for_normals` is given. `prims`: (mode, indices or None, material,
    COLOR_0 or None). Returns the mesh index; its weights are animated by :func:`gltf`."""
    lib = b.lib
    base = x[0]
    attrs = lib.Attributes(POSITION=b.floats(base, minmax=True))
    targets = []
    fu = None if faces_for_normals is None else np.ascontiguousarray(faces_for_normals, dtype=np.uint32)
    n0 = None
    if fu is not None:
        n0 = _normals(base, fu).astype(np.float32)
        attrs.NORMAL = b.floats(n0)
    for k in range(1, len(x)):
        t = {"POSITION": b.floats((x[k] - base).astype(np.float32), minmax=True)}
        if fu is not None:
            t["NORMAL"] = b.floats(_normals(x[k], fu).astype(np.float32) - n0)
        targets.append(t)
    primitives = []
    for mode, idx, material, colors in prims:
        a = lib.Attributes(POSITION=attrs.POSITION, NORMAL=attrs.NORMAL if mode == _TRIANGLES else None)
        if colors is not None:
            a.COLOR_0 = b.floats(colors)
        primitives.append(lib.Primitive(attributes=a, indices=None if idx is None else b.indices(idx), material=material,
                                        mode=mode, targets=[dict(t) if mode == _TRIANGLES else {"POSITION": t["POSITION"]}
                                                            for t in targets] or None))
    b.g.meshes.append(lib.Mesh(name=name, primitives=primitives, weights=[0.0] * len(targets) or None,
                               extras={"targetNames": [f"frame {k}" for k in range(1, len(x))]} if targets else None))
    return len(b.g.meshes) - 1


def _point_size(x0: np.ndarray, radii: np.ndarray | None, diag: float) -> float:
    """A point's diameter (m) for players: twice the mean radius the scene gives its particles,
    else the median distance to the nearest other particle at frame 0 (of a sample of 256),
    kept within 0.4 % to 3 % of the scene's diagonal `diag` (a few balls launched from one
    point, or far apart, still show)."""
    if radii is not None and len(radii) and float(np.mean(radii)) > 0:
        return float(2.0 * np.mean(radii))
    lo, hi = 0.004 * diag, 0.03 * diag
    x = x0[np.isfinite(x0).all(axis=1)].astype(np.float64)
    if len(x) < 2:
        return hi
    rng = np.random.default_rng(0)
    s = x[rng.choice(len(x), size=min(256, len(x)), replace=False)]
    d = np.sqrt(((s[:, None, :] - x[None, :, :]) ** 2).sum(-1))
    d[d == 0] = np.inf
    near = d.min(axis=1)
    near = near[np.isfinite(near)]
    return float(np.clip(np.median(near), lo, hi)) if len(near) else hi


def _bounds(rec: Any, moving: np.ndarray | None, extent: Any) -> tuple[np.ndarray, np.ndarray]:
    """(3,) lower and upper corners (m, relative to the origin, scene axes) of what the
    recording shows over every frame: the `extent` render default if given, else its particles,
    bodies, walls and spheres. Of a cloud of particles (`_CLOUD` or more) the bounds hold the
    first frame whole and 99 % of the positions of every frame along each axis, so that a few
    escaping stars or drops do not shrink the rest to a speck."""
    dim = rec.positions.shape[2]
    if extent is not None:
        lo, hi = (_pad3(np.asarray(e, np.float64)[None] - rec.origin[None])[0] for e in extent)
        return lo, hi
    pts = []
    if moving is not None and moving.size:
        f = moving.reshape(-1, 3)
        f = f[np.isfinite(f).all(axis=1)]
        first = moving[0][np.isfinite(moving[0]).all(axis=1)]
        if moving.shape[1] >= _CLOUD and len(first):
            pts.append(np.quantile(f, [0.005, 0.995], axis=0))
            pts.append(first)
        else:
            pts.append(f)
    if rec.walls is not None and len(rec.walls):
        pts.append(_pad3(np.asarray(rec.walls, np.float64)))
    tr = rec.bodies
    if tr is not None and dim == 2:  # the outlines themselves
        from ._bodies import body_bounds

        blo, bhi = body_bounds(tr)
        if np.isfinite(blo).all() and np.isfinite(bhi).all():
            pts += [np.array([[blo[0], blo[1], 0.0], [bhi[0], bhi[1], 0.0]])]
    elif tr is not None:
        c = _pad3(tr.poses[:, :, :dim].astype(np.float64)).reshape(-1, 3)
        r = np.tile(tr.reach, tr.poses.shape[0])
        ok = np.isfinite(c).all(axis=1)
        pts += [c[ok] - r[ok, None], c[ok] + r[ok, None]]
    for c, r, inside in rec.spheres:
        if not inside:
            c = _pad3(np.asarray(c, np.float64) - rec.origin)
            pts += [(c - r)[None], (c + r)[None]]
    pts = [p for p in pts if len(p)]
    if not pts:
        return np.full(3, -0.5), np.full(3, 0.5)
    allp = np.concatenate(pts)
    return allp.min(axis=0), allp.max(axis=0)


def _camera_pose(lo: np.ndarray, hi: np.ndarray, toward: np.ndarray, aspect: float,
                 yfov: float) -> tuple[np.ndarray, np.ndarray, float, float]:
    """A perspective camera looking along -`toward` at the box [lo, hi] (glTF world axes, +y up)
    from as near as shows the whole box (the player's fit, _player.js): its position (3,), its
    rotation (x, y, z, w) (glTF cameras look along their -z, +y up) and znear, zfar (m)."""
    centre = 0.5 * (lo + hi)
    d = np.asarray(toward, np.float64) / np.linalg.norm(toward)
    up = np.array([0.0, 0.0, -1.0]) if abs(d[1]) > 0.999 else np.array([0.0, 1.0, 0.0])
    right = np.cross(up, d)
    right /= np.linalg.norm(right)
    upv = np.cross(d, right)
    tan = math.tan(yfov / 2)
    corners = np.array([[hi[0] if i & 1 else lo[0], hi[1] if i & 2 else lo[1], hi[2] if i & 4 else lo[2]] for i in range(8)]) - centre
    need = np.maximum(np.abs(corners @ upv) / tan, np.abs(corners @ right) / (tan * aspect))
    dist = max(float(np.max(1.08 * need + corners @ d)), 1e-6)
    reach = float(np.max(np.linalg.norm(corners, axis=1)))
    m = np.stack([right, upv, d], axis=1)  # the camera's axes, as columns
    w = math.sqrt(max(1.0 + m[0, 0] + m[1, 1] + m[2, 2], 0.0)) / 2
    if w > 1e-6:
        q = np.array([(m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w), (m[1, 0] - m[0, 1]) / (4 * w), w])
    else:  # a half turn: the axis from the diagonal
        k = int(np.argmax(np.diag(m)))
        i, j = (k + 1) % 3, (k + 2) % 3
        s = math.sqrt(max(1.0 + m[k, k] - m[i, i] - m[j, j], 0.0)) * 2
        q = np.zeros(4)
        q[k], q[i], q[j], q[3] = s / 4, (m[i, k] + m[k, i]) / s, (m[j, k] + m[k, j]) / s, (m[j, i] - m[i, j]) / s
    q /= np.linalg.norm(q)
    near = max(dist - 2 * reach, dist / 1000, 1e-6)
    return centre + dist * d, q, near, dist + 20 * reach + 1e-3


def _backdrop(look: Any) -> tuple[tuple[int, ...], tuple[int, ...]] | None:
    """The (top, bottom) sRGB colours of a scene's ``render_defaults`` look's backdrop (a dict or
    a :class:`Look`), or None; players draw it as a vertical gradient behind the scene."""
    b = look.get("backdrop") if isinstance(look, dict) else getattr(look, "backdrop", None)
    try:
        top, bottom = (tuple(int(v) for v in np.clip(np.asarray(c, np.float64), 0, 255)) for c in b)
    except (TypeError, ValueError):
        return None
    return (top, bottom) if len(top) == 3 and len(bottom) == 3 else None


def _check_recording(source: Any) -> None:
    if isinstance(source, _recording.Recording):
        return
    if not (hasattr(source, "positions") and hasattr(source, "step") and hasattr(source, "dim")):
        raise InvalidTypeError(f"scene: expected a physcore scene or a render.Recording, got {type(source).__name__}")


def _check_out(path: Any, exts: tuple[str, ...]) -> Path:
    from ._checks import _check_no_nul

    if not isinstance(path, (str, os.PathLike)):
        raise InvalidTypeError(f"path must be a str or os.PathLike, got {type(path).__name__}")
    _check_no_nul(path)
    p = Path(path)
    if p.suffix.lower() not in exts:
        raise InvalidInputError(f"path must end in {' or '.join(exts)}, got {str(p)!r}")
    if not p.parent.is_dir():
        raise InvalidInputError(f"path: directory {str(p.parent)!r} does not exist")
    if p.is_dir():
        raise InvalidInputError(f"path {str(p)!r} is a directory")
    return p


def _prepare(source: Any, *, frames: Any, steps_per_frame: Any, frame_time: Any, substeps: Any, fps: Any, mesh: Any,
             theme: Any, view: Any, progress: bool, before_simulating: Any = None) -> tuple[Any, dict[str, Any]]:
    """The recording to export and its checked options (fps, mesh, theme, view, defaults); a
    scene is recorded (positions only, as :func:`record` does with ``color_by="none"``), after
    every check has passed and `before_simulating()` has run."""
    from .. import _check

    _check_recording(source)
    progress = _check.flag("progress", progress)
    if isinstance(source, _recording.Recording):
        given = [a for a, v in (("frames", frames), ("steps_per_frame", steps_per_frame), ("frame_time", frame_time),
                                ("substeps", substeps)) if v is not None]
        if given:
            raise InvalidInputError(f"{given[0]}: a Recording is already simulated; give it to record() instead")
        d = dict(source.defaults or {})
        n, dim = source.positions.shape[1], source.positions.shape[2]
    else:
        scene = _recording.points_view(source)
        d = _recording.scene_defaults(scene)
        n, dim = int(getattr(scene, "n_particles", 0)), int(getattr(scene, "dim", 0))
    if dim not in (2, 3):
        raise InvalidInputError(f"scene.dim must be 2 or 3, got {dim}")
    if not isinstance(source, _recording.Recording):
        from ._fields import grid_plan

        bodies = [g for g in getattr(scene, "bodies", ()) if getattr(g, "first", None) is not None]
        if n == 0 and not bodies and grid_plan(scene) is not None:
            raise InvalidInputError(_GRID)
    fps = _check_fps(d.get("fps", 30.0) if fps is None else fps)
    theme = d.get("theme", "light") if theme is None else theme
    theme = _check.choice("theme", theme, THEMES)
    view = _check_view(d.get("view") if view is None else view)
    mesh = check_mesh(d.get("mesh") if mesh is None else mesh, n)
    colors = _check_colors(d.get("colors"), n)
    opts = {"fps": fps, "theme": theme, "view": view or DEFAULT_VIEW, "mesh": mesh, "colors": colors, "defaults": d}
    if frames is not None and not isinstance(source, _recording.Recording):
        frames = _check_int("frames", frames, 1)
    # glTF's animation clock is float32, its key times finite and strictly increasing: frame k
    # at k / fps (fps = 1e-300 overflowed it, fps = 1e308 put every frame at 0).
    count = source.positions.shape[0] if isinstance(source, _recording.Recording) else frames or d.get("frames", 90)
    if isinstance(count, int) and count > 1:
        with np.errstate(over="ignore"):
            keys = (np.arange(count, dtype=np.float64) / fps).astype(np.float32)
        if not (np.isfinite(keys).all() and (np.diff(keys) > 0).all()):
            raise InvalidInputError(f"fps: {fps:g} gives {count} frames no distinct finite times on glTF's float32 "
                                    "clock (frame k at k / fps s); give an fps between about 1e-36 and 1e36")
    if before_simulating is not None:
        before_simulating()
    if isinstance(source, _recording.Recording):
        rec = source
    else:
        rec = _recording.record(source, frames=frames, steps_per_frame=steps_per_frame, frame_time=frame_time,
                                substeps="auto" if substeps is None else substeps, color_by="none", progress=progress,
                                velocities=False)
    if rec.fields is not None and rec.positions.shape[1] == 0 and rec.bodies is None:
        raise InvalidInputError(_GRID)
    return rec, opts


def glb_bytes(rec: Any, fps: float, theme: str, view: tuple[float, float], mesh: Any, colors: np.ndarray | None,
              defaults: dict[str, Any], embed: bool = False) -> bytes:
    """The binary glTF of `rec` (checked options; see :func:`gltf`), or with `embed` the JSON
    glTF with its buffer as a base64 data URI."""
    lib = pygltflib_module()
    g = lib.GLTF2(asset=lib.Asset(generator="physcore", version="2.0"), scene=0)
    b = _Builder(g)
    dim = rec.positions.shape[2]
    F, N = rec.positions.shape[:2]
    x = _pad3(_held(rec.positions)).astype(np.float32)  # (F, N, 3) relative to the origin
    origin = _pad3(np.asarray(rec.origin, np.float64)[None])[0]
    times = np.arange(F, dtype=np.float64) / fps
    t_acc = b.floats(times.astype(np.float32), minmax=True, vertex=False) if F > 1 else None
    channels, samplers = [], []

    def animate(node: int, path: str, values: np.ndarray, interpolation: str = "LINEAR") -> None:
        samplers.append(lib.AnimationSampler(input=t_acc, output=b.floats(values, vertex=False), interpolation=interpolation))
        channels.append(lib.AnimationChannel(sampler=len(samplers) - 1, target=lib.AnimationChannelTarget(node=node, path=path)))

    children: list[int] = []
    # The mesh over the particles, and the particles it leaves out as points (with their springs).
    in_mesh = np.zeros(N, dtype=bool)
    edge = 0.0
    if mesh is not None:
        in_mesh[mesh.faces.reshape(-1)] = True
        used = np.flatnonzero(in_mesh)
        remap = np.full(N, -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        faces = remap[mesh.faces]
        xm = x[:, used]
        e = xm[0][faces[:, 1]] - xm[0][faces[:, 0]]
        edge = float(np.median(np.linalg.norm(e, axis=1))) if len(e) else 0.0
        rgb = _FRONT.get(theme, _FRONT["light"])
        vcol = None
        if colors is not None:
            vcol, rgb = _to_linear(colors[used] / 255.0), (1.0, 1.0, 1.0)
        mat = b.material(np.array(rgb) * 255.0, "cloth", double=True)
        m = _morph_set(b, "cloth", xm, [(_TRIANGLES, faces, mat, vcol)], faces)
        children.append(b.node("cloth", mesh=m))
    free = np.flatnonzero(~in_mesh)
    lo, hi = _bounds(rec, x if N else None, defaults.get("extent"))
    point_size = _point_size(x[0][free] if len(free) else x[0], None if rec.radii is None else rec.radii,
                             max(float(np.linalg.norm(hi - lo)), 1e-9))
    if len(free):
        xp = x[:, free]
        if colors is not None:
            vcol, rgb = _to_linear(colors[free] / 255.0), (255, 255, 255)
        else:
            vcol = None
            cmap = defaults.get("cmap")
            rgb = _CMAPS[cmap][len(_CMAPS[cmap]) * 2 // 5] if cmap in _CMAPS else GROUP_COLORS[0]
        prims = [(_POINTS, None, b.material(rgb, "particles", lit=False), vcol)]
        if mesh is None and rec.pairs is not None and len(rec.pairs[0]):
            remap = np.full(N, -1, dtype=np.int64)
            remap[free] = np.arange(len(free))
            i, j = remap[rec.pairs[0]], remap[rec.pairs[1]]
            keep = (i >= 0) & (j >= 0)
            if keep.any():
                prims.append((_LINES, np.stack([i[keep], j[keep]], 1), b.material((120, 120, 120), "springs", lit=False), None))
        m = _morph_set(b, "particles", xp, prims, None)
        children.append(b.node("particles", mesh=m, extras={"physcore": {"point_size": point_size}}))
    morph_nodes = [k for k in children]
    # Rigid bodies: a node each, posed every frame.
    tr = rec.bodies
    if tr is not None:
        poses = _held(tr.poses.astype(np.float64))
        geo_cache: dict[tuple, int] = {}
        for k in range(len(tr.reach)):
            if dim == 3:
                sel = tr.owner == k
                first = int(np.flatnonzero(sel)[0])
                verts, normals = tr.local[sel], tr.normals[sel]
                faces = tr.faces[np.isin(tr.faces[:, 0], np.flatnonzero(sel))] - first
                # The body's colour is its brightest vertex's (a ball's second half is a shade darker).
                base = tr.rgb[sel].max(axis=0)
                color = np.rint(np.clip(base, 0, 1) * 255).astype(np.uint8)
                shade = tr.rgb[sel] / np.maximum(base, 1e-6)
                vcol = _to_linear(shade) if (shade < 0.99).any() else None
                mode, double = _TRIANGLES, False
            else:
                o = np.asarray(tr.outlines[k], np.float64)
                verts, normals = o, np.tile([0.0, 0.0, 1.0], (len(o), 1))
                if tr.chains[k]:
                    faces, mode = None, _LINE_STRIP
                    normals = None
                else:
                    faces, mode = np.stack([np.zeros(len(o) - 2, np.int64), np.arange(1, len(o) - 1), np.arange(2, len(o))], 1), _TRIANGLES
                vcol, double, color = None, True, tr.colors[k]
            key = (np.asarray(verts).tobytes(), None if faces is None else np.asarray(faces).tobytes(), tuple(color.tolist()),
                   None if vcol is None else vcol.tobytes(), mode)
            if key not in geo_cache:
                mat = b.material(color, f"body {tuple(int(c) for c in color)}", double=double)
                geo_cache[key] = _static_mesh(b, f"body {k}", verts, normals, faces, mat, mode, vcol)
            p = poses[:, k]
            if dim == 3:
                pos, q = p[:, :3], p[:, 3:7]
            else:
                pos = np.concatenate([p[:, :2], np.zeros((F, 1))], axis=1)
                q = np.stack([np.zeros(F), np.zeros(F), np.sin(p[:, 2] / 2), np.cos(p[:, 2] / 2)], axis=1)
            q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-300)
            # Consecutive quaternions on the same hemisphere: LINEAR (slerp) takes the short way.
            for f in range(1, F):
                if float(q[f] @ q[f - 1]) < 0:
                    q[f] = -q[f]
            node = b.node(f"body {k}", mesh=geo_cache[key], translation=pos[0].tolist(), rotation=q[0].tolist())
            children.append(node)
            if F > 1 and not (np.all(pos == pos[0]) and np.all(q == q[0])):
                animate(node, "translation", pos.astype(np.float32))
                animate(node, "rotation", q.astype(np.float32))
    # What stands still: balls, rods, floors, walls, 2D box colliders.
    balls = _ball_geometry(rec.spheres, np.asarray(rec.origin, np.float64)) if dim == 3 else None
    if balls is not None:
        mat = b.material(np.array(_BALL.get(theme, _BALL["light"])) * 255, "ball")
        children.append(b.node("balls", mesh=_static_mesh(b, "balls", balls[0], balls[1], balls[2], mat)))
    rods = _rod_geometry(rec.rods, np.asarray(rec.origin, np.float64), edge) if dim == 3 else None
    if rods is not None:
        mat = b.material(np.array(_BALL.get(theme, _BALL["light"])) * 255, "ball")
        children.append(b.node("rods", mesh=_static_mesh(b, "rods", rods[0], rods[1], rods[2], mat)))
    if dim == 3 and rec.planes:
        spheres_rel = [(np.asarray(c, np.float64) - rec.origin, float(r)) for c, r, inside in rec.spheres if not inside]
        rods_rel = [(np.asarray(a, np.float64) - rec.origin, np.asarray(bb, np.float64) - rec.origin, float(r)) for a, bb, r in rec.rods]
        planes_rel = [(np.asarray(pt, np.float64) - rec.origin, np.asarray(nrm, np.float64)) for pt, nrm in rec.planes]
        fl = _floor_geometry(planes_rel, lo, hi, theme, spheres_rel, rods_rel)
        if fl is not None:
            mat = b.material((255, 255, 255), "floor")
            children.append(b.node("floor", mesh=_static_mesh(b, "floor", fl[0], fl[1], fl[2], mat, colors=_to_linear(fl[3]))))
    if rec.walls is not None and len(rec.walls):
        # Faint, so that the water inside a closed tank shows through (the GIF draws them under it).
        mat = b.material(_WALL_RGB, "walls", lit=False, alpha=_WALL_ALPHA)
        walls = _held(np.asarray(rec.walls, np.float64)[None])[0]
        children.append(b.node("walls", mesh=_static_mesh(b, "walls", walls, None, None, mat, _POINTS),
                               extras={"physcore": {"point_size": 0.5 * point_size}}))
    if dim == 2 and rec.planes:  # a 2D plane: a strip of its solid side along the edge, as the GIF shades it
        span = 2.0 * max(float(np.max(hi[:2] - lo[:2])), 1e-9)
        centre = 0.5 * (lo[:2] + hi[:2])
        pal = theme_palette(theme)
        for k, (pt, nrm) in enumerate(rec.planes):
            pt, nrm = np.asarray(pt, np.float64) - rec.origin[:2], np.asarray(nrm, np.float64)
            c = centre - ((centre - pt) @ nrm) * nrm
            t = np.array([-nrm[1], nrm[0]])
            quad = np.array([c - span * t, c + span * t, c + span * t - 0.03 * span * nrm, c - span * t - 0.03 * span * nrm])
            mat = b.material(pal[_PLANE_LINE], "plane", double=True)
            children.append(b.node(f"plane {k}", mesh=_static_mesh(b, f"plane {k}", quad, np.tile([0.0, 0, 1], (4, 1)),
                                                                  np.array([[0, 1, 2], [0, 2, 3]]), mat)))
    for k, poly in enumerate(rec.polygons):
        poly = np.asarray(poly, np.float64) - rec.origin[:2]
        fan = np.stack([np.zeros(len(poly) - 2, np.int64), np.arange(1, len(poly) - 1), np.arange(2, len(poly))], 1)
        mat = b.material(_WALL_RGB, "collider", double=True)
        children.append(b.node(f"collider {k}", mesh=_static_mesh(b, f"collider {k}", poly, np.tile([0.0, 0, 1], (len(poly), 1)), fan, mat)))
    if F > 1:
        eye = np.eye(F - 1, dtype=np.float32)
        weights = np.concatenate([np.zeros((1, F - 1), np.float32), eye]).reshape(-1)
        for node in morph_nodes:
            animate(node, "weights", weights)
    if channels:
        g.animations.append(lib.Animation(name="physcore", samplers=samplers, channels=channels))
    inner = b.node("origin", translation=origin.tolist(), children=children)
    root = b.node("physcore", rotation=list(_Z_UP) if dim == 3 else None, children=[inner])

    # For players: the bounds and the view direction in glTF's world axes (+y up).
    def world(p: np.ndarray) -> np.ndarray:
        return np.array([p[0], p[2], -p[1]]) if dim == 3 else p

    a, c = world(lo + origin), world(hi + origin)
    toward = world(_view_basis(*view)[:, 2]) if dim == 3 else np.array([0.0, 0.0, 1.0])
    # A camera for viewers that open a file's own (Blender imports it): the player's view.
    size = defaults.get("size", (480, 360))
    aspect = float(size[0]) / float(size[1]) if len(size) == 2 and float(size[1]) > 0 else 4.0 / 3.0
    eye, quat, near, far = _camera_pose(np.minimum(a, c), np.maximum(a, c), toward, aspect, _YFOV)
    g.cameras.append(lib.Camera(type="perspective", name="view", perspective=lib.Perspective(
        aspectRatio=aspect, yfov=_YFOV, znear=near, zfar=far)))
    cam = b.node("camera", camera=0, translation=eye.tolist(), rotation=quat.tolist())
    bg = defaults.get("background")
    bg = tuple(int(v) for v in theme_palette(theme)[_BACKGROUND]) if bg is None else tuple(int(v) for v in bg)
    backdrop = _backdrop(defaults.get("look"))
    if backdrop is not None:  # the GIF's gradient; its mean stands for it where one colour is wanted
        bg = tuple(int(round((a + c) / 2)) for a, c in zip(*backdrop, strict=True))
    scene_times = rec.times if rec.times is not None else times
    title = defaults.get("title")
    g.scenes.append(lib.Scene(name="physcore", nodes=[root, cam], extras={"physcore": {
        "frames": int(F), "fps": float(fps), "dim": int(dim),
        "times": [float(t) for t in _held(np.asarray(scene_times, np.float64)[:, None])[:, 0]],
        "bounds": [np.minimum(a, c).tolist(), np.maximum(a, c).tolist()],
        "view": [float(v) for v in toward], "point_size": point_size,
        "background": list(bg), "theme": theme, "title": title if isinstance(title, str) else "",
        **({"backdrop": [list(c) for c in backdrop]} if backdrop is not None else {}),
    }}))
    b.blob.extend(b"\0" * (-len(b.blob) % 4))
    if embed:
        g.buffers.append(lib.Buffer(byteLength=len(b.blob),
                                    uri="data:application/octet-stream;base64," + base64.b64encode(bytes(b.blob)).decode("ascii")))
        return g.gltf_to_json(separators=(",", ":"), indent=None).encode("utf-8")
    g.buffers.append(lib.Buffer(byteLength=len(b.blob)))
    g.set_binary_blob(bytes(b.blob))
    return b"".join(g.save_to_bytes())


@refusing_memory("gltf", "the frames")
def gltf(
    scene: Any,
    path: str | os.PathLike,
    *,
    frames: int | None = None,
    steps_per_frame: int | None = None,
    frame_time: float | None = None,
    substeps: str | int | None = None,
    fps: float | None = None,
    mesh: Any = None,
    theme: str | None = None,
    view: tuple[float, float] | None = None,
    progress: bool = False,
) -> Path:
    """Write a scene's motion as glTF 2.0: a binary ``.glb``, or a ``.gltf`` with its buffer
    embedded; for Blender, three.js, model viewers (:func:`html` plays it in a browser).

    Rigid bodies are nodes with a LINEAR translation and rotation animation; a mesh over
    particles (a cloth) moves by one morph target per frame after the first, its weights
    animated LINEAR (one key per frame); particles outside a mesh are points (and their springs
    lines) moving by the same morph targets; colliders that stand still (balls, capsules, 3D
    floors, a fluid's boundary particles, 2D boxes) are static meshes or points. Colours are
    materials: the scene's own (bodies' colours, ``render_defaults`` ``colors``), else the GIF's.

    Units are metres, with the scene's +z turned to glTF's +y up (the root node's rotation);
    the animation runs on the playback clock, frame k at k / `fps` seconds (as the GIF plays);
    the scene's own time of each frame is in ``scenes[0].extras["physcore"]["times"]`` (s).
    A 2D scene lies in the z = 0 plane (its +y already up). Non-finite positions (a particle
    beyond float32) are held at their last finite value. The size grows as frames × the
    moving vertices × 24 bytes (positions and normals of each frame).

    Parameters
    ----------
    scene : physcore.Scene or Recording
        A scene is recorded first, as :func:`record` does (its ``render_defaults``: frames and
        stepping); a :class:`Recording` is written as it is.
    path : str or os.PathLike
        Ends in ``.glb`` or ``.gltf``; its directory must exist and be writable (checked before
        simulating). Written atomically.
    frames, steps_per_frame, frame_time, substeps, progress
        As for :func:`record` (a scene only).
    fps : float, optional
        Frames per second of playback (default: the scene's, else 30).
    mesh : physcore.render.Mesh, (T, 3) int array or False, optional
        Triangles over the particles (default: the scene's, e.g. a cloth's grid); False: all
        particles as points.
    theme : {"light", "dark"}, optional
        Colours of cloth, balls and floor, and the background players use.
    view : (azimuth, elevation), optional
        Degrees, the initial camera a player takes (default: the scene's, else
        ``DEFAULT_VIEW``); in ``extras`` only.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    ImportError
        Without pygltflib, naming the extra to install (``pip install "physcore[web]"``), before
        simulating.
    physcore.InvalidTypeError
        `scene` neither a scene nor a Recording, `path` not a path (naming the argument).
    physcore.InvalidInputError
        `path` not ending in .glb/.gltf or its directory missing; a grid scene (fields only);
        bad options, each naming itself; all before simulating.
    physcore.SimulationDiverged, OSError
        As :func:`gif`: no file is left behind.

    Examples
    --------
    >>> import os, tempfile
    >>> import physcore as pc
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     out = pc.render.gltf(pc.scenes.cloth_on_ball(n=8), os.path.join(tmp, "cloth.glb"), frames=4)
    ...     out.suffix, out.read_bytes()[:4]
    ('.glb', b'glTF')
    """
    from .._atomic import atomic_write
    from ._checks import _check_writable

    p = _check_out(path, GLTF_FORMATS)
    pygltflib_module()
    rec, opts = _prepare(scene, frames=frames, steps_per_frame=steps_per_frame, frame_time=frame_time, substeps=substeps,
                         fps=fps, mesh=mesh, theme=theme, view=view, progress=progress,
                         before_simulating=lambda: _check_writable(p))
    data = glb_bytes(rec, opts["fps"], opts["theme"], opts["view"], opts["mesh"], opts["colors"], opts["defaults"],
                     embed=p.suffix.lower() == ".gltf")
    return atomic_write(p, lambda fh: fh.write(data))
