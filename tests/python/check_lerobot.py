#!/usr/bin/env python3
"""An independent reader of a LeRobot v3.0 dataset, with pyarrow only (no teleop code, no lerobot).

    check_lerobot.py DATASET [--frame INDEX]

Reads every parquet file of the dataset and checks that:
- meta/info.json has the v3.0 keys, and its features match the data files' columns, types and
  shapes (a float32 vector of shape [n] is a fixed-size list of n float32; shape [1] a scalar);
- the data files together hold total_frames rows, `index` 0..total_frames-1 in file order, and
  each frame's timestamp is frame_index / fps;
- meta/episodes/ holds total_episodes rows, episode_index 0, 1, ..., and each episode's
  data/chunk_index, data/file_index, dataset_from_index, dataset_to_index and length point at
  exactly the rows of that episode (episode_index, frame_index 0..length-1, its task_index);
- each episode's stats/<feature>/{min,max,count} columns equal those of its rows;
- meta/tasks.parquet has task_index 0..total_tasks-1 and pandas metadata making `task` the index
  (and, where pandas is installed, pandas reads it so, as lerobot does);
- meta/stats.json has min, max, mean, std, count, q01..q99 per feature, count = total_frames,
  min/max those of all frames;
- where numpy is installed (CI has it), each episode's mean, std and quantiles are those that
  our numpy transcription of lerobot's method (compute_stats.py: get_feature_stats with
  RunningQuantileStats, aggregate_feature_stats) computes from its rows, and stats.json is that
  transcription's aggregate of the episodes'. This is not lerobot's code and it computes in
  float64 where lerobot computes in the column's float32: it checks that the writer computed
  what the method says, at f64, independently of the writer's code; a misreading of the method
  shared by both would pass, and lerobot's own float32 values differ at float32 rounding.

Prints one JSON object: {"ok": true, "total_episodes": ..., "total_frames": ..., "frame": {...}}
with the frame of global index INDEX (every column), or exits 1 naming the first failure.
Exits 2 when pyarrow cannot be imported (the caller decides whether that skips).
"""

import glob
import json
import math
import os
import sys

try:
    import pyarrow as pa
    import pyarrow.parquet as pq
except ImportError as e:  # the caller tells "skip" from "fail"
    print(f"pyarrow is not importable: {e}", file=sys.stderr)
    sys.exit(2)

QUANTILES = ["q01", "q10", "q50", "q90", "q99"]
STATS = ["min", "max", "mean", "std", "count"] + QUANTILES
INFO_KEYS = [
    "codebase_version", "robot_type", "total_episodes", "total_frames", "total_tasks",
    "chunks_size", "data_files_size_in_mb", "fps", "splits", "data_path", "features",
]


class Failure(Exception):
    pass


def need(cond, what):
    if not cond:
        raise Failure(what)


def close(a, b):
    return a == b or (isinstance(a, float) and isinstance(b, float) and (
        (math.isnan(a) and math.isnan(b)) or abs(a - b) <= 1e-6 * max(1.0, abs(a), abs(b))))


def files(root, sub):
    return sorted(glob.glob(os.path.join(root, sub, "chunk-*", "file-*.parquet")))


def chunk_file(path):
    chunk = int(os.path.basename(os.path.dirname(path))[len("chunk-"):])
    file = int(os.path.basename(path)[len("file-"):-len(".parquet")])
    return chunk, file


def check_type(name, feature, field):
    shape = feature["shape"]
    dtype = feature["dtype"]
    want = {"float32": pa.float32(), "int64": pa.int64()}.get(dtype)
    need(want is not None, f"feature {name}: dtype {dtype} is not one this check knows")
    if list(shape) == [1]:
        need(field.type == want, f"column {name}: {field.type}, info.json says {dtype} scalar")
    else:
        need(len(shape) == 1, f"feature {name}: shape {shape}")
        need(pa.types.is_fixed_size_list(field.type) and field.type.list_size == shape[0]
             and field.type.value_type == want,
             f"column {name}: {field.type}, info.json says {dtype}[{shape[0]}]")
        names = feature.get("names")
        need(isinstance(names, list) and len(names) == shape[0],
             f"feature {name}: {len(names or [])} names for shape {shape}")


