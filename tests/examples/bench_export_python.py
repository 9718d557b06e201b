"""The tool a lab would otherwise use to turn a recording into training data, the peer of
`teleop export --format lerobot` in bench_export.rs: a plain Python script with the packages a
lab has at hand for MCAP (`mcap` + `mcap-ros2-support`, pinned in .ci/requirements.txt), numpy
and pyarrow.

What it does, as a lab engineer would write it:
- reads the recording once with `mcap.reader.make_reader` and decodes the messages of the
  exported topics (glove/state, hand/state, hand/tactile, hand/command, glove/force_command,
  episode) with `mcap_ros2.decoder.DecoderFactory`, keeping per topic the samples' stamps
  (`header.stamp_ns`) and values in memory (`array.array`, 4 bytes a value);
- cuts episodes from the episode marks (START opens one, STOP closes it with its outcome, a
  START over an open one closes it unlabelled, DISCARD throws away the open one or else the last
  closed one), as teleop-recording's `episodes` rule does;
- resamples each kept episode to FPS frames per second by zero-order hold with numpy
  (`searchsorted`: frame k is due at start + k/fps while not after the stop and holds, per
  topic, the newest sample stamped at or before it; frames before every topic has had a sample
  are dropped), the same rule as `teleop export`;
- writes one parquet file per episode with pyarrow (`write_table`, snappy):
  `observation.state` (glove positions, joint positions and speeds, per fingertip normal and
  tangential force: 28 values for the Revo2), `action` (joint targets), `glove.force_command`
  as fixed-size lists of float32, and lerobot's `timestamp`, `frame_index`, `episode_index`,
  `index`, `task_index`.

What it does not do that `teleop export` does: no feature names from the hand profile (the
Revo2's layout is assumed: 6 joints, 5 fingertips, no efforts), no per-episode statistics or
quantiles, no `meta/` files (info.json, tasks, episodes), no rate rule, no append to an
existing dataset, no crash safety (a killed run leaves what it wrote), no read-back check, no
sessions split over several files; and it holds the whole recording's samples in memory.

Usage: python3 bench_export_python.py RECORDING.mcap OUT_DIR FPS
Prints one JSON object: {"episodes": n, "frames": n, "messages": n (decoded)}.

Or (untimed, after the runs): python3 bench_export_python.py --compare DATASET OUT_DIR
Compares the frames this script wrote to OUT_DIR with those of the LeRobot dataset `teleop
export` wrote to DATASET, column by column in index order, NaN equal to NaN. Prints one JSON
object: {"rows": [dataset's, ours], "differ": [columns whose values differ]}.

Exit status: 0 done; 1 bad input; 2 a Python module is missing (the message names it).
"""

import array
import json
import sys
from pathlib import Path

try:
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
except ImportError as error:  # pragma: no cover
    print(
        f"missing Python package: {error} (pip install -r .ci/requirements.txt)",
        file=sys.stderr,
    )
    sys.exit(2)

# teleop_msgs/msg/Episode's `event` and `outcome` values (shared/core/msgs/src/contract.rs).
START, STOP, DISCARD = 1, 2, 3
JOINTS, TIPS = 6, 5  # the Revo2

# Topic -> values per sample, and how a decoded message gives them.
TOPICS = {
    "glove/state": (6, lambda m: m.position),
    "hand/state": (
        2 * JOINTS,
        lambda m: [j.position for j in m.joints[:JOINTS]]
        + [j.speed for j in m.joints[:JOINTS]],
    ),
    "hand/tactile": (
        2 * TIPS,
        lambda m: [v for f in m.fingertips[:TIPS] for v in (f.normal_n, f.tangential_n)],
    ),
    "hand/command": (JOINTS, lambda m: [j.target for j in m.joints[:JOINTS]]),
    "glove/force_command": (5, lambda m: m.force),
}
STATE = ["glove/state", "hand/state", "hand/tactile"]


def read(path):
    """Per topic: (stamps, values as an n x width float32 array); and the episode marks."""
    stamps = {t: array.array("Q") for t in TOPICS}
    values = {t: array.array("f") for t in TOPICS}
    marks = []
    messages = 0
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(
            topics=[*TOPICS, "episode"]
        ):
            messages += 1
            topic = channel.topic
            if topic == "episode":
                task = bytes(msg.task).split(b"\0", 1)[0].decode("utf-8", "replace")
                marks.append((msg.header.stamp_ns, msg.event, msg.outcome, task))
                continue
            stamps[topic].append(msg.header.stamp_ns)
            values[topic].extend(TOPICS[topic][1](msg))
    samples = {}
    for topic, (width, _) in TOPICS.items():
        t = np.frombuffer(stamps[topic], dtype=np.uint64).astype(np.int64)
        v = np.frombuffer(values[topic], dtype=np.float32).reshape(-1, width)
        order = np.argsort(t, kind="stable")
        samples[topic] = (t[order], v[order])
    return samples, marks, messages


