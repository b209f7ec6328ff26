"""Hostile inputs refused by name, before any state changes: values a float32 state cannot hold
on every f32 path (the GPU's included), and zero-stride (broadcast) arrays standing for more
rows than memory holds (physcore's OutOfMemoryError, never numpy's bare MemoryError)."""
from __future__ import annotations

import os
import pickle
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import physcore as pc

GPU = "gpu:lavapipe" if any("llvmpipe" in a["name"] for a in pc.gpu_adapters()) else None
FAR = [[0.0, 0.0], [1e39, 0.0]]  # row 1 is past float32's range (3.4e38)


@pytest.mark.skipif(GPU is None, reason="no lavapipe (apt-get install mesa-vulkan-drivers)")
def test_a_gpu_f32_scene_refuses_values_past_float32_as_a_cpu_f32_scene_does(tmp_path):
    # The GPU scene took them (its state is float64 on the host until the first step), then
    # save() wrote inf and Scene.load / unpickling refused the file it had written.
    messages = {}
    for label, kwargs in (("cpu", {"precision": "f32"}), ("gpu", {"device": GPU})):
        s = pc.Scene(2, **kwargs)
        assert s.precision == "f32"
        with pytest.raises(pc.InvalidInputError) as err:
            s.add_particles(FAR)
        assert s.n_particles == 0
        messages[label, "add"] = str(err.value)
        with pytest.raises(pc.InvalidInputError) as err:
            s.add_particles([[0.0, 0.0], [1.0, 0.0]], velocities=FAR)
        assert s.n_particles == 0
        messages[label, "add v"] = str(err.value)
        s.add_particles([[0.0, 0.0], [1.0, 0.0]])
        for key in ("positions", "velocities"):
            before = getattr(s, key)
            with pytest.raises(pc.InvalidInputError) as err:
                setattr(s, key, FAR)
            assert np.array_equal(getattr(s, key), before)
            messages[label, key] = str(err.value)
            state = s.state()
            state[key] = np.array(FAR)
            with pytest.raises(pc.InvalidInputError) as err:
                s.set_state(state)
            assert np.array_equal(getattr(s, key), before)
            messages[label, "state", key] = str(err.value)
        # What is left saves and loads back (no inf in the file).
        path = s.save(tmp_path / f"{label}.npz")
        assert np.array_equal(pc.Scene.load(path).positions, s.positions)
        assert np.array_equal(pickle.loads(pickle.dumps(s)).positions, s.positions)
    assert messages["gpu", "add"] == messages["cpu", "add"] == 'positions: row 1 does not fit float32 (precision="f32"): [1e+39, 0.0]'
    assert messages["gpu", "add v"] == messages["cpu", "add v"] == 'velocities: row 1 does not fit float32 (precision="f32"): [1e+39, 0.0]'
    for key in ("positions", "velocities"):
        assert messages["gpu", key] == messages["cpu", key] == f'{key}: row 1 does not fit float32 (precision="f32"): [1e+39, 0.0]'
        assert messages["gpu", "state", key] == messages["cpu", "state", key]
        assert messages["gpu", "state", key].startswith(f"state['{key}']: row 1 does not fit float32")


# 10**12 rows: a copy numpy refuses at once (terabytes), so a missing check fails fast here
# instead of allocating.
HUGE = 10**12


def test_broadcast_positions_beyond_memory_are_refused_by_name_before_any_copy():
    s = pc.Scene(2)
    s.add_particles(np.zeros((3, 2)))
    with pytest.raises(pc.OutOfMemoryError, match=r"^add_particles: needs about .* for 1,000,000,000,000 particles") as err:
        s.add_particles(np.broadcast_to(np.zeros(2), (HUGE, 2)))
    assert isinstance(err.value, pc.PhyscoreError) and err.value.bytes >= HUGE * 2 * 8
    # Masses of the wrong length are refused by their shape, not copied first.
    with pytest.raises(pc.InvalidInputError, match=r"^masses: expected a scalar or shape \(3,\)"):
        s.add_particles(np.zeros((3, 2)), masses=np.broadcast_to(1.0, (HUGE,)))
    assert s.n_particles == 3


def test_broadcast_spring_arrays_beyond_memory_are_refused_by_name():
    with pytest.raises(pc.OutOfMemoryError, match=r"^i/j: needs about .* for 1,000,000,000,000 springs") as err:
        pc.Springs(np.broadcast_to(np.int64(0), (HUGE,)), np.broadcast_to(np.int64(1), (HUGE,)))
    assert isinstance(err.value, pc.PhyscoreError) and err.value.bytes >= HUGE * 16
    with pytest.raises(pc.OutOfMemoryError, match=r"^stiffness: needs "):
        pc.Springs([0], [1], stiffness=np.broadcast_to(1.0, (HUGE,)))