def column_values(rows, name):
    """Per dimension, the values of a column over `rows` (a list of dicts)."""
    first = rows[0][name]
    if isinstance(first, list):
        return [[r[name][d] for r in rows] for d in range(len(first))]
    return [[r[name] for r in rows]]


def lerobot_episode_stats(np, values):
    """An episode's statistics by our transcription of lerobot's method
    (compute_stats.get_feature_stats with RunningQuantileStats fed the episode in one batch),
    computed in float64 (lerobot: the column's float32): min, max, mean, population
    std from E[x^2] - E[x]^2, and each quantile read off a 5000-bin histogram over
    [min - 1e-10, max + 1e-10], interpolated inside the bin; one frame: std 0, quantiles = mean."""
    x = np.asarray(values, dtype=np.float64).reshape(len(values), -1)
    out = {"min": x.min(0), "max": x.max(0), "mean": x.mean(0)}
    if len(x) < 2:
        out["std"] = np.zeros(x.shape[1])
        for q in QUANTILES:
            out[q] = out["mean"]
        return out
    out["std"] = np.sqrt(np.maximum(0.0, (x ** 2).mean(0) - out["mean"] ** 2))
    for q in QUANTILES:
        out[q] = np.zeros(x.shape[1])
    for d in range(x.shape[1]):
        edges = np.linspace(out["min"][d] - 1e-10, out["max"][d] + 1e-10, 5001)
        hist, _ = np.histogram(x[:, d], bins=edges)
        cumsum = np.cumsum(hist)
        for q in QUANTILES:
            target = int(q[1:]) / 100 * len(x)
            idx = int(np.searchsorted(cumsum, target))
            if idx == 0:
                value = edges[0]
            elif idx >= len(cumsum):
                value = edges[-1]
            else:
                before = cumsum[idx - 1]
                inside = cumsum[idx] - before
                value = edges[idx] if inside == 0 else (
                    edges[idx] + (target - before) / inside * (edges[idx + 1] - edges[idx]))
            out[q][d] = value
    return out


def lerobot_aggregate(np, parts):
    """stats.json from the episodes' statistics by our transcription of lerobot's
    aggregate_feature_stats, in float64."""
    counts = np.array([p["count"][0] for p in parts], dtype=np.float64)
    total = counts.sum()
    means = np.array([p["mean"] for p in parts])
    mean = (means * counts[:, None]).sum(0) / total
    var = ((np.array([p["std"] for p in parts]) ** 2 + (means - mean) ** 2) * counts[:, None]).sum(0) / total
    out = {"min": np.array([p["min"] for p in parts]).min(0),
           "max": np.array([p["max"] for p in parts]).max(0),
           "mean": mean, "std": np.sqrt(var)}
    for q in QUANTILES:
        stack = np.array([p[q] for p in parts])
        out[q] = stack.min(0) if int(q[1:]) <= 50 else stack.max(0)
    return out


def near(np, got, want, tolerance):
    return len(got) == len(want) and bool(np.all(np.abs(np.asarray(got, dtype=np.float64) - want) <= tolerance))


