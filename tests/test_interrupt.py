"""Ctrl-C during a long step(n) stops it promptly and leaves the scene as it was before the call."""
from __future__ import annotations

import os
import signal
import sys
import threading
import time

import numpy as np
import pytest

import physcore as pc


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("threads", [None, 2])
def test_keyboard_interrupt_rolls_back_long_step(threads):
    rng = np.random.default_rng(1)
    scene = pc.Scene(3, integrator="verlet", dt=1e-3, threads=threads)
    scene.add_particles(rng.random((200_000, 3)), rng.normal(size=(200_000, 3)))
    scene.add(pc.Gravity([0.0, 0.0, -9.81]))
    scene.step(3)
    before = scene.positions
    timer = threading.Timer(0.3, os.kill, args=(os.getpid(), signal.SIGINT))
    timer.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt):
            scene.step(10**7)  # minutes of work if not interrupted
    finally:
        timer.cancel()
    assert time.perf_counter() - t0 < 30.0
    assert scene.step_count == 3
    assert np.array_equal(scene.positions, before)
    scene.step(2)  # still usable
    assert scene.step_count == 5


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_keyboard_interrupt_reaches_rk45_internal_steps():
    # Few output steps, each of many internal rk45 steps (a stiff cloth with a long dt): the
    # interrupt is polled by internal work, not only between output steps.
    scene = pc.scenes.cloth(n=48, integrator="rk45", dt=0.5)
    scene.rtol = 1e-10
    before = scene.positions
    timer = threading.Timer(0.5, os.kill, args=(os.getpid(), signal.SIGINT))
    timer.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt):
            scene.step(200)  # minutes of work if not interrupted
    finally:
        timer.cancel()
    assert time.perf_counter() - t0 < 10.0
    assert scene.step_count == 0
    assert np.array_equal(scene.positions, before)
