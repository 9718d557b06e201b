"""dex-retargeting's `DexPilotOptimizer` (PyPI `dex-retargeting`, pinned in .ci/requirements.txt), the
independent peer of our retargeting solver in bench_retarget.rs: the same URDF, target vectors,
weights and scaling go in, its joint positions, solve times and objectives come out, and the Rust
benchmark computes every metric itself.

The optimizer is built as the package's `RetargetingConfig.build` builds it (retargeting_config.py):
the URDF read by its own yourdfpy and written back to a temporary file that pinocchio loads through
`RobotWrapper`, a `MimicJointKinematicAdaptor` when the URDF has `<mimic>` joints, and the URDF's
joint limits set on the optimizer as `SeqRetargeting` does (seq_retarget.py). Then, as
`SeqRetargeting.retarget` does but without its low-pass filter: each frame's `last_qpos` is the
previous frame's result (the first: zeros), clipped to the limits. Unlike `build`, which passes
only scaling and the two projection distances, every DexPilot parameter comes from the input.
The optimizer keeps its `projected` state from frame to frame, as in real use.

What the package's objective is (optimizer.py, `DexPilotOptimizer.get_objective_function`), for
whoever sets our solver up the same: the sum over vectors of weight x SmoothL1(beta=huber_delta) of
the distance to the reference, divided by the number of vectors. Weights: a tip pair 1, or while
projected 200 (thumb pairs) or 400 (other pairs); a wrist -> tip vector n(n-1)/2 + n
(`ones * len_proj + num_fingers`: 10 for 4 tips, 15 for 5). A projected pair's reference is its
direction x eta1 (thumb pairs) or eta2 (others), not scaled; the others are scaled. A non-thumb
pair projects only while both its thumb pairs do and its own distance is <= 0.03 m (a constant,
not project_dist).

Usage: python3 bench_retarget_dexpilot.py INPUT.json > OUTPUT.json

INPUT: {"urdf": path, "wrist_link": name, "tip_links": [thumb first, ...], "target_joint_names":
[...], "scaling", "huber_delta", "norm_delta", "project_dist", "escape_dist", "eta1", "eta2":
numbers, "frames": [[[x, y, z], ...], ...]}: per frame, for n tips, the n(n-1)/2 tip-pair vectors in
`DexPilotOptimizer.generate_link_indices` order, then the n wrist -> tip vectors (task - origin,
metres, unscaled).

OUTPUT: {"versions": {...}, "joint_names": [order of q], "frames": [{"q": [...], "solve_us": wall
time of `optimizer.retarget()`, "objective": nlopt's `last_optimum_value()` (the weighted Huber
sum only: the optimizer puts its `norm_delta` term into the gradient, not the value),
"nlopt_result": `last_optimize_result()`, "error": present only when nlopt raised something that
`retarget()` does not catch itself (q is then last_qpos, as `retarget()` gives on its own
RuntimeError)}]}.

Exit status: 0 done; 1 bad input or a failure building the optimizer; 2 a Python module is missing
(the message names it and the pip line that installs it).
"""

import importlib
import importlib.metadata
import json
import sys
import tempfile
import time
from pathlib import Path

# module -> the PyPI package that provides it (versions: .ci/requirements.txt).
MODULES = {
    "numpy": "numpy",
    "torch": "torch",
    "nlopt": "nlopt",
    "pinocchio": "pin",
    "dex_retargeting": "dex-retargeting",
}

PARAMETERS = ("scaling", "huber_delta", "norm_delta", "project_dist", "escape_dist", "eta1", "eta2")


class Failure(Exception):
    """A failure that ends the run with its message."""


def import_modules():
    for module, package in MODULES.items():
        try:
            importlib.import_module(module)
        except ImportError as e:
            print(
                f"error: Python module {module} is not importable ({e}); install it with "
                f"`python3 -m pip install {package}` (the pinned version: "
                f"`python3 -m pip install -r .ci/requirements.txt`)",
                file=sys.stderr,
            )
            sys.exit(2)


def read_input(path):
    try:
        spec = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise Failure(f"cannot read input {path}: {e}") from e
    if not isinstance(spec, dict):
        raise Failure(f"input {path}: a JSON object expected")
    for key in ("urdf", "wrist_link", "tip_links", "target_joint_names", "frames", *PARAMETERS):
        if key not in spec:
            raise Failure(f"input {path}: no `{key}`")
    for key in PARAMETERS:
        if not isinstance(spec[key], (int, float)):
            raise Failure(f"input {path}: `{key}` is {spec[key]!r}, not a number")
    for key in ("urdf", "wrist_link"):
        if not isinstance(spec[key], str):
            raise Failure(f"input {path}: `{key}` is {spec[key]!r}, not a string")
    for key in ("tip_links", "target_joint_names"):
        if not (isinstance(spec[key], list) and all(isinstance(name, str) for name in spec[key])):
            raise Failure(f"input {path}: `{key}` is {spec[key]!r}, not a list of names")
    if not isinstance(spec["frames"], list):
        raise Failure(f"input {path}: `frames` is not a list")
    return spec


