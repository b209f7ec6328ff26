"""What the GPU benches share: the device to run on, and the timing of a call of steps apart
from the read-back after it."""
from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import physcore as pc


def device_of(arg: str | None) -> str:
    """``--device``, else the first real GPU ("gpu"), else lavapipe; prints the adapters."""
    adapters = pc.gpu_adapters()
    for a in adapters:
        print(f"# adapter: {a['name']} ({a['kind']}, {a['backend']}, f64: {a['f64']})")
    return arg or ("gpu" if any(a["kind"] != "cpu" for a in adapters) else "gpu:lavapipe")


def timed(s: pc.Scene, steps: int, read: Callable[[], object]) -> tuple[float, float]:
    """Median seconds of a call of ``steps`` steps, and of one ``read()`` after them, over 3
    calls after a warm-up step (the move to the device, the shaders' compilation). A device's
    ``step`` returns once the device has finished (it waits for each submission's finiteness
    flag), so the steps are timed alone; the read-back (device to host, f32 to f64) is timed
    apart, as a frame or a save pays it."""
    s.step(1)
    times, reads = [], []
    for _ in range(3):
        t = time.perf_counter()
        s.step(steps)
        times.append(time.perf_counter() - t)
        t = time.perf_counter()
        read()
        reads.append(time.perf_counter() - t)
    return statistics.median(times), statistics.median(reads)
