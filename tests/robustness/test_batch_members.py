"""A Batch whose member changed after the batch was made, a batch file whose ``batch.json`` is
not an object, and ``Batch.from_scene`` given arrays where it takes callables: each refused by
name, of physcore's own error class, before anything changes (the hostile run found a bare
numpy shape error after the batch had stepped, an AttributeError, and "'numpy.ndarray' object
is not callable")."""
from __future__ import annotations

import zipfile

import numpy as np
import pytest
from conftest import busy_uses

import physcore as pc


def _gpu() -> str | None:
    """A GPU, else lavapipe, else None (as tests/gpu/test_gpu_scenes.py picks one)."""
    adapters = pc.gpu_adapters()
    if any(a["kind"] != "cpu" for a in adapters):
        return "gpu"
    return "gpu:lavapipe" if any("llvmpipe" in a["name"] for a in adapters) else None


def _pair() -> pc.Batch:
    def one() -> pc.Scene:
        s = pc.Scene(dim=2, dt=1e-3, threads=1)
        s.add_particles([[0.0, 0.0], [1.0, 0.0]])
        return s

    return pc.Batch([one(), one()], threads=1)


def _clocks(b: pc.Batch) -> list[tuple[float, int]]:
    return [(s.time, s.step_count) for s in b.members]


@pytest.mark.parametrize("change, what", [
    (lambda s: s.add_particles([[5.0, 5.0]]), "particle count"),
    (lambda s: s.add(pc.Drag(0.1)), "parts"),
    (lambda s: s.add(pc.Bodies("box", size=[(0.2, 0.2)], positions=[(3.0, 3.0)])), "parts"),
])
@pytest.mark.parametrize("changed", [0, 1])
def test_a_member_changed_alone_is_refused_by_name_before_anything_steps(change, what, changed):
    """Stepping, reading the state and rendering a batch one of whose members gained a particle,
    a term or a bodies group raise InvalidInputError naming that member and what differs; no
    member is stepped."""
    b = _pair()
    b.step(1)
    change(b[changed])
    before = _clocks(b)
    other = 1 - changed
    said = f"member {changed} differs from entry {other} in its {what} since the batch was made"
    with pytest.raises(pc.InvalidInputError, match=said):
        b.step(2)
    assert _clocks(b) == before
    for read in (lambda: b.positions, lambda: b.velocities, lambda: b.render_defaults):
        with pytest.raises(pc.InvalidInputError, match=said):
            read()


def test_a_changed_member_is_refused_by_the_renderer(tmp_path):
    """render.gif of a batch one of whose members gained a particle: InvalidInputError naming
    it, no file written (it raised a reshape ValueError)."""
    from physcore import render

    b = _pair()
    b[1].add_particles([[5.0, 5.0]])
    out = tmp_path / "b.gif"
    with pytest.raises(pc.InvalidInputError, match="member 1 differs from entry 0 in its particle count"):
        render.gif(b, out, frames=2, steps_per_frame=1, size=(32, 32))
    assert not out.exists()


@pytest.mark.skipif(_gpu() is None, reason="no GPU adapter and no lavapipe")
@pytest.mark.parametrize("change", [lambda s: s.add_particles([[5.0, 5.0]]), lambda s: s.add(pc.Drag(0.1))])
def test_a_gpu_batch_member_changed_alone_is_refused_before_anything_steps(change):
    """The GPU batch checks only the members used since its last call (any use writes a member
    back first): one changed after a call, another read meanwhile, is refused by name."""
    b = pc.Batch.from_scene(pc.scenes.figure_eight(), 3, device=_gpu())
    b.step(2)
    assert b[0].positions.shape == (3, 2)  # member 0 used, unchanged
    change(b[2])
    steps = b.step_count.copy()
    with pytest.raises(pc.InvalidInputError, match="member 2 differs from entry 0 in its"):
        b.step(1)
    with pytest.raises(pc.InvalidInputError, match="member 2 differs from entry 0 in its"):
        _ = b.positions
    assert np.array_equal(b.step_count, steps)


def test_a_member_stepped_alone_on_another_thread_makes_the_batch_say_busy():
    """The members' check reads the core directly: while a member steps alone on another thread,
    the batch's step and reads raise SceneBusyError, not pyo3's "Already mutably borrowed"."""
    rng = np.random.default_rng(0)
    s = pc.Scene(dim=2, dt=1e-4, threads=1)
    s.add_particles(rng.normal(size=(300, 2)))
    s.add(pc.PairwiseGravity(G=1e-6, softening=0.1))
    b = pc.Batch.from_scene(s, 2, threads=1)
    seen, errors = busy_uses(lambda: b[0].step(3000), (lambda: b.step(1), lambda: b.positions))
    assert not errors and seen
    assert all("another thread" in str(e) for e in seen)


def test_members_changed_alike_still_step_together():
    """Every member given the same term: still one structure, stepped and read as a batch."""
    b = _pair()
    b.step(1)
    for s in b.members:
        s.add(pc.Drag(0.1))
    b.step(2)
    assert b.positions.shape == (2, 2, 2)
    assert [c for _, c in _clocks(b)] == [3, 3]


@pytest.mark.parametrize("raw", [b"1", b"[]", b"[1]", b'"batch"', b"null", b"true", b"1.5"])
def test_a_batch_json_that_is_not_an_object_is_a_scene_file_error(tmp_path, raw):
    """batch.json a bare number, array, string, null or boolean: SceneFileError naming
    batch.json (a bare 1 raised AttributeError: 'int' object has no attribute 'get')."""
    s = pc.Scene(dim=2, dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.0]])
    path = tmp_path / "b.npz"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("batch.json", raw)
        z.writestr("member0.npz", s.to_bytes())
    with pytest.raises(pc.SceneFileError, match="batch.json: must be a JSON object") as e:
        pc.Batch.load(path)
    assert e.value.field == "batch.json"


@pytest.mark.parametrize("arg", ["positions", "velocities"])
@pytest.mark.parametrize("value", [np.zeros((1, 2)), [[0.0, 0.0]], 1.0])
def test_from_scene_refuses_a_value_where_it_takes_a_callable(arg, value):
    """positions= / velocities= given an array (not f(k, x)): InvalidTypeError naming the
    argument ("'numpy.ndarray' object is not callable" before)."""
    s = pc.Scene(dim=2, dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.0]])
    with pytest.raises(pc.InvalidTypeError, match=f"^{arg}: expected a callable"):
        pc.Batch.from_scene(s, 2, **{arg: value})
