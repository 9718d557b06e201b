#!/usr/bin/env python3
"""Loads a LeRobot dataset with lerobot's own LeRobotDataset (the training side's reader).

    load_lerobot.py DATASET

Prints one JSON object: the dataset's episode and frame counts as lerobot sees them, each
episode's length, and the first frame of every episode (observation.state, action, task,
episode_index, frame_index, timestamp) as lerobot returns it. Exits 2 when lerobot cannot be
imported (it pulls in torch; the caller decides whether that skips), 1 when loading fails.
"""

import json
import os
import sys

os.environ.setdefault("HF_HUB_OFFLINE", "1")

try:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
except ImportError as e:
    print(f"lerobot is not importable: {e}", file=sys.stderr)
    sys.exit(2)


def plain(value):
    """A tensor or number as JSON-able lists and floats."""
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def main():
    root = sys.argv[1]
    dataset = LeRobotDataset("local/teleop", root=root)
    report = {
        "num_episodes": dataset.num_episodes,
        "num_frames": dataset.num_frames,
        "fps": dataset.fps,
        "lengths": [],
        "first_frames": [],
    }
    episodes = dataset.meta.episodes
    for e in range(dataset.num_episodes):
        start = int(episodes[e]["dataset_from_index"])
        end = int(episodes[e]["dataset_to_index"])
        report["lengths"].append(end - start)
        item = dataset[start]
        report["first_frames"].append(
            {key: plain(item[key]) for key in
             ["observation.state", "action", "task", "episode_index", "frame_index", "timestamp"]
             if key in item}
        )
    print(json.dumps(report))


if __name__ == "__main__":
    try:
        main()
    except Exception as e:  # any failure to load is the finding
        print(f"lerobot could not load the dataset: {type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(1)