def target_vectors(spec, tips):
    """The frames as (frames, vectors, 3) float32 (as `SeqRetargeting` hands them on), checked."""
    import numpy as np

    count = tips * (tips - 1) // 2 + tips
    frames = []
    for i, frame in enumerate(spec["frames"]):
        try:
            vectors = np.asarray(frame, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise Failure(f"frame {i}: not a list of [x, y, z]: {e}") from e
        if vectors.shape != (count, 3):
            raise Failure(
                f"frame {i}: shape {vectors.shape}, expected ({count}, 3) for {tips} tips "
                f"({tips * (tips - 1) // 2} tip pairs, then {tips} wrist -> tip)"
            )
        if not np.all(np.isfinite(vectors)):
            raise Failure(f"frame {i}: a vector is not finite")
        frames.append(vectors.astype(np.float32))
    return frames


def build(spec):
    """The optimizer, the target joints' limits (target order) and the fixed joints' positions."""
    import numpy as np
    from dex_retargeting import yourdfpy
    from dex_retargeting.kinematics_adaptor import MimicJointKinematicAdaptor
    from dex_retargeting.optimizer import DexPilotOptimizer
    from dex_retargeting.retargeting_config import parse_mimic_joint
    from dex_retargeting.robot_wrapper import RobotWrapper

    urdf_path = Path(spec["urdf"])
    try:
        robot_urdf = yourdfpy.URDF.load(str(urdf_path), build_scene_graph=False)
    except Exception as e:
        raise Failure(f"yourdfpy cannot load {urdf_path}: {e}") from e
    with tempfile.TemporaryDirectory(prefix="dex_retargeting-") as temp_dir:
        temp_path = Path(temp_dir) / urdf_path.name
        robot_urdf.write_xml_file(str(temp_path))
        try:
            robot = RobotWrapper(str(temp_path))
        except Exception as e:
            raise Failure(f"pinocchio cannot build {urdf_path} (as yourdfpy wrote it back): {e}") from e

    try:
        optimizer = DexPilotOptimizer(
            robot,
            list(spec["target_joint_names"]),
            finger_tip_link_names=list(spec["tip_links"]),
            wrist_link_name=spec["wrist_link"],
            huber_delta=spec["huber_delta"],
            norm_delta=spec["norm_delta"],
            project_dist=spec["project_dist"],
            escape_dist=spec["escape_dist"],
            eta1=spec["eta1"],
            eta2=spec["eta2"],
            scaling=spec["scaling"],
        )
        has_mimic, sources, mimics, multipliers, offsets = parse_mimic_joint(robot_urdf)
        if has_mimic:
            optimizer.set_kinematic_adaptor(
                MimicJointKinematicAdaptor(
                    robot,
                    target_joint_names=optimizer.target_joint_names,
                    source_joint_names=sources,
                    mimic_joint_names=mimics,
                    multipliers=multipliers,
                    offsets=offsets,
                )
            )
    except ValueError as e:
        raise Failure(f"DexPilotOptimizer on {urdf_path}: {e}") from e

    limits = robot.joint_limits
    optimizer.set_joint_limit(limits[optimizer.idx_pin2target])
    fixed = limits[optimizer.idx_pin2fixed]
    # Joints neither moved by the optimizer nor mimicking one stay at zero (within their limits).
    fixed_qpos = np.clip(np.zeros(len(fixed)), fixed[:, 0], fixed[:, 1]).astype(np.float32)
    return optimizer, limits[optimizer.idx_pin2target], fixed_qpos


def run(spec):
    import nlopt
    import numpy as np
    import pinocchio
    import torch

    optimizer, limits, fixed_qpos = build(spec)
    frames = target_vectors(spec, len(spec["tip_links"]))
    lower, upper = limits[:, 0], limits[:, 1]
    last_qpos = np.zeros(len(lower), dtype=np.float32)
    results = []
    for vectors in frames:
        last_qpos = np.clip(last_qpos, lower, upper)
        error = None
        start = time.perf_counter_ns()
        try:
            qpos = optimizer.retarget(ref_value=vectors, fixed_qpos=fixed_qpos, last_qpos=last_qpos)
        except Exception as e:  # nlopt's RoundoffLimited and ForcedStop are not RuntimeErrors
            qpos, error = np.array(last_qpos, dtype=np.float32), f"{type(e).__name__}: {e}"
        solve_ns = time.perf_counter_ns() - start
        frame = {
            "q": [float(v) for v in qpos],
            "solve_us": solve_ns / 1000.0,
            "objective": float(optimizer.opt.last_optimum_value()),
            "nlopt_result": int(optimizer.opt.last_optimize_result()),
        }
        if error is not None:
            frame["error"] = error
        results.append(frame)
        last_qpos = qpos
    return {
        "versions": {
            "dex_retargeting": importlib.metadata.version("dex-retargeting"),
            "pinocchio": pinocchio.__version__,
            "nlopt": nlopt.__version__,
            "torch": torch.__version__,
            "numpy": np.__version__,
        },
        "joint_names": list(optimizer.target_joint_names),
        "frames": results,
    }


def main():
    if len(sys.argv) != 2:
        print("usage: python3 bench_retarget_dexpilot.py INPUT.json", file=sys.stderr)
        sys.exit(1)
    # `Optimizer.retarget` prints nlopt's RuntimeError to stdout: only our JSON goes there.
    out, sys.stdout = sys.stdout, sys.stderr
    import_modules()
    try:
        result = run(read_input(sys.argv[1]))
    except Failure as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(1)
    json.dump(result, out)
    out.write("\n")


if __name__ == "__main__":
    main()
