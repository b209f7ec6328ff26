"""glTF 2.0 export and the HTML player's file (issue 67): ``render.gltf`` / ``render.html`` /
``physcore render NAME -o x.glb|x.html``.

Each file is read back by pygltflib and by a second reader (trimesh), and what it holds is
compared with the scene's own data, not with the exporter's: the particles' positions at a frame
with the scene's state (the scene is left at the last frame), the bodies' poses with the scene's
body groups (positions, orientations or angles), their triangles with the groups' own meshes, the
materials with the groups' colours. The structure is checked as a validator would: buffer and
view bounds, accessor counts and min/max, animation channel targets and sampler lengths. The
player in a real browser is tests/render/test_web_browser.py.
"""
from __future__ import annotations

import base64
import json
import math
import sys

import numpy as np
import pytest

import physcore as pc
from physcore import InvalidInputError, InvalidTypeError, PhyscoreError

pygltflib = pytest.importorskip("pygltflib", reason='pygltflib is not installed (pip install "physcore[web]")')

FRAMES = 6
#: The issue's four scenes (a 3D fluid: the cheapest, drop at 20 particles across the tank).
SCENES = {
    "tablecloth": lambda: pc.scenes.tablecloth(),
    "pyramid": lambda: pc.scenes.pyramid(),
    "cloth_on_ball": lambda: pc.scenes.cloth_on_ball(),
    "drop": lambda: pc.scenes.drop(dim=3, n=20),
}
_DT = {5126: np.float32, 5123: np.uint16, 5125: np.uint32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """name -> (scene left at the last frame, its Recording, the .glb written from it, seconds taken)."""
    import time

    out = {}
    tmp = tmp_path_factory.mktemp("glb")
    for name, make in SCENES.items():
        scene = make()
        rec = pc.render.record(scene, frames=FRAMES, color_by="none")
        t0 = time.perf_counter()
        path = pc.render.gltf(rec, tmp / f"{name}.glb")
        out[name] = (scene, rec, path, time.perf_counter() - t0)
    return out


def _accessor(g, blob: bytes, i: int) -> np.ndarray:
    a = g.accessors[i]
    v = g.bufferViews[a.bufferView]
    w = _WIDTH[a.type]
    arr = np.frombuffer(blob, _DT[a.componentType], a.count * w, v.byteOffset + (a.byteOffset or 0))
    return arr.reshape(a.count, w) if w > 1 else arr


def _load(path):
    g = pygltflib.GLTF2().load(str(path))
    return g, g.binary_blob()


def _node(g, name: str):
    (k,) = [k for k, n in enumerate(g.nodes) if n.name == name]
    return k, g.nodes[k]


def _srgb_to_linear(rgb) -> np.ndarray:
    c = np.asarray(rgb, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _quat_rotate(q, v: np.ndarray) -> np.ndarray:
    """Rotate the rows of v (N, 3) by the unit quaternion q (x, y, z, w)."""
    x, y, z, w = q
    u = np.array([x, y, z])
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def _morph_positions(g, blob, mesh_name: str, k: int) -> np.ndarray:
    """Frame k's vertices of a morphing mesh: the base plus target k - 1 (m, relative to the origin node)."""
    (mesh,) = [m for m in g.meshes if m.name == mesh_name]
    prim = mesh.primitives[0]
    x = _accessor(g, blob, prim.attributes.POSITION).astype(np.float64)
    if k:
        x = x + _accessor(g, blob, prim.targets[k - 1]["POSITION"])
    return x


@pytest.mark.parametrize("name", list(SCENES))
def test_the_file_is_well_formed(recorded, name):
    """As a validator checks: the GLB's buffer and views in bounds, every accessor inside its
    view, POSITION min/max the data's, indices inside their vertices, morph targets alike on
    every primitive, the channels' targets present and their samplers one key per frame."""
    scene, rec, path, _ = recorded[name]
    g, blob = _load(path)
    assert g.asset.version == "2.0"
    assert len(g.buffers) == 1 and g.buffers[0].byteLength == len(blob) and len(blob) % 4 == 0
    for v in g.bufferViews:
        assert v.buffer == 0 and v.byteOffset % 4 == 0 and v.byteOffset + v.byteLength <= len(blob)
    for i, a in enumerate(g.accessors):
        v = g.bufferViews[a.bufferView]
        item = np.dtype(_DT[a.componentType]).itemsize * _WIDTH[a.type]
        assert (a.byteOffset or 0) + a.count * item <= v.byteLength
        data = _accessor(g, blob, i)
        assert np.isfinite(data).all()
        if a.min:
            np.testing.assert_array_equal(np.asarray(a.min, np.float32), data.reshape(a.count, -1).min(axis=0))
            np.testing.assert_array_equal(np.asarray(a.max, np.float32), data.reshape(a.count, -1).max(axis=0))
    for mesh in g.meshes:
        counts = {len(p.targets or []) for p in mesh.primitives}
        assert len(counts) == 1
        for p in mesh.primitives:
            a = g.accessors[p.attributes.POSITION]
            assert a.type == "VEC3" and len(a.min) == len(a.max) == 3  # required by the spec
            if p.indices is not None:
                assert _accessor(g, blob, p.indices).max() < a.count
            for t in p.targets or []:
                assert g.accessors[t["POSITION"]].count == a.count and len(g.accessors[t["POSITION"]].min) == 3
        targets = counts.pop()
        if targets:  # the moving meshes: one target per frame after the first, weights 0 at rest
            assert targets == FRAMES - 1 and list(mesh.weights) == [0.0] * targets
    (anim,) = g.animations
    fps = float(rec.defaults.get("fps", 30.0))
    for ch in anim.channels:
        s = anim.samplers[ch.sampler]
        t = _accessor(g, blob, s.input)
        np.testing.assert_allclose(t, np.arange(FRAMES) / fps, rtol=1e-6)
        out = g.accessors[s.output]
        node = g.nodes[ch.target.node]
        if ch.target.path == "weights":
            assert node.mesh is not None and out.count == FRAMES * (FRAMES - 1)
        else:
            assert ch.target.path in ("translation", "rotation") and node.name.startswith("body")
            assert out.count == FRAMES and out.type == ("VEC3" if ch.target.path == "translation" else "VEC4")
    extras = g.scenes[0].extras["physcore"]
    assert extras["frames"] == FRAMES and extras["dim"] == scene.dim
    np.testing.assert_allclose(extras["times"], rec.times)


@pytest.mark.parametrize("name", ["tablecloth", "cloth_on_ball", "drop"])
def test_the_moving_vertices_are_the_scenes_positions(recorded, name):
    """The cloth's (or the water's) vertices at the last frame, base plus the last morph target
    plus the origin node's translation, are the scene's positions now to float32 rounding; at
    every frame they are the recording's; and the weights animation shows target k - 1 alone at
    frame k."""
    scene, rec, path, _ = recorded[name]
    g, blob = _load(path)
    _, origin = _node(g, "origin")
    mesh_name = "cloth" if name != "drop" else "particles"
    x = _morph_positions(g, blob, mesh_name, FRAMES - 1) + np.asarray(origin.translation)
    truth = np.asarray(scene.positions, np.float64)
    scale = float(np.abs(truth).max())
    np.testing.assert_allclose(x, truth, rtol=0, atol=4 * np.finfo(np.float32).eps * max(scale, 1.0))
    for k in range(FRAMES):
        np.testing.assert_allclose(_morph_positions(g, blob, mesh_name, k), rec.positions[k], rtol=0, atol=1e-6 * max(scale, 1.0))
    (anim,) = g.animations
    (ch,) = [c for c in anim.channels if c.target.path == "weights" and g.nodes[c.target.node].name == mesh_name]
    w = _accessor(g, blob, anim.samplers[ch.sampler].output).reshape(FRAMES, FRAMES - 1)
    np.testing.assert_array_equal(w, np.vstack([np.zeros(FRAMES - 1), np.eye(FRAMES - 1)]))
    # Scene +z up is glTF +y up: the root turns (x, y, z) to (x, z, -y).
    _, root = _node(g, "physcore")
    up = _quat_rotate(root.rotation, np.array([[0.0, 0.0, 1.0]]))[0]
    np.testing.assert_allclose(up, [0.0, 1.0, 0.0], atol=1e-12)


def _body_groups(scene):
    return [b for b in scene.bodies if getattr(b, "first", None) is not None]


@pytest.mark.parametrize("name", ["tablecloth", "pyramid"])
def test_the_bodies_move_as_the_scenes_bodies(recorded, name):
    """Every body node's pose at the last frame (its animation's last key, or its constant pose)
    plus the origin is the scene's body pose now (positions; orientations in 3D, angles in 2D);
    its triangles are the group's own mesh (or outline) and its material the group's colour."""
    scene, rec, path, _ = recorded[name]
    g, blob = _load(path)
    _, origin = _node(g, "origin")
    anim = g.animations[0]
    keys = {(c.target.node, c.target.path): _accessor(g, blob, anim.samplers[c.sampler].output) for c in anim.channels}
    k = 0
    moved = 0
    for grp in _body_groups(scene):
        pos = np.asarray(grp.positions, np.float64).reshape(grp.n, -1)
        colors = np.broadcast_to(np.asarray(grp.color, np.uint8), (grp.n, 3))
        shapes = grp.meshes() if scene.dim == 3 else [(o, None) for o in grp.outline()]
        rot = np.asarray(grp.orientations if scene.dim == 3 else grp.angles, np.float64)
        for j in range(grp.n):
            node_i, node = _node(g, f"body {k}")
            t = keys.get((node_i, "translation"), np.asarray([node.translation]))[-1]
            q = keys.get((node_i, "rotation"), np.asarray([node.rotation]))[-1].astype(np.float64)
            moved += (node_i, "translation") in keys
            np.testing.assert_allclose((t + np.asarray(origin.translation))[:scene.dim], pos[j], atol=1e-5 * max(1.0, np.abs(pos).max()))
            if scene.dim == 3:
                assert abs(abs(float(q @ rot[j])) - 1.0) < 1e-5  # the same rotation (q or -q)
            else:
                np.testing.assert_allclose(q[:2], 0.0, atol=1e-7)
                assert abs(math.remainder(2 * math.atan2(q[2], q[3]) - rot[j], 2 * math.pi)) < 1e-5
            prim = g.meshes[node.mesh].primitives[0]
            verts = _accessor(g, blob, prim.attributes.POSITION).astype(np.float64)
            local = np.asarray(shapes[j][0], np.float64)
            local = local if local.shape[1] == 3 else np.concatenate([local, np.zeros((len(local), 1))], 1)
            d = np.sqrt(((verts[:, None, :] - local[None, :, :]) ** 2).sum(-1))
            assert d.min(axis=1).max() < 1e-6  # every vertex is one of the body's own
            if shapes[j][1] is not None:
                assert d.min(axis=0)[np.unique(shapes[j][1])].max() < 1e-6  # and every corner is drawn
            base = g.materials[prim.material].pbrMetallicRoughness.baseColorFactor
            np.testing.assert_allclose(base[:3], _srgb_to_linear(colors[j]), atol=0.004 if scene.dim == 3 else 1e-9)
            k += 1
    assert k == len([n for n in g.nodes if n.name.startswith("body ")])
    assert moved > 0  # something moves: the channels are really checked


def test_a_2d_scene_lies_in_the_z0_plane_unturned(recorded):
    _, _, path, _ = recorded["pyramid"]
    g, blob = _load(path)
    _, root = _node(g, "physcore")
    assert root.rotation is None
    for m in g.meshes:
        assert np.all(_accessor(g, blob, m.primitives[0].attributes.POSITION)[:, 2] == 0.0)


def test_a_second_reader_sees_the_same_first_frame(recorded):
    """trimesh reads the files on its own: the cloth at frame 0 (the base mesh, through the
    node transforms) is the recording's first frame turned +z -> +y; the water's points too."""
    trimesh = pytest.importorskip("trimesh", reason="trimesh is not installed (the test extra has it)")
    for name, geom in (("cloth_on_ball", "cloth"), ("tablecloth", "cloth"), ("drop", "particles")):
        _, rec, path, _ = recorded[name]
        sc = trimesh.load(str(path), force="scene", process=False)
        (node,) = [n for n in sc.graph.nodes_geometry if sc.graph[n][1] == geom]
        transform, gname = sc.graph[node]
        v = np.asarray(sc.geometry[gname].vertices, np.float64)
        world = v @ transform[:3, :3].T + transform[:3, 3]
        x = rec.positions[0].astype(np.float64) + rec.origin
        expected = np.stack([x[:, 0], x[:, 2], -x[:, 1]], axis=1)
        np.testing.assert_allclose(world, expected, atol=1e-5)
        if geom == "cloth":
            assert len(sc.geometry[gname].faces) == len(rec.defaults["mesh"].faces)


def test_gltf_with_embedded_buffer_holds_the_same_data(recorded, tmp_path):
    _, rec, path, _ = recorded["cloth_on_ball"]
    out = pc.render.gltf(rec, tmp_path / "c.gltf")
    doc = json.loads(out.read_text())
    uri = doc["buffers"][0]["uri"]
    assert uri.startswith("data:application/octet-stream;base64,")
    assert base64.b64decode(uri.split(",", 1)[1]) == _load(path)[1]


def test_html_embeds_the_glb_and_every_script(recorded, tmp_path):
    """One file: the GLB (base64) the player parses is the .glb's bytes; no script, style or
    image is fetched (no src= or href= at all), three.js and the player inline."""
    scene, rec, path, _ = recorded["tablecloth"]
    out = pc.render.html(rec, tmp_path / "t.html", title="A <table>")
    text = out.read_text()
    start = text.index('<script id="physcore-glb" type="application/octet-stream">') + len('<script id="physcore-glb" type="application/octet-stream">')
    glb = base64.b64decode("".join(text[start:text.index("</script>", start)].split()))
    assert glb == path.read_bytes()
    from html.parser import HTMLParser

    class Tags(HTMLParser):  # the page's own tags (a script's text is data, not tags)
        def __init__(self):
            super().__init__()
            self.tags = []

        def handle_starttag(self, tag, attrs):
            self.tags.append((tag, dict(attrs)))

    parser = Tags()
    parser.feed(text)
    assert {t for t, _ in parser.tags} <= {"html", "head", "meta", "title", "style", "body", "div", "button", "input", "span", "script"}
    assert not [(t, a) for t, a in parser.tags if "src" in a or "href" in a]
    assert sum(t == "script" for t, _ in parser.tags) == 5  # the GLB, three.js, OrbitControls, GLTFLoader, the player
    assert "THREE.OrbitControls" in text or "OrbitControls=" in text
    assert "GLTFLoader" in text and "physcore player" in text
    assert "<title>A &lt;table&gt;</title>" in text


def test_export_is_quick_and_small(recorded):
    for name, (_, _, path, seconds) in recorded.items():
        print(f"{name}: {FRAMES} frames, {path.stat().st_size / 1e3:.0f} kB, {seconds:.3f} s")
        assert seconds < 5.0


def test_a_scene_is_recorded_with_its_defaults_and_save_routes_by_extension(tmp_path):
    scene = pc.scenes.pyramid()
    out = pc.render.save(scene, tmp_path / "p.glb", frames=3)
    g, _ = _load(out)
    assert g.scenes[0].extras["physcore"]["frames"] == 3 and scene.time > 0
    out = pc.render.save(pc.scenes.pyramid(), tmp_path / "p.html", frames=2, title="pyramid")
    assert out.read_text().startswith("<!DOCTYPE html>")
    with pytest.raises(InvalidInputError, match="size"):
        pc.render.save(pc.scenes.pyramid(), tmp_path / "p.glb", frames=2, size=(10, 10))
    with pytest.raises(InvalidInputError, match="title"):
        pc.render.save(pc.scenes.pyramid(), tmp_path / "p.glb", frames=2, title="x")


def test_the_command_line_writes_glb_and_html(tmp_path, capsys):
    from physcore.cli import main

    assert main(["render", "cloth_on_ball", "--param", "n=8", "--frames", "3", "-o", str(tmp_path / "c.glb"), "-q"]) == 0
    g, _ = _load(tmp_path / "c.glb")
    assert [m.name for m in g.meshes if m.name == "cloth"] and g.scenes[0].extras["physcore"]["frames"] == 3
    assert main(["render", "pyramid", "--frames", "2", "-o", str(tmp_path / "p.html"), "-q"]) == 0
    assert "<title>pyramid</title>" in (tmp_path / "p.html").read_text()
    assert "px" not in capsys.readouterr().out.split("frames:")[1].splitlines()[0]


@pytest.mark.parametrize("ext", ["glb", "html"])
def test_bad_paths_are_refused_naming_path_before_simulating(tmp_path, ext):
    fn = pc.render.gltf if ext == "glb" else pc.render.html
    (tmp_path / f"d.{ext}").mkdir()
    scene = pc.scenes.pyramid()
    other = "html" if ext == "glb" else "glb"
    for path, error in ((42, InvalidTypeError), (tmp_path / "x.obj", InvalidInputError), (tmp_path / f"x.{other}", InvalidInputError),
                        (tmp_path / "missing" / f"x.{ext}", InvalidInputError), (tmp_path / f"d.{ext}", InvalidInputError)):
        with pytest.raises(error, match="^path") as e:
            fn(scene, path)
        assert isinstance(e.value, PhyscoreError)
    assert scene.time == 0.0 and [p.name for p in tmp_path.iterdir()] == [f"d.{ext}"]


@pytest.mark.parametrize("what", [42, "tablecloth", None, np.zeros((3, 3))])
def test_what_is_not_a_scene_is_refused_naming_scene(tmp_path, what):
    for fn, ext in ((pc.render.gltf, "glb"), (pc.render.html, "html")):
        with pytest.raises(InvalidTypeError, match="scene"):
            fn(what, tmp_path / f"x.{ext}")
    assert not list(tmp_path.iterdir())


def test_bad_options_are_refused_naming_them_before_simulating(tmp_path):
    scene = pc.scenes.pyramid()
    for kw, word in (({"fps": 0}, "fps"), ({"theme": "sepia"}, "theme"), ({"frames": 0}, "frames"),
                     ({"mesh": np.array([[0, 1, 99]])}, "mesh"), ({"view": (1, 2, 3)}, "view")):
        with pytest.raises(InvalidInputError, match=word):
            pc.render.gltf(scene, tmp_path / "x.glb", **kw)
    with pytest.raises(InvalidInputError, match="title"):
        pc.render.html(scene, tmp_path / "x.html", title="two\nlines")
    with pytest.raises(InvalidTypeError, match="title"):
        pc.render.html(scene, tmp_path / "x.html", title=3)
    assert scene.time == 0.0 and not list(tmp_path.iterdir())
    # glTF's clock is float32: fps = 1e-300 put frame 1 at 1e300 s, and json refused the
    # infinite float32 time with a bare ValueError after the whole simulation; fps = 1e308
    # wrote every frame at t = 0 (an animation whose key times must increase).
    for fn, ext in ((pc.render.gltf, "glb"), (pc.render.html, "html")):
        for fps in (1e-300, 1e308):
            with pytest.raises(InvalidInputError, match="fps"):
                fn(scene, tmp_path / f"x.{ext}", fps=fps, frames=2)
    assert scene.time == 0.0 and not list(tmp_path.iterdir())
    rec = pc.render.record(pc.scenes.pyramid(), frames=2)
    with pytest.raises(InvalidInputError, match="frames"):
        pc.render.gltf(rec, tmp_path / "x.glb", frames=3)


def test_a_grid_scene_is_refused_before_simulating(tmp_path):
    scene = pc.scenes.ripple(n=32)
    with pytest.raises(InvalidInputError, match="scene: a grid scene"):
        pc.render.gltf(scene, tmp_path / "x.glb", frames=2)
    assert scene.time == 0.0


def test_without_pygltflib_the_error_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pygltflib", None)  # import pygltflib now raises ImportError
    scene = pc.scenes.pyramid()
    for fn, ext in ((pc.render.gltf, "glb"), (pc.render.html, "html")):
        with pytest.raises(ImportError, match=r'pip install "physcore\[web\]"'):
            fn(scene, tmp_path / f"x.{ext}")
    assert scene.time == 0.0 and not list(tmp_path.iterdir())


@pytest.mark.parametrize("fn", ["gltf", "html"])
def test_the_docstring_examples_run(fn):
    """physcore.render's doctest run skips these (they are defined in private modules)."""
    import doctest

    runner = doctest.DocTestRunner()
    for t in doctest.DocTestFinder().find(getattr(pc.render, fn), globs={}):
        runner.run(t)
    result = runner.summarize(verbose=False)
    assert result.attempted > 0 and result.failed == 0


@pytest.mark.parametrize("name", list(SCENES))
def test_the_files_camera_sees_the_whole_scene(recorded, name):
    """The camera node (for viewers that open a file's own camera) looks at the centre of the
    bounds in extras, every corner of them inside its field of view, along the scene's view."""
    _, rec, path, _ = recorded[name]
    g, _ = _load(path)
    (k,) = [k for k, n in enumerate(g.nodes) if n.camera is not None]
    assert k in g.scenes[0].nodes  # at the root: world axes
    node, cam = g.nodes[k], g.cameras[g.nodes[k].camera]
    extras = g.scenes[0].extras["physcore"]
    lo, hi = (np.asarray(v) for v in extras["bounds"])
    eye = np.asarray(node.translation)
    axes = _quat_rotate(np.asarray(node.rotation), np.eye(3))  # the camera's x, y, z in the world
    np.testing.assert_allclose(axes[2], np.asarray(extras["view"]) / np.linalg.norm(extras["view"]), atol=1e-9)
    corners = np.array([[(hi if i & b else lo)[j] for j, b in enumerate((1, 2, 4))] for i in range(8)])
    rel = (corners - eye) @ axes.T  # camera coordinates: in front is -z
    tan = math.tan(cam.perspective.yfov / 2)
    assert np.all(-rel[:, 2] > cam.perspective.znear) and np.all(-rel[:, 2] < cam.perspective.zfar)
    assert np.all(np.abs(rel[:, 1]) <= tan * -rel[:, 2] + 1e-9)
    assert np.all(np.abs(rel[:, 0]) <= tan * cam.perspective.aspectRatio * -rel[:, 2] + 1e-9)
    centre = (0.5 * (lo + hi) - eye) @ axes.T
    np.testing.assert_allclose(centre[:2], 0.0, atol=1e-9 * max(1.0, np.abs(eye).max()))


def test_a_few_escaping_particles_do_not_shrink_the_cloud(tmp_path):
    """Of a cloud of particles (galaxies, a splash) the bounds players fit hold the first frame
    and 99 % of every frame's positions: one particle flung 100 m away leaves them the cloud's."""
    rng = np.random.default_rng(1)
    s = pc.Scene(dim=3, integrator="verlet", dt=0.01)
    x = rng.uniform(-1.0, 1.0, size=(600, 3))
    v = np.zeros_like(x)
    v[0] = (1000.0, 0.0, 0.0)  # 10 m a step: 100 m away at the last frame
    s.add_particles(x, v)
    path = pc.render.gltf(s, tmp_path / "cloud.glb", frames=3, steps_per_frame=5)
    g, _ = _load(path)
    lo, hi = (np.asarray(b) for b in g.scenes[0].extras["physcore"]["bounds"])
    assert np.all(hi - lo < 2.5), (lo, hi)  # the cloud (2 m across, the origin its centroid)
    assert np.all(hi - lo > 1.9), (lo, hi)  # all of it at the first frame


def test_the_scenes_backdrop_goes_to_the_players(recorded):
    """A scene whose look has a backdrop (the tablecloth's wall) gives players its gradient,
    top and bottom sRGB, and their mean as the one background colour; others give none."""
    g, _ = _load(recorded["tablecloth"][2])
    extras = g.scenes[0].extras["physcore"]
    top, bottom = pc.scenes.tablecloth.render_defaults["look"]["backdrop"]
    assert extras["backdrop"] == [list(top), list(bottom)]
    assert extras["background"] == [round((a + b) / 2) for a, b in zip(top, bottom, strict=True)]
    g, _ = _load(recorded["drop"][2])
    assert "backdrop" not in g.scenes[0].extras["physcore"]
