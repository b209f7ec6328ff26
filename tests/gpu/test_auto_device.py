"""``Scene(device="auto")``: the choice between the CPU and a GPU made at the first step by the
cost model of physcore.scene (``_auto_choice``), and what it keeps from the CPU path.

These run on any machine: the adapters a scene sees are replaced where a test needs a GPU to
choose from, and the one test that moves a scene runs on lavapipe (skipped without it).
"""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc
from physcore import scene as scene_mod

H100 = {"name": "NVIDIA H100 80GB HBM3", "backend": "vulkan", "kind": "discrete", "driver": "NVIDIA",
        "f64": True, "max_storage_binding": 2**31, "max_buffer": 2**32}
LAVAPIPE = {"name": "llvmpipe (LLVM 15.0.6, 256 bits)", "backend": "vulkan", "kind": "cpu", "driver": "Mesa",
            "f64": True, "max_storage_binding": 2**27, "max_buffer": 2**31}


def _nbody(n: int, device: str = "auto", precision: str | None = None) -> pc.Scene:
    rng = np.random.default_rng(1)
    s = pc.Scene(dim=3, integrator="verlet", dt=1e-3, device=device, precision=precision)
    s.add_particles(rng.normal(size=(n, 3)), 0.1 * rng.normal(size=(n, 3)), masses=1.0 / n)
    s.add(pc.PairwiseGravity(G=1.0, softening=0.05))
    return s


def _work(s: pc.Scene) -> dict[str, float]:
    return scene_mod._auto_work(s._parts, s.n_particles)


def test_the_device_argument_takes_auto_and_refuses_a_misspelling_by_name():
    assert pc.Scene(2, device="auto").device == "auto"
    with pytest.raises(pc.InvalidInputError, match="device"):
        pc.Scene(2, device="autogpu")


def test_a_small_scene_stays_on_the_cpu_and_a_large_one_goes_to_a_real_gpu():
    small, large = _work(_nbody(256)), _work(_nbody(65536))
    assert scene_mod._auto_choice(small, 2, [H100], None)[0] == "cpu"
    device, why = scene_mod._auto_choice(large, 2, [H100], None)
    assert device == "gpu:" + H100["name"] and "ms" in why
    # More CPU threads move the threshold up, never down.
    n_switch = {}
    for threads in (1, 2, 16):
        n_switch[threads] = next(n for n in 2 ** np.arange(6, 18)
                                 if scene_mod._auto_choice(_work(_nbody(int(n))), threads, [H100], None)[0] != "cpu")
    assert n_switch[1] <= n_switch[2] <= n_switch[16]


def test_never_a_cpu_adapter_and_never_f64_where_the_adapter_lacks_it():
    large = _work(_nbody(65536))
    device, why = scene_mod._auto_choice(large, 2, [LAVAPIPE], None)
    assert device == "cpu" and "no GPU adapter" in why
    no_f64 = dict(H100, f64=False)
    device, why = scene_mod._auto_choice(large, 2, [no_f64], "f64")
    assert device == "cpu" and "f64" in why
    assert scene_mod._auto_choice(large, 2, [no_f64], "f32")[0] == "gpu:" + H100["name"]


def test_a_part_without_a_gpu_kernel_keeps_the_scene_on_the_cpu_bit_for_bit(monkeypatch):
    monkeypatch.setattr(scene_mod._core, "gpu_adapters", lambda: [H100])
    twins = []
    for device in ("auto", "cpu"):
        s = _nbody(512, device)
        s.add(pc.TreeGravity(G=1.0))  # no GPU kernel yet
        s.step(5)
        twins.append(s)
    auto, cpu = twins
    assert auto.device == "cpu" and "TreeGravity" in auto.device_reason and auto.precision == "f64"
    assert np.array_equal(auto.positions, cpu.positions)


def test_without_a_gpu_the_scene_runs_on_the_cpu_as_device_cpu_does(monkeypatch):
    monkeypatch.setattr(scene_mod._core, "gpu_adapters", lambda: [])
    auto, cpu = _nbody(300), _nbody(300, "cpu")
    assert auto.device_reason is None and auto.precision == "f64"
    auto.step(10)
    cpu.step(10)
    assert auto.device == "cpu" and "no GPU adapter" in auto.device_reason
    assert np.array_equal(auto.positions, cpu.positions) and auto.energy().total == cpu.energy().total
    # f32 asked for: the CPU's f32 mode, as device="cpu" gives it.
    a32, c32 = _nbody(300, precision="f32"), _nbody(300, "cpu", precision="f32")
    a32.step(10)
    c32.step(10)
    assert a32.precision == "f32" and np.array_equal(a32.positions, c32.positions)


def _lavapipe() -> dict | None:
    return next((a for a in pc.gpu_adapters() if "llvmpipe" in a["name"]), None)


@pytest.mark.skipif(_lavapipe() is None, reason="no lavapipe (apt-get install mesa-vulkan-drivers)")
def test_a_chosen_gpu_steps_the_scene_in_f32_and_agrees_with_the_cpu(monkeypatch):
    # lavapipe dressed as a discrete GPU: the choice is the cost model's, the move is real.
    lp = dict(_lavapipe(), kind="discrete")
    monkeypatch.setattr(scene_mod._core, "gpu_adapters", lambda: [lp])
    monkeypatch.setattr(scene_mod, "_AUTO_FLOOR_S", {"particles": 0.0, "grid": 0.0})  # any scene pays on this "GPU"
    auto, cpu = _nbody(600), _nbody(600, "cpu")
    auto.step(20)
    cpu.step(20)
    assert auto.device == "gpu:" + lp["name"] and auto.precision == "f32"
    assert "estimated" in auto.device_reason
    assert np.abs(auto.positions - cpu.positions).max() < 1e-5
    # Once chosen, the scene is a GPU scene: the same refusals as device="gpu".
    with pytest.raises(pc.InvalidInputError, match="on the GPU"):
        auto.integrator = "rk4"


def test_galaxies_take_ten_times_the_stars_on_a_discrete_gpu_and_not_elsewhere(monkeypatch):
    # The adapters are replaced: no scene here steps, so none opens a device.
    from physcore.scenes import orbits

    for adapters, device, n in (
        ([H100, LAVAPIPE], "gpu", 100_000),
        ([H100, LAVAPIPE], "gpu:nvidia", 100_000),
        ([H100, LAVAPIPE], "gpu:llvmpipe", 10_000),
        ([H100, LAVAPIPE], "gpu:lavapipe", 10_000),
        ([LAVAPIPE], "gpu", 10_000),
        ([], "gpu", 10_000),
        ([H100], "cpu", 10_000),
        ([H100], "auto", 10_000),  # the tree: the CPU's
        ([dict(H100, kind="integrated", name="Apple M2")], "gpu", 10_000),
        ([dict(H100, kind="integrated", name="Intel UHD"), H100], "gpu", 100_000),  # the best: discrete
    ):
        monkeypatch.setattr(orbits, "gpu_adapters", lambda adapters=adapters: adapters)
        s = pc.scenes.galaxies(device=device)
        assert s.n_particles == n, (device, [a["kind"] for a in adapters])
        # A size given is kept on any device.
        assert pc.scenes.galaxies(n=600, device=device).n_particles == 600
    # Which gravity each takes: the direct sum on a GPU, the tree elsewhere.
    monkeypatch.setattr(orbits, "gpu_adapters", lambda: [H100])
    assert [p.kind for p in pc.scenes.galaxies(n=600, device="gpu").terms] == ["pairwise_gravity"]
    assert [p.kind for p in pc.scenes.galaxies(n=600).terms] == ["tree_gravity"]
