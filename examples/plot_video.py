"""
The same scene as a video
=========================

:func:`physcore.render.save` draws like :func:`physcore.render.gif` in the format the file's
extension names: ``.mp4`` is H.264 video (it plays in browsers, phones and slides),
``.webm`` VP9, ``.png`` one image per frame. Videos need PyAV
(``pip install "physcore[video]"``, whose wheel brings FFmpeg's libraries). A video is far
smaller than a GIF of the same frames, so it suits long or large animations.

The scene is the chain of :doc:`plot_own_scene`; the build uses 90 frames of 320 x 240
pixels (480 x 360 by default).
"""
import numpy as np

import physcore as pc

n = 12
scene = pc.Scene(dim=2, dt=1e-3)
scene.add_particles(np.column_stack([np.linspace(0.0, 1.1, n), np.full(n, 1.0)]),
                    pinned=[True] + [False] * (n - 1))
scene.add(pc.Springs(np.arange(n - 1), np.arange(1, n), stiffness=2000.0, damping=0.5))
scene.add(pc.Gravity([0.0, -9.81]))
scene.add(pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=0.3, friction=0.2))

path = pc.render.save(scene, "chain.mp4", frames=90, fps=30, size=(320, 240), trail=10)
print(f"{path.name}: {path.stat().st_size / 1024:.0f} KiB")