@pytest.mark.parametrize("arg, make", [
    ("size", lambda big: pc.Bodies("ball", big(0))),
    ("positions", lambda big: pc.Bodies("ball", 1.0, big(2))),
    ("distance", lambda big: pc.XpbdConstraints(distance=big(2, np.int64))),
    ("positions", lambda big: pc.PointMasses(big(2), 1.0)),
    ("anchors", lambda big: pc.Joints("revolute", pc.Bodies("ball", 1.0, np.zeros((1, 2))), None, big(2))),
    ("phi", lambda big: pc.PotentialGrid(np.broadcast_to(0.0, (10**6, 10**6)), 1.0)),
    ("mask", lambda big: pc.Wave((8, 8), mask=np.broadcast_to(False, (10**6, 10**6)))),
    ("positions", lambda big: pc.render.render_frame(big(2))),
], ids=["Bodies size", "Bodies positions", "XpbdConstraints", "PointMasses", "Joints", "PotentialGrid", "Wave", "render_frame"])
def test_broadcast_arrays_beyond_memory_are_refused_by_name_by_every_constructor(arg, make):
    # A fault audit: these copied first (Bodies of 10**9 broadcast rows took 24 GB and the OOM
    # killer ended the process); every array a part takes is now measured before any copy.
    def big(width, dtype=float):
        return np.broadcast_to(np.zeros(width, dtype), (HUGE, width)) if width else np.broadcast_to(np.zeros((), dtype), (HUGE,))

    with pytest.raises(pc.OutOfMemoryError, match=f"^{arg}: needs about "):
        make(big)


def test_an_attribute_of_the_wrong_length_is_refused_before_it_is_copied():
    s = pc.Scene(2)
    s.add_particles(np.zeros((3, 2)))
    with pytest.raises(pc.InvalidInputError, match=f"^charge: has {HUGE} entries, the scene has 3 particles"):
        s.set_attribute("charge", np.broadcast_to(1.0, (HUGE,)))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS as Linux enforces it, /proc for the baseline")
def test_broadcast_copies_that_fail_under_a_memory_cap_raise_physcores_error():
    # Sizes below physcore's limit whose copies (800 MB, 400 MB) a cap of 200 MB above what
    # the child maps refuses: numpy's MemoryError comes back as OutOfMemoryError naming the
    # call (add_particles) or the term's argument (Springs' i). The cap keeps the child small even if that were not so.
    code = textwrap.dedent("""
        import re, resource
        import numpy as np
        import physcore as pc
        s = pc.Scene(2)
        s.add_particles(np.zeros((3, 2)))
        n = 50_000_000
        vm = int(re.search(r"VmSize:\\s+(\\d+) kB", open("/proc/self/status").read()).group(1)) * 1024
        resource.setrlimit(resource.RLIMIT_AS, (vm + (200 << 20), resource.getrlimit(resource.RLIMIT_AS)[1]))
        for name, call in (
            ("add_particles", lambda: s.add_particles(np.broadcast_to(np.zeros(2), (n, 2)))),
            ("i", lambda: pc.Springs(np.broadcast_to(np.int64(0), (n,)), np.broadcast_to(np.int64(1), (n,)))),
            # A fault audit found these raising numpy's bare MemoryError (and Bodies of 10**9
            # rows, uncapped, taking 24 GB until the OOM killer ended the process).
            ("Bodies", lambda: pc.Bodies("ball", np.broadcast_to(1.0, (n,)))),
            ("Fluid", lambda: pc.Fluid(np.broadcast_to(np.zeros(2), (n, 2)), 0.01)),
            ("XpbdConstraints", lambda: pc.XpbdConstraints(distance=np.broadcast_to(np.zeros(2, np.int64), (n, 2)))),
            ("PointMasses", lambda: pc.PointMasses(np.broadcast_to(np.zeros(2), (n, 2)), 1.0)),
            ("Joints", lambda: pc.Joints("revolute", pc.Bodies("ball", 1.0, np.zeros((1, 2))), None,
                                         np.broadcast_to(np.zeros(2), (n, 2)))),
            ("render_frame", lambda: pc.render.render_frame(np.broadcast_to(np.zeros(2), (n, 2)))),
        ):
            try:
                call()
                raise AssertionError(name + ": no error")
            except MemoryError as e:
                assert isinstance(e, pc.OutOfMemoryError), repr(e)
                assert str(e).startswith(name + ": needs "), str(e)
        assert s.n_particles == 3
        print("ok")
    """)
    root = os.path.dirname(os.path.dirname(os.path.abspath(pc.__file__)))
    env = dict(os.environ, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stdout + proc.stderr[-3000:]


def test_an_unsigned_spring_index_past_int64_is_refused_as_itself():
    # A fault audit: the cast to int64 wrapped 2**63 to -2**63, and the message said so.
    with pytest.raises(pc.InvalidInputError, match=r"^i: index 9223372036854775808 is beyond any particle count"):
        pc.Springs(np.array([2**63], np.uint64), np.array([0], np.uint64))
