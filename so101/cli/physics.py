"""`so101 physics`: the ranges varied physics draws from, and why; `--fit` measures a recording's servos.

- `so101 physics [--ranges FILE]` prints each range (the defaults, or a ranges file's) with why it is what it is.
- `so101 physics --fit --from DATASET [--episodes 0,1] [--units U] [--calibration FILE] [-o FILE]` fits each
  joint's delay, time constant, speed limit and resting offset to how the recording's states followed its
  actions (so101.bodies.servo_fit), prints each joint's error before (the state as a perfect servo would
  have it) and after, on the episodes fitted and on one held out, and writes a ranges file centred on the
  fit (the command delay, the servos' time constant and the speed limit; the rest the defaults) that
  `--physics FILE` takes.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, fields, replace
from pathlib import Path

import numpy as np

from so101.bodies.physics import DEFAULT_RANGES, NOMINAL, RANGE_REASONS, PhysicsError, PhysicsRanges, physics_ranges
from so101.bodies.servo_fit import FitError, JointFit, fit_joint, model_errors
from so101.dataset.features import ACTION_KEY, STATE_KEY
from so101.dataset.layout import DatasetError
from so101.dataset.units import UNITS, UNITS_HELP
from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS

# The fitted speed limit and time constant, spread by this either way in the ranges written; the delay by a frame.
SPEED_SPREAD = 0.15
TIME_CONSTANT_SPREAD = 0.25


def episode_list(text: str) -> list[int]:
    """--episodes: whole numbers >= 0, comma-separated ("0,1,2")."""
    words = [word.strip() for word in text.split(",")]
    if not words or not all(word.isdigit() for word in words):
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of episodes: whole numbers, comma-separated (0,1,2)")
    return sorted({int(word) for word in words})


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("--ranges", metavar="FILE", default=None,
                        help="print this ranges file's ranges instead of the defaults")
    parser.add_argument("--fit", action="store_true",
                        help="fit the servos to a recording (--from DATASET) and write the ranges centred on the fit")
    parser.add_argument("--from", dest="dataset", type=Path, metavar="DATASET", default=None,
                        help="--fit: the LeRobot dataset (a real arm's recording) whose states and actions are fitted")
    parser.add_argument("--episodes", type=episode_list, default=None, metavar="0,1,...",
                        help="--fit: the episodes fitted (default: all but the last, which is held out to score the fit)")
    parser.add_argument("--units", choices=UNITS, default=None, help="--fit: " + UNITS_HELP)
    parser.add_argument("--calibration", type=Path, metavar="FILE", default=None,
                        help="--fit, --units normalized: the recording follower's LeRobot calibration JSON")
    parser.add_argument("-o", dest="output", type=Path, metavar="FILE", default=None,
                        help="--fit: the ranges file written (default: printed only); kept as it is unless the fit succeeds")


def fail(line: str) -> int:
    print(f"so101 physics: {line}", file=sys.stderr)
    return 2


def range_lines(ranges: PhysicsRanges) -> list[str]:
    """A line a range: its name, its span, fixed physics' value (NOMINAL's), and why."""
    lines = [f"  {'range':<21} {'varied':<14} {'fixed':<8} why"]
    for spec in fields(PhysicsRanges):
        value = getattr(ranges, spec.name)
        shown = ("not set" if value is None else f"±{value:g}" if spec.name == "calibration_deg"
                 else f"{value[0]:g}-{value[1]:g}")
        fixed = 0.0 if spec.name == "calibration_deg" else getattr(NOMINAL, spec.name)
        lines.append(f"  {spec.name:<21} {shown:<14} {'not set' if fixed is None else f'{fixed:.4g}':<8} "
                     f"{RANGE_REASONS[spec.name]}")
    return lines


def fitted_ranges(fits: list[JointFit]) -> tuple[PhysicsRanges, str]:
    """The default ranges with the command delay, the servos' time constant and the speed limit centred on the
    body joints' fits; and a line saying what was fitted."""
    body = [fit for fit in fits if fit.joint in {joint.name for joint in ACTUATED_JOINTS[:NUM_ARM_JOINTS]}]
    fps = body[0].fps
    delay = int(np.median([fit.delay_frames for fit in body]))
    # No shorter than a frame: a joint that closes its gap within one says only that it is at least that quick.
    time_constant_s = max(1 / fps, float(np.median([fit.time_constant_s for fit in body])))
    time_constants_s = (round(time_constant_s * (1 - TIME_CONSTANT_SPREAD), 4),
                        round(time_constant_s * (1 + TIME_CONSTANT_SPREAD), 4))
    ranges = replace(DEFAULT_RANGES, command_delay_s=(round(max(0, delay - 1) / fps, 4), round((delay + 1) / fps, 4)),
                     servo_time_constant_s=time_constants_s)
    limited = [fit.speed_deg_s for fit in body if np.isfinite(fit.speed_deg_s)]
    said = f"command_delay_s {ranges.command_delay_s[0]:g}-{ranges.command_delay_s[1]:g} (the body's median delay, " \
           f"{delay} frames, ± one), servo_time_constant_s {time_constants_s[0]:g}-{time_constants_s[1]:g} " \
           f"(their median, ±{TIME_CONSTANT_SPREAD:.0%})"
    if limited:
        speed = float(np.median(limited))
        ranges = replace(ranges, speed_limit_deg_s=(round(speed * (1 - SPEED_SPREAD), 1),
                                                    round(speed * (1 + SPEED_SPREAD), 1)))
        said += f", speed_limit_deg_s {ranges.speed_limit_deg_s[0]:g}-{ranges.speed_limit_deg_s[1]:g} " \
                f"(the median limit of {len(limited)} joints, ±{SPEED_SPREAD:.0%})"
    else:
        said += ", speed_limit_deg_s the default (no joint reached a limit)"
    return ranges.check("the fitted ranges"), said


