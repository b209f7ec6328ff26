"""
Many scenes in one call: a batch
================================

:class:`physcore.Batch` steps M scenes of the same structure with one call into the core,
side by side on the cores, each member bit for bit as it would step alone. Here eight
copies of the figure-eight three-body orbit, member ``k`` started with its positions scaled
by ``1 + 0.01 k``: the larger the change, the further its orbit wanders from the figure
eight. Every 20 steps
the batch's positions, an ``(M, N, dim)`` array, are kept; the figure overlays the first
body's path in each member.
"""
import matplotlib.pyplot as plt
import numpy as np

import physcore as pc

batch = pc.Batch.from_scene(pc.scenes.figure_eight(), 8, positions=lambda k, x: x * (1 + 0.01 * k))
paths = []
for _ in range(315):  # 315 calls of 20 steps: three periods (2100 steps each)
    batch.step(20)
    paths.append(batch.positions[:, 0])  # (M, dim): body 0 of every member
paths = np.array(paths)  # (frames, M, dim)

fig, ax = plt.subplots(figsize=(7, 4))
for k in range(len(batch)):
    ax.plot(paths[:, k, 0], paths[:, k, 1], lw=1, label=f"x * {1 + 0.01 * k:.2f}")
ax.set_aspect("equal")
ax.legend(title="positions", fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
fig.tight_layout()
print("time of each member:", batch.time.round(3), "energy drifts:", batch.energy_drift())
plt.show()
