"""Writes a small LeRobotDataset v3.0 with LeRobot's own writer in the LIBERO layout
(`observation.images.image`, `observation.images.wrist_image`, `observation.state` (8), `action`
(7), videos in LeRobot's default codec), for the import test.

Usage: python lerobot_make_libero.py ROOT EPISODES FRAMES SIZE
Prints one JSON line: {"actions": [[7] per frame, in order], "tasks": [...], "codec": ...}.
"""

import json
import sys

import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset

root, episodes, frames, size = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
image = {"dtype": "video", "shape": (size, size, 3), "names": ["height", "width", "channel"]}
features = {
    "observation.images.image": image,
    "observation.images.wrist_image": dict(image),
    "observation.state": {"dtype": "float32", "shape": (8,), "names": ["state"]},
    "action": {"dtype": "float32", "shape": (7,), "names": ["actions"]},
}
ds = LeRobotDataset.create("test/libero_like", fps=10, root=root, features=features, robot_type="panda", use_videos=True)
rng = np.random.default_rng(0)
actions, tasks = [], []
for e in range(episodes):
    task = f"put the bowl number {e % 2} on the plate"
    tasks.append(task)
    for k in range(frames):
        # A smooth picture (a gradient moving with k), so the lossy codec keeps it close.
        y, x = np.mgrid[0:size, 0:size]
        img = np.stack([(x * 4 + k * 3) % 256, (y * 4) % 256, np.full_like(x, 40 * e % 256)], -1).astype(np.uint8)
        a = rng.uniform(-1, 1, 7).astype(np.float32)
        actions.append(a.tolist())
        ds.add_frame({
            "observation.images.image": img,
            "observation.images.wrist_image": img[::-1].copy(),
            "observation.state": rng.uniform(-1, 1, 8).astype(np.float32),
            "action": a,
            "task": task,
        })
    ds.save_episode()
ds.finalize()
print(json.dumps({"actions": actions, "tasks": tasks, "codec": ds.meta.features["observation.images.image"]["info"]["video.codec"]}))