def fit(args: argparse.Namespace) -> int:
    from so101.dataset.reader import Dataset

    if args.dataset is None:
        return fail("--fit needs --from DATASET: a recording whose states and actions are fitted")
    try:
        dataset = Dataset.open(args.dataset.expanduser())
        missing = [key for key in (ACTION_KEY, STATE_KEY) if key not in dataset.features]
        if missing:
            return fail(f"{dataset.root} has no {' or '.join(missing)}: a fit follows the states after the actions")
        indices = [episode.index for episode in dataset.episodes]
        if not indices:
            return fail(f"{dataset.root} has no episodes yet")
        fitted = args.episodes if args.episodes is not None else (indices[:-1] or indices)
        unknown = [index for index in fitted if index not in indices]
        if unknown:
            return fail(f"{dataset.root} has no episode {unknown[0]}: it has {indices[0]}-{indices[-1]}")
        held_out = next((index for index in reversed(indices) if index not in fitted), None)
        units = dataset.joint_units(args.units, args.calibration and args.calibration.expanduser(), fitted[0])
        joints = {index: dataset.episode_joints_deg(index, units) for index in [*fitted, *([held_out] if held_out is not None else [])]}
    except DatasetError as error:
        return fail(str(error))
    frames = sum(len(joints[index][ACTION_KEY]) for index in fitted)
    print(f"fit: episodes {', '.join(map(str, fitted))} of {dataset.root} ({frames} frames at {dataset.fps} fps); "
          f"{units.how}", flush=True)
    fits, skipped = [], []
    for number, joint in enumerate(ACTUATED_JOINTS):
        episodes = [(joints[index][ACTION_KEY][:, number], joints[index][STATE_KEY][:, number]) for index in fitted]
        try:
            fits.append(fit_joint(joint.name, episodes, dataset.fps))
        except FitError as error:
            skipped.append(str(error))
    if not any(fit.joint != ACTUATED_JOINTS[-1].name for fit in fits):
        return fail(f"no arm joint could be fitted: {skipped[0]}")
    print(f"  {'joint':<14} {'delay':>16} {'time constant':>14} {'speed limit':>12} {'offset':>8}   "
          "p50, mean before -> after (deg)")
    for each in fits:
        delay = f"{each.delay_frames} frames, {each.delay_s * 1000:.0f} ms"
        speed = "none reached" if not np.isfinite(each.speed_deg_s) else f"{each.speed_deg_s:.0f} deg/s"
        print(f"  {each.joint:<14} {delay:>16} {each.time_constant_s * 1000:>11.0f} ms {speed:>12} {each.offset_deg:>+8.2f}   "
              f"{each.error_before_deg:.2f}, {each.mean_before_deg:.2f} -> {each.error_after_deg:.2f}, {each.mean_after_deg:.2f}")
    for line in skipped:
        print(f"  not fitted: {line}")
    # Means: a recording of steps that mostly rests has p50s near 0 whatever the model.
    before, after = np.median([f.mean_before_deg for f in fits]), np.median([f.mean_after_deg for f in fits])
    if not after < before:
        return fail(f"the fit does not converge: its model follows the recording no better than the commands do "
                    f"(a mean {after:.2f} deg against {before:.2f} deg); nothing written")
    if held_out is not None:
        column = {joint.name: number for number, joint in enumerate(ACTUATED_JOINTS)}
        scored = [model_errors(each, joints[held_out][ACTION_KEY][:, column[each.joint]],
                               joints[held_out][STATE_KEY][:, column[each.joint]]) for each in fits]
        p50s, means = [np.median([s[k] for s in scored]) for k in (0, 1)], [np.median([s[k] for s in scored]) for k in (2, 3)]
        print(f"held out, episode {held_out}: p50 {p50s[0]:.2f} deg before -> {p50s[1]:.2f} deg after, "
              f"mean {means[0]:.2f} -> {means[1]:.2f} deg (the joints' medians)")
    ranges, said = fitted_ranges(fits)
    text = json.dumps(asdict(ranges), indent=1) + "\n"
    if args.output is None:
        print(f"the ranges, fitted: {said}")
        print(text, end="")
        return 0
    output = args.output.expanduser()
    partial = output.with_name(output.name + ".partial")
    partial.write_text(text, encoding="utf-8")
    partial.replace(output)
    print(f"wrote {output}: {said}; the rest the defaults. Use it: --physics {output}")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.fit:
        if args.ranges is not None:
            return fail("--ranges shows a ranges file; --fit writes one (-o FILE): give one of them")
        return fit(args)
    given = [option for option, value in (("--from", args.dataset), ("--episodes", args.episodes), ("--units", args.units),
                                          ("--calibration", args.calibration), ("-o", args.output)) if value is not None]
    if given:
        return fail(f"{given[0]} goes with --fit")
    try:
        ranges = DEFAULT_RANGES if args.ranges is None else physics_ranges(str(args.ranges))
    except PhysicsError as error:
        return fail(str(error))
    if ranges is None:
        return fail("--ranges takes a ranges file (NAME.json): fixed physics draws nothing")
    print(f"the ranges {'--physics varied draws from' if args.ranges is None else f'of {args.ranges}'}, "
          "each episode's drawn from its seed, and fixed physics' point (MuJoCo's keeps no speed limit; "
          "docs/loop/physics.md):")
    print("\n".join(range_lines(ranges)))
    return 0