def main():
    args = sys.argv[1:]
    frame_at = None
    if "--frame" in args:
        i = args.index("--frame")
        frame_at = int(args[i + 1])
        del args[i:i + 2]
    if len(args) != 1:
        print(__doc__, file=sys.stderr)
        return 64
    root = args[0]
    with open(os.path.join(root, "meta", "info.json")) as f:
        info = json.load(f)
    for key in INFO_KEYS:
        need(key in info, f"info.json: no `{key}`")
    need(info["codebase_version"] == "v3.0", f"codebase_version {info['codebase_version']}")
    features = info["features"]
    fps = info["fps"]
    for key in ["timestamp", "frame_index", "episode_index", "index", "task_index"]:
        need(key in features, f"info.json: no default feature `{key}`")
    need(info["splits"].get("train") == f"0:{info['total_episodes']}",
         f"splits {info['splits']} for {info['total_episodes']} episodes")

    # Data: every file, its schema against info.json, rows in order.
    data = {}
    rows = []
    for path in files(root, "data"):
        table = pq.read_table(path)
        need(set(table.column_names) == set(features),
             f"{path}: columns {sorted(table.column_names)}, features {sorted(features)}")
        for name, feature in features.items():
            check_type(name, feature, table.schema.field(name))
        expected = info["data_path"].format(chunk_index=chunk_file(path)[0],
                                            file_index=chunk_file(path)[1])
        need(path.endswith(expected), f"{path} is not named as data_path {info['data_path']}")
        first = len(rows)
        rows.extend(table.to_pylist())
        data[chunk_file(path)] = (first, len(rows))
    need(len(rows) == info["total_frames"],
         f"data files hold {len(rows)} rows, total_frames is {info['total_frames']}")
    for i, r in enumerate(rows):
        need(r["index"] == i, f"row {i} has index {r['index']}")
        t = r["frame_index"] / fps
        need(abs(r["timestamp"] - t) < 1e-4, f"row {i}: timestamp {r['timestamp']}, frame_index/fps {t}")

    # Tasks.
    tasks_table = pq.read_table(os.path.join(root, "meta", "tasks.parquet"))
    tasks = tasks_table.to_pylist()
    need(len(tasks) == info["total_tasks"], f"{len(tasks)} tasks, total_tasks {info['total_tasks']}")
    need([t["task_index"] for t in tasks] == list(range(len(tasks))), "task_index is not 0..n-1")
    pandas = json.loads((tasks_table.schema.metadata or {}).get(b"pandas", b"{}"))
    need(pandas.get("index_columns") == ["task"], "tasks.parquet: `task` is not the pandas index")
    task_index = {t["task"]: t["task_index"] for t in tasks}
    try:  # lerobot reads the tasks with pandas (load_tasks): where it is installed, read them so too
        import pandas
    except ImportError:
        pandas = None
    if pandas is not None:
        frame = pandas.read_parquet(os.path.join(root, "meta", "tasks.parquet"))
        need(frame.index.name == "task", f"pandas reads the tasks indexed by {frame.index.name!r}")
        need({str(k): int(v) for k, v in frame["task_index"].items()} == task_index,
             "pandas reads other tasks than pyarrow")

    try:  # numpy (which pyarrow does not need) checks the statistics by our transcription of lerobot's method
        import numpy as np
    except ImportError:
        np = None

    # Episodes: each points at exactly its rows.
    episodes = []
    for path in files(root, os.path.join("meta", "episodes")):
        table = pq.read_table(path)
        for e in table.to_pylist():
            need((e["meta/episodes/chunk_index"], e["meta/episodes/file_index"]) == chunk_file(path),
                 f"{path}: episode {e['episode_index']} names another meta/episodes file")
            episodes.append(e)
    need(len(episodes) == info["total_episodes"],
         f"{len(episodes)} episode rows, total_episodes {info['total_episodes']}")
    for n, e in enumerate(episodes):
        need(e["episode_index"] == n, f"episode row {n} has episode_index {e['episode_index']}")
        lo, hi = e["dataset_from_index"], e["dataset_to_index"]
        need(hi - lo == e["length"] > 0, f"episode {n}: {lo}..{hi} for length {e['length']}")
        key = (e["data/chunk_index"], e["data/file_index"])
        need(key in data, f"episode {n}: data file {key} does not exist")
        first, end = data[key]
        need(first <= lo and hi <= end, f"episode {n}: rows {lo}..{hi} are not in data file {key}")
        mine = rows[lo:hi]
        need(all(r["episode_index"] == n for r in mine), f"episode {n}: rows of another episode")
        need([r["frame_index"] for r in mine] == list(range(e["length"])),
             f"episode {n}: frame_index is not 0..length-1")
        need(len(e["tasks"]) == 1 and e["tasks"][0] in task_index, f"episode {n}: tasks {e['tasks']}")
        need(all(r["task_index"] == task_index[e["tasks"][0]] for r in mine),
             f"episode {n}: rows' task_index is not its task's")
        others = [r for r in rows[:lo] + rows[hi:] if r["episode_index"] == n]
        need(not others, f"episode {n}: {len(others)} of its rows lie outside its range")
        for name in features:
            for stat in STATS:
                need(f"stats/{name}/{stat}" in e, f"episode {n}: no stats/{name}/{stat}")
            cols = column_values(mine, name)
            need(e[f"stats/{name}/count"] == [len(mine)], f"episode {n}: stats/{name}/count")
            for stat, fn in (("min", min), ("max", max)):
                got = e[f"stats/{name}/{stat}"]
                want = [float(fn(c)) for c in cols]
                need(len(got) == len(want) and all(close(float(a), b) for a, b in zip(got, want)),
                     f"episode {n}: stats/{name}/{stat} {got[:4]}..., its rows say {want[:4]}...")
            if np is not None:
                want = lerobot_episode_stats(np, [r[name] for r in mine])
                for stat in ["mean", "std"] + QUANTILES:
                    slack = 1e-9 * np.maximum(1.0, np.abs(want[stat]))
                    need(near(np, e[f"stats/{name}/{stat}"], want[stat], slack),
                         f"episode {n}: stats/{name}/{stat} is not lerobot's: "
                         f"{e[f'stats/{name}/{stat}'][:4]}... vs {list(want[stat][:4])}...")

    # Global stats.
    with open(os.path.join(root, "meta", "stats.json")) as f:
        stats = json.load(f)
    for name in features:
        need(name in stats, f"stats.json: no `{name}`")
        width = features[name]["shape"][0]
        for stat in STATS:
            need(stat in stats[name], f"stats.json: `{name}` has no `{stat}`")
            need(len(stats[name][stat]) == (1 if stat == "count" else width),
                 f"stats.json: `{name}`.{stat} has {len(stats[name][stat])} values")
        need(stats[name]["count"] == [len(rows)], f"stats.json: `{name}`.count {stats[name]['count']}")
        cols = column_values(rows, name)
        for stat, fn in (("min", min), ("max", max)):
            want = [float(fn(c)) for c in cols]
            need(all(close(float(a), b) for a, b in zip(stats[name][stat], want)),
                 f"stats.json: `{name}`.{stat} is not that of all frames")
        if np is not None:
            parts = [{stat: e[f"stats/{name}/{stat}"] for stat in STATS} for e in episodes]
            want = lerobot_aggregate(np, parts)
            for stat in ["mean", "std"] + QUANTILES:
                need(near(np, stats[name][stat], want[stat], 1e-9 * np.maximum(1.0, np.abs(want[stat]))),
                     f"stats.json: `{name}`.{stat} is not lerobot's aggregate of the episodes")

    out = {
        "ok": True,
        "total_episodes": info["total_episodes"],
        "total_frames": info["total_frames"],
        "total_tasks": info["total_tasks"],
        "data_files": len(data),
        "stats_checked_by_lerobots_method": np is not None,
    }
    if frame_at is not None:
        need(0 <= frame_at < len(rows), f"--frame {frame_at}: the dataset has {len(rows)} frames")
        out["frame"] = rows[frame_at]
    print(json.dumps(out, allow_nan=True))
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Failure as e:
        print(f"check_lerobot: {e}", file=sys.stderr)
        sys.exit(1)