def episodes(marks):
    """The kept episodes: (start_ns, stop_ns, task), in order."""
    closed, open_ = [], None
    for stamp, event, outcome, task in marks:
        if event == START:
            if open_ is not None:
                closed.append([open_[0], max(stamp, open_[0]), open_[1], False])
            open_ = (stamp, task)
        elif event == STOP and open_ is not None:
            closed.append([open_[0], max(stamp, open_[0]), open_[1], False])
            open_ = None
        elif event == DISCARD:
            if open_ is not None:
                open_ = None
            elif closed:
                closed[-1][3] = True
    return [(start, stop, task) for start, stop, task, discarded in closed if not discarded]


def fixed(rows):
    """An n x width float32 array as an arrow column of fixed-size lists."""
    return pa.FixedSizeListArray.from_arrays(pa.array(rows.ravel()), rows.shape[1])


def main(path, out, fps):
    samples, marks, messages = read(path)
    data = Path(out) / "data" / "chunk-000"
    data.mkdir(parents=True, exist_ok=True)
    tasks, index, written = {}, 0, 0
    period = 1e9 / fps
    for start, stop, task in episodes(marks):
        k = np.arange(int((stop - start) / period) + 2)
        due = start + np.round(k * period).astype(np.int64)
        due = due[due <= stop]
        held = {}
        first = 0
        for topic, (t, _) in samples.items():
            i = np.searchsorted(t, due, side="right") - 1
            held[topic] = i
            first = max(first, int(np.searchsorted(i, 0)))  # i only grows
        due = due[first:]
        if len(due) == 0:
            continue
        row = {topic: samples[topic][1][held[topic][first:]] for topic in TOPICS}
        n = len(due)
        frame = np.arange(n, dtype=np.int64)
        task_index = tasks.setdefault(task, len(tasks))
        table = pa.table(
            {
                "observation.state": fixed(np.concatenate([row[t] for t in STATE], axis=1)),
                "action": fixed(row["hand/command"]),
                "glove.force_command": fixed(row["glove/force_command"]),
                "timestamp": pa.array((frame / fps).astype(np.float32)),
                "frame_index": pa.array(frame),
                "episode_index": pa.array(np.full(n, written, dtype=np.int64)),
                "index": pa.array(index + frame),
                "task_index": pa.array(np.full(n, task_index, dtype=np.int64)),
            }
        )
        pq.write_table(table, data / f"episode_{written:06d}.parquet")
        written += 1
        index += n
    print(json.dumps({"episodes": written, "frames": index, "messages": messages}))


def frames(folder):
    """Every parquet file under `folder`/data, concatenated in path order."""
    files = sorted((Path(folder) / "data").glob("*/*.parquet"))
    if not files:
        print(f"{folder}: no data/*/*.parquet", file=sys.stderr)
        sys.exit(1)
    return pa.concat_tables([pq.read_table(f) for f in files])


def compare(dataset, out):
    theirs, ours = frames(dataset), frames(out)
    differ = []
    for name in ours.column_names:
        if name not in theirs.column_names or theirs.num_rows != ours.num_rows:
            differ.append(name)
            continue
        a = np.asarray(theirs.column(name).combine_chunks().flatten() if name in FIXED else theirs.column(name))
        b = np.asarray(ours.column(name).combine_chunks().flatten() if name in FIXED else ours.column(name))
        if not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
            differ.append(name)
    print(json.dumps({"rows": [theirs.num_rows, ours.num_rows], "differ": differ}))


FIXED = {"observation.state", "action", "glove.force_command"}


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--compare":
        compare(sys.argv[2], sys.argv[3])
        sys.exit(0)
    if len(sys.argv) != 4 or not sys.argv[3].isdigit() or int(sys.argv[3]) == 0:
        print(
            "usage: bench_export_python.py RECORDING.mcap OUT_DIR FPS\n"
            "       bench_export_python.py --compare DATASET OUT_DIR",
            file=sys.stderr,
        )
        sys.exit(1)
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
