"""`so101 dataset DIR`: what a LeRobot v3.0 dataset holds; `--plot N` draws episode N's joints.

Reads any LeRobot v3.0 dataset (ours or LeRobot's own) with so101.dataset.reader, and says in
which units its joints are read (so101.dataset.units: its meta, `--units`, or values that can only
be degrees). The plot shows, per joint, the action (what the arm was told) against
observation.state (where it was), in degrees for the five arm joints (normalized ones made
degrees) and LeRobot's 0-100 for the gripper; a dataset whose units cannot be known is not drawn.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from so101.runtime import argtypes
from so101.dataset.features import ACTION_KEY, GRIPPER_RANGE, STATE_KEY, to_lerobot
from so101.dataset.layout import DatasetError
from so101.dataset.reader import Dataset
from so101.dataset.units import UNITS, UNITS_HELP, JointUnits

PLOT_SIZE_IN = (12.0, 8.0)
PLOT_DPI = 100  # 1200 x 800 pixels


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("root", type=Path, metavar="DIR", help="the dataset's folder (LeRobot v3.0)")
    parser.add_argument("--plot", type=argtypes.whole_number(0, 10**9), metavar="N", default=None,
                        help="also draw episode N's six joints, action against observation.state over time (PNG)")
    parser.add_argument("--out", type=Path, default=None, metavar="FILE",
                        help="the PNG --plot writes (default out/episode-N.png)")
    parser.add_argument("--units", choices=UNITS, default=None, help=UNITS_HELP)
    parser.add_argument("--convert", action="store_true",
                        help="make a LeRobot v2.1 dataset v3.0 in place, with LeRobot's own converter (in the policy "
                        "environment, offline); the original is kept beside it as DIR_old")
    parser.add_argument("--policy-python", type=Path, default=None, metavar="PY",
                        help="--convert: the policy environment's Python, with LeRobot (default: so101 policy-env's)")
    parser.add_argument("--calibration", type=Path, default=None, metavar="FILE",
                        help="--units normalized: the recording follower's LeRobot calibration JSON, whose ranges make "
                        "the joints degrees (default: the URDF's joint ranges)")


def _shape_text(shape: list[int]) -> str:
    return "(" + ", ".join(str(size) for size in shape) + ("," if len(shape) == 1 else "") + ")"


def summary_lines(dataset: Dataset, units_line: str = "") -> list[str]:
    """The dataset in lines: its episodes, totals, tasks, features and (`units_line`) its joints' units."""
    total_s = dataset.total_frames / dataset.fps
    lines = [f"{dataset.root}: LeRobot {dataset.info.get('codebase_version', '?')} dataset, "
             f"robot {dataset.robot_type or 'unknown'}, {dataset.fps} fps"]
    if dataset.episodes:
        lines.append(f"{len(dataset.episodes)} episodes:")
        lines.append(f"  {'episode':>7}  {'frames':>6}  {'duration':>9}  task")
        for episode in dataset.episodes:
            lines.append(f"  {episode.index:>7}  {episode.length:>6}  {episode.duration_s:>7.1f} s  "
                         f"{' | '.join(episode.tasks)}")
    else:
        lines.append("no episodes yet")
    lines.append(f"total: {dataset.total_frames} frames, {total_s:.1f} s at {dataset.fps} fps")
    lines.append(f"{len(dataset.tasks)} tasks:")
    lines += [f"  {index:>3}: {task}" for index, task in enumerate(dataset.tasks)]
    lines.append("features:")
    width = max(len(key) for key in dataset.features)
    for key, feature in dataset.features.items():
        line = f"  {key:<{width}}  {feature['dtype']:<8} {_shape_text(list(feature['shape']))}"
        video = feature.get("info") or {}
        if feature["dtype"] == "video" and video:
            line += f"  {video.get('video.codec', '?')} {video.get('video.width', '?')}x{video.get('video.height', '?')}"
        lines.append(line)
    return lines + ([units_line] if units_line else [])


