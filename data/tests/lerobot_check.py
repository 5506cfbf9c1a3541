"""Opens a `data export-lerobot` directory with LeRobot's own `LeRobotDataset` and checks it
against what the Rust test expects (a JSON file written by the test).

Usage: python lerobot_check.py ROOT EXPECT.json
EXPECT: {"frames", "episodes", "tasks": [...], "first_action": [7], "last_action": [7],
         "frame": {"index": i, "rgb": "path of raw [H, W, 3] uint8 bytes", "max_mean_abs": x},
         "episode_lengths": [...], "backends": ["pyav", "torchcodec"?]}
Prints one JSON line with what it measured; exits 1 on a mismatch.
"""

import json
import sys

import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset

root, expect_path = sys.argv[1], sys.argv[2]
expect = json.load(open(expect_path))
report = {}
failures = []

for backend in expect["backends"]:
    ds = LeRobotDataset("libero_mem/export", root=root, video_backend=backend)
    report["frames"] = len(ds)
    report["episodes"] = ds.num_episodes
    if len(ds) != expect["frames"]:
        failures.append(f"{backend}: {len(ds)} frames, expected {expect['frames']}")
    if ds.num_episodes != expect["episodes"]:
        failures.append(f"{backend}: {ds.num_episodes} episodes, expected {expect['episodes']}")
    lengths = [int(e["length"]) for e in ds.meta.episodes]
    if lengths != expect["episode_lengths"]:
        failures.append(f"{backend}: episode lengths {lengths}, expected {expect['episode_lengths']}")
    tasks = list(ds.meta.tasks.index)
    if tasks != expect["tasks"]:
        failures.append(f"{backend}: tasks {tasks}, expected {expect['tasks']}")
    first, last = ds[0], ds[len(ds) - 1]
    for name, item, want in [("first", first, expect["first_action"]), ("last", last, expect["last_action"])]:
        got = item["action"].numpy().astype(np.float32)
        if not np.array_equal(got, np.asarray(want, dtype=np.float32)):
            failures.append(f"{backend}: {name} action {got.tolist()}, expected {want}")
    if first["task"] != expect["tasks"][0]:
        failures.append(f"{backend}: first task {first['task']!r}")
    f = expect["frame"]
    item = ds[f["index"]]
    img = item["observation.images.image"]  # [3, H, W] float32 in [0, 1]
    got = (img.permute(1, 2, 0).numpy() * 255.0).round()
    want = np.frombuffer(open(f["rgb"], "rb").read(), dtype=np.uint8).reshape(got.shape).astype(np.float64)
    mean_abs = float(np.abs(got - want).mean())
    report[f"mean_abs_{backend}"] = mean_abs
    report["frame_shape"] = list(img.shape)
    if mean_abs > f["max_mean_abs"]:
        failures.append(f"{backend}: frame {f['index']} differs by {mean_abs:.2f} grey levels on average")
    # Timestamps of every frame: k / fps within the episode.
    ts = [float(ds.hf_dataset[i]["timestamp"]) for i in range(len(ds))]
    fi = [int(ds.hf_dataset[i]["frame_index"]) for i in range(len(ds))]
    if any(abs(t - k / ds.fps) > 1e-4 for t, k in zip(ts, fi)):
        failures.append(f"{backend}: timestamps are not frame_index / fps")
    if ds.meta.stats is None or "action" not in ds.meta.stats:
        failures.append("no action statistics in meta/stats.json")

report["failures"] = failures
print(json.dumps(report))
sys.exit(1 if failures else 0)