def write_plot(dataset: Dataset, index: int, out: Path, units: JointUnits) -> None:
    """Episode `index`'s joints over time: action and observation.state, one panel per joint."""
    frames = dataset.episode_frames(index)
    missing = [key for key in (ACTION_KEY, STATE_KEY) if key not in frames]
    if missing:
        raise DatasetError(f"{dataset.root} has no {' or '.join(missing)}: --plot draws action against "
                           "observation.state")
    joints_deg = dataset.episode_joints_deg(index, units)
    actions, states = (np.array([to_lerobot(frame) for frame in joints_deg[key]]) for key in (ACTION_KEY, STATE_KEY))
    times_s = frames["frame_index"] / dataset.fps if "frame_index" in frames else np.arange(len(actions)) / dataset.fps
    names = dataset.features[ACTION_KEY].get("names") or [f"joint {i}" for i in range(actions.shape[1])]
    episode = next(e for e in dataset.episodes if e.index == index)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = (actions.shape[1] + 1) // 2
    figure, axes = plt.subplots(rows, 2, figsize=PLOT_SIZE_IN, dpi=PLOT_DPI, sharex=True, squeeze=False)
    for joint, name in enumerate(names):
        panel = axes[joint // 2][joint % 2]
        panel.plot(times_s, actions[:, joint], linewidth=1.6, label="action (told)")
        panel.plot(times_s, states[:, joint], linewidth=1.6, linestyle="--", label="observation.state (measured)")
        is_gripper = str(name).startswith("gripper")
        unit = f"opening, {GRIPPER_RANGE[0]:g}-{GRIPPER_RANGE[1]:g} (LeRobot)" if is_gripper else "angle (degrees)"
        panel.set_title(str(name), fontsize=10)
        panel.set_ylabel(unit)
        panel.grid(True, alpha=0.3)
        if joint == 0:
            panel.legend(loc="best", fontsize=8)
    for panel in axes[-1]:
        panel.set_xlabel("time in the episode (s)")
    for extra in range(len(names), rows * 2):
        axes[extra // 2][extra % 2].set_visible(False)
    figure.suptitle(f"{dataset.root.name}: episode {index}, {episode.length} frames ({episode.duration_s:.1f} s), "
                    f"task: {' | '.join(episode.tasks)}", fontsize=11)
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out)
    plt.close(figure)


def convert(args: argparse.Namespace) -> int:
    from so101.dataset.convert import check_convertible, convert_to_v30
    from so101.policy.environment import PolicyEnvError, check, default_dir, python_in

    root = args.root.expanduser().resolve()
    try:
        check_convertible(root)
    except DatasetError as error:
        print(f"so101 dataset: {error}", file=sys.stderr)
        return 2
    try:
        python = check((args.policy_python or python_in(default_dir())).expanduser()).python
    except PolicyEnvError as error:
        print(f"so101 dataset: --convert runs LeRobot's converter in the policy environment: {error}", file=sys.stderr)
        return 2
    print(f"converting {root} to LeRobot v3.0 with LeRobot's own converter ({python})...", flush=True)
    try:
        kept = convert_to_v30(root, python, Path("out") / f"convert-{root.name}.log")
        dataset = Dataset.open(root)
    except DatasetError as error:
        print(f"so101 dataset: {error}", file=sys.stderr)
        return 2
    print(f"converted: {root} is v3.0 ({len(dataset.episodes)} episodes, {dataset.total_frames} frames); "
          f"the v2.1 original is kept in {kept}")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.convert:
        if args.plot is not None:
            print("so101 dataset: --convert and --plot N: convert first, then plot", file=sys.stderr)
            return 2
        return convert(args)
    if args.policy_python is not None:
        print("so101 dataset: --policy-python goes with --convert", file=sys.stderr)
        return 2
    units: JointUnits | None = None
    try:
        dataset = Dataset.open(args.root)
        if args.plot is not None:
            dataset.episode_frames(args.plot)  # an episode that does not exist: say so before drawing
        try:
            units = dataset.joint_units(args.units, args.calibration, args.plot)
            units_line = units.how
        except DatasetError as error:
            if args.plot is not None or args.units or args.calibration:
                raise
            units_line = f"joints: {str(error).removeprefix(f'{dataset.root}: ')}"
    except DatasetError as error:
        print(f"so101 dataset: {error}", file=sys.stderr)
        return 2
    print("\n".join(summary_lines(dataset, units_line)))
    if args.plot is not None and units is not None:
        out = args.out if args.out is not None else Path(f"out/episode-{args.plot}.png")
        try:
            write_plot(dataset, args.plot, out, units)
        except DatasetError as error:
            print(f"so101 dataset: {error}", file=sys.stderr)
            return 2
        print(f"wrote {out}")
    return 0
