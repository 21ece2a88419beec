"""`so101 teleop`: the dataflow and the keyboard prompt in one terminal.

Starts `dora run` in the background with its log in a file, waits until the
simulation has loaded the arm, runs the prompt (`nodes/keyboard_control.py`) in
the foreground, and stops the dataflow when the prompt exits (quit, Ctrl-D,
Ctrl-C), leaving no process behind (so101.launch.beside_prompt, which so101 replay shares).

dora gives a node the `env:` of dataflow.yml over the environment it was started
with, so `--mode` and `--lang` cannot reach the simulation as inherited variables:
teleop runs a copy of dataflow.yml (in a temporary folder, removed at exit) with
those two values set and the node paths made absolute. The file itself stays as the course has it.

`--leader PORT --leader-calibration FILE` puts the leader node between the prompt and the body
(dataflow_leader.yml's graph, on whichever body `--body` chose): the leader arm drives, and typed
motion commands take over until the leader moves again.

`--task NAME [--seed N]` puts a task's scene (so101.tasks) on a simulated body's floor: the body
publishes `object_state` and `task_status`, and the prompt's `reset [SEED]` and `task` talk to it.

`--record DIR` adds the recorder node (and, for a simulation, the camera node that draws its
pictures) to that copy: the prompt's `record`, `stop`, `discard` and `episodes` then keep
episodes in DIR as a LeRobot dataset.

`--body real --camera front=SOURCE --camera wrist=SOURCE` gives the real arm eyes: one real camera node
per camera (so101.launch.real_cameras), recorded as observation.images.front and .wrist and seen by a
policy that sees.

`--coordinator ADDR[:PORT] --machine HERE` runs the dataflow on a dora cluster someone runs (`dora start`),
every node on this machine's daemon HERE, the prompt joined through it; `--policy-machine NAME` runs the
policy node on daemon NAME instead, under its --policy-python there (docs/loop/policy-elsewhere.md).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path, PurePath

from so101.bodies.looks import DEFAULT_LOOKS, LOOKS_CHOICES
from so101.bodies.physics import DEFAULT_PHYSICS
from so101.bodies.scenario import Scenario
from so101.bodies.registry import BODIES, BodyKind
from so101.dataset.features import DEFAULT_FPS, video_keys_and_sizes
from so101.dataset.settings import DEFAULT_IMAGE_SIZE
from so101.launch.camera_poses import add_backdrop_option, add_camera_pose_option
from so101.launch.lockstep import add_physics_option
from so101.launch.beside_prompt import (
    TEXT, add_body_arguments, add_log_option, add_task_arguments, add_web_arguments, add_web_view, prepare, run_beside,
    task_problem,
)
from so101.policy.choice import ChosenPolicy
from so101.policy.settings import torch_device
from so101.observe import OBSERVE_ENV_VAR, OBSERVE_HELP, Observed, observed_for
from so101.cameras.sources import DEFAULT_CAMERA_FPS, DEFAULT_CAMERA_SIZE, parse_camera_option
from so101.dataset.recording import CAMERA_LOST_CHOICES
from so101.launch.on_cluster import add_policy_machine_argument, cluster_place
from so101.launch.real_cameras import add_real_cameras, checked_cameras, policy_picture_problem
from so101.runtime.argtypes import (
    add_camera_size_option, add_language_option, image_size, observed_list, parsed_by, whole_number,
)
from so101.runtime.dataflow import (
    CAMERA_NODE_ID, LEADER_READY_MARKS, LOADED_MARKS, PERCEPTION_NODE_ID, POLICY_READY_MARKS, PROMPT_NODE_FILE, ROOT,
    WEB_VIEW_MARKS, WEB_VIEW_NODE_ID, dataflow_copy, tell_nodes,
    with_camera, with_expert, with_leader, with_perception, with_policy, with_recorder, with_task,
)
from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS
from so101.tasks import task_named


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    add_body_arguments(parser)
    add_task_arguments(parser)
    add_language_option(parser, "the prompt and the logs")
    parser.add_argument(
        "--record", type=Path, metavar="DIR", default=None,
        help="keep episodes in DIR as a LeRobot dataset (v3.0): made if missing, appended to if it is one; "
        "at the prompt: record TASK TEXT, stop, discard, episodes (jog: E)",
    )
    parser.add_argument(
        "--fps", type=whole_number(1, 1000), default=DEFAULT_FPS, metavar="N",
        help=f"--record: frames per second (default {DEFAULT_FPS}, LeRobot's)",
    )
    parser.add_argument("--looks", choices=LOOKS_CHOICES, default=DEFAULT_LOOKS,
                        help="--task --record: the cameras' pictures, fixed (default), varied (each layout's seed draws "
                             "its light, floor and object colours and camera placement; the dataset keeps them) or "
                             "unseen (looks held out of varied's palettes and spreads)")
    add_physics_option(parser)
    parser.add_argument("--observe", type=observed_list, default=None, metavar="LIST", help=f"--record: {OBSERVE_HELP}")
    add_camera_pose_option(parser)
    add_backdrop_option(parser)
    add_camera_size_option(parser, None, "--record: each camera's pictures, stored as video; real cameras are asked "
                                         "for it; `so101 bench --cameras --camera-size WxH` says what a size costs",
                           default_text=f"{DEFAULT_IMAGE_SIZE} on a simulation, {DEFAULT_CAMERA_SIZE} for real cameras")
    parser.add_argument("--camera", type=parsed_by(parse_camera_option), action="append", metavar="NAME=SOURCE",
                        help="--body real: a real camera, NAME front or wrist, SOURCE a device index, /dev/videoN or a "
                             "video file (played at its own rate); once per camera; `so101 cameras` lists them")
    parser.add_argument("--camera-fps", type=whole_number(1, 240), default=DEFAULT_CAMERA_FPS, metavar="N",
                        help=f"--camera: frames per second asked of each camera (default {DEFAULT_CAMERA_FPS})")
    parser.add_argument("--camera-lost", choices=CAMERA_LOST_CHOICES, default="save",
                        help="--camera --record: a camera that stops ends the episode recording; save it up to then "
                             "(default) or discard it")
    parser.add_argument(
        "--leader", metavar="PORT", default=None,
        help="an SO-101 leader arm on PORT drives the body (with --leader-calibration; `so101 fake-arm` emulates one); "
        "typed motion commands take over until the leader moves again",
    )
    parser.add_argument(
        "--leader-calibration", type=Path, metavar="FILE", default=None,
        help="--leader: the leader's calibration JSON (from `so101 calibrate --leader`, or LeRobot's so101_leader one)",
    )
    parser.add_argument(
        "--policy", type=Path, metavar="DIR", default=None,
        help="a trained LeRobot policy (lerobot-train's .../checkpoints/last/pretrained_model) between the prompt "
        "and the body: at the prompt, policy on / policy off; a typed move takes over",
    )
    parser.add_argument("--policy-python", type=Path, metavar="PY", default=None,
                        help="--policy: the Python that runs it, with LeRobot (default: so101 policy-env's)")
    parser.add_argument("--policy-device", type=torch_device, metavar="DEVICE", default="cpu",
                        help="--policy: the torch device it runs on: cpu (default), cuda or mps")
    parser.add_argument("--coordinator", default=None, metavar="ADDR[:PORT]",
                        help="run on the dora cluster of this coordinator (its token in DORA_AUTH_TOKEN, as for "
                             "`dora start`), with --machine: every node on this machine's daemon")
    parser.add_argument("--machine", default=None, metavar="ID",
                        help="with --coordinator: the machine id of this machine's daemon, which the prompt joins "
                             "through (dora's default local port, or SO101_DAEMON_PORT)")
    parser.add_argument("--root", type=PurePath, default=None, metavar="FOLDER",
                        help="with --policy-machine: the project's folder on the policy's machine (default: this "
                             "checkout's)")
    add_policy_machine_argument(parser)
    add_web_arguments(parser)
    add_log_option(parser)


def run(args: argparse.Namespace) -> int:
    text = TEXT[args.lang]
    place = cluster_place(args, "the body and the prompt run")
    problem = task_problem(args, BODIES[args.body]) or (place if isinstance(place, str) else None)
    if args.policy_machine and args.policy is None:
        problem = f"--policy-machine {args.policy_machine} places the policy: it goes with --policy DIR"
    if problem or isinstance(place, str):
        print(f"so101 teleop: {problem}", file=sys.stderr)
        return 2
    launch = prepare(args, "teleop")
    if launch is None:
        return 2
    descriptor = dataflow_copy(launch.node_env, launch.body.dataflow_file)
    try:
        cameras = checked_cameras(args.camera, launch.body.simulated)
    except ValueError as error:
        print(f"so101 teleop: {error}", file=sys.stderr)
        return 2
    if args.image_size is None:
        args.image_size = image_size(DEFAULT_CAMERA_SIZE if cameras else DEFAULT_IMAGE_SIZE)
    args.cameras = cameras
    ready_marks: tuple[tuple[str, ...], ...] = (LOADED_MARKS,)
    if args.task is not None:
        with_task(descriptor, launch.body.node_id, args.task, args.seed or 0)
    if args.leader is not None or args.leader_calibration is not None:
        problem = add_leader(descriptor, launch.body, args.leader, args.leader_calibration, args.port, args.lang)
        if problem:
            print(f"so101 teleop: {problem}", file=sys.stderr)
            return 2
        ready_marks += (LEADER_READY_MARKS,)
    if args.task is not None:  # after the leader: a leader's move takes over from the expert, as a typed one does
        with_expert(descriptor, launch.body.node_id, {"SO101_TASK": args.task, "SO101_LANG": args.lang})
    if args.policy is not None:  # last before the body: any move before it takes over, the expert's too
        problem = add_policy(descriptor, launch.body, args)
        if problem:
            print(f"so101 teleop: {problem}", file=sys.stderr)
            return 2
        ready_marks += (POLICY_READY_MARKS,)
    elif args.policy_python is not None:
        print("so101 teleop: --policy-python goes with --policy DIR", file=sys.stderr)
        return 2
    if args.looks != DEFAULT_LOOKS and (args.task is None or not launch.body.simulated or (
            args.record is None and not any(node["id"] == CAMERA_NODE_ID for node in descriptor["nodes"]))):
        print(f"so101 teleop: --looks {args.looks} goes with --task NAME on a simulated body, and --record DIR or a "
              "--policy that sees: the task's cameras draw only for them", file=sys.stderr)
        return 2
    if args.physics != DEFAULT_PHYSICS and (args.task is None or not launch.body.simulated):
        print("so101 teleop: --physics varies a task's simulated physics: it goes with --task NAME on a simulated body",
              file=sys.stderr)
        return 2
    if args.observe is not None and args.record is None:
        print("so101 teleop: --observe says what a recording's frames show: it goes with --record DIR", file=sys.stderr)
        return 2
    if args.record is not None:
        names = tuple(cameras)
        observed = args.observe or observed_for(task=args.task is not None, video=launch.body.simulated, cameras=names)
        problem = observed.problem(task=args.task is not None, video=launch.body.simulated,
                                   why_no_video="the real arm has no camera of its own: give --camera NAME=SOURCE",
                                   cameras=names)
        problem = problem and f"--observe {observed}: {problem}"
        if not problem and cameras:
            add_real_cameras(descriptor, cameras, args.image_size, args.image_size, args.camera_fps)
        problem = problem or add_recorder(descriptor, launch.body, args.record.expanduser().resolve(), args.fps,
                                          args.lang, args.task, args.image_size, observed,
                                          names, args.camera_lost)
        if problem:
            print(f"so101 teleop: {problem}", file=sys.stderr)
            return 2
    add_real_cameras(descriptor, cameras, args.image_size, args.image_size, args.camera_fps)  # seen in the web view
    drawing = (CAMERA_NODE_ID, "recorder", PERCEPTION_NODE_ID)  # the nodes that draw, keep or read task pictures
    present = {node["id"] for node in descriptor["nodes"]}
    # A seeing policy's eyes take the camera's geometry on any body: on the real arm, where the real camera stands.
    if args.camera_poses and PERCEPTION_NODE_ID not in present and not (
            launch.body.simulated and args.task is not None and present & set(drawing)):
        print("so101 teleop: --camera-pose draws a task's simulated cameras, or tells a seeing policy's eyes where the "
              "camera stands: it goes with --task NAME on a simulated body and --record DIR, or a --policy that sees",
              file=sys.stderr)
        return 2
    if args.backdrops and not (launch.body.simulated and args.task is not None and CAMERA_NODE_ID in present):
        print("so101 teleop: --backdrop is drawn behind a task's simulated cameras: it goes with --task NAME on a "
              "simulated body, and --record DIR or a --policy that sees", file=sys.stderr)
        return 2
    # The body has its physics, the camera draws the pictures, the recorder keeps them, the eyes see from where they
    # stand, the page draws each layout as the pictures do.
    web_line = add_web_view(args, descriptor, launch.body, "teleop")
    scenario = Scenario(args.looks, dict(args.camera_poses), args.physics, dict(args.backdrops))
    tell_nodes(descriptor, (launch.body.node_id, *drawing, WEB_VIEW_NODE_ID), scenario.env())
    if web_line:
        ready_marks += (WEB_VIEW_MARKS,)
    if place is None:
        print(text["starting"].format(mode=launch.mode, log=launch.log), flush=True)
    else:
        policy = text["policy_there"].format(machine=place.policy_machine) if place.policy_machine else ""
        print(text["starting_cluster"].format(coordinator=f"{place.coordinator_addr}:{place.coordinator_port}",
                                              mode=launch.mode, here=place.here, policy=policy, log=launch.log), flush=True)
    return run_beside(launch, descriptor, PROMPT_NODE_FILE, text, ready_marks, web_line, place)


def add_policy(descriptor: dict, body: BodyKind, args: argparse.Namespace) -> str | None:
    """The policy node added to `descriptor`, before `body`; or, in one line, why it cannot be (a folder that
    is not a policy's, features this dataflow cannot give, no Python to run it)."""
    from so101.policy.choice import choose_policy

    names = task_named(args.task).object_state_names if args.task else ()
    try:
        chosen = choose_policy(args.policy, args.policy_python, args.task, names,
                               python_elsewhere=args.policy_machine is not None)
    except ValueError as error:
        return str(error)
    pictures, seen_size = chosen.body_pictures
    if seen_size is not None:  # the camera node draws what it (or its eyes) sees, at the rate it learned from
        width, height = seen_size
        if not body.simulated:  # the real cameras' pictures, scaled to the policy's where the camera's differ
            if not args.cameras:
                return ("the policy sees cameras, and the real arm has none here: give --camera front=SOURCE "
                        "--camera wrist=SOURCE (`so101 cameras` lists them), or run it on a simulation")
            problem = policy_picture_problem(pictures, args.cameras, tuple(args.image_size), seen_size,
                                             args.record is not None)
            if problem:
                return problem
            if tuple(args.image_size) != seen_size:
                print(f"so101 teleop: note: the cameras' {args.image_size[0]}x{args.image_size[1]} pictures are "
                      f"scaled to the policy's {width}x{height}", flush=True)
            add_real_cameras(descriptor, args.cameras, tuple(args.image_size), seen_size, args.camera_fps)
            finish_policy(descriptor, body, args, chosen, tuple(args.cameras))
            return None
        if not args.task:
            return "the policy sees the task's cameras (the wrist's is drawn for a task's scene): add --task cube_to_box"
        if args.record is not None and tuple(args.image_size) != seen_size:
            return (f"the policy sees {width}x{height} pictures, and one camera draws them for the recording too: "
                    f"record at --camera-size {width}x{height}")
        with_camera(descriptor, body.node_id, {"SO101_RECORD_IMAGE_SIZE": f"{width}x{height}"}, DEFAULT_LOCKSTEP_FPS)
    finish_policy(descriptor, body, args, chosen)
    return None


def finish_policy(descriptor: dict, body: BodyKind, args: argparse.Namespace, chosen: ChosenPolicy,
                  real_cameras: tuple[str, ...] = ()) -> None:
    """The policy node added, once its pictures (if it sees) have a camera; `real_cameras`: the real arm's,
    one that stops sending stops the policy's drive."""
    for line in chosen.notes(args.backdrops, args.camera_poses):
        print(f"so101 teleop: {line}", flush=True)
    print(f"so101 teleop: {chosen.reads()}", flush=True)
    if chosen.recipe is not None:  # the cameras its eyes see: the front one
        real_cameras = tuple(name for name in real_cameras if name == "front")
    env = {**chosen.env(args.task or "", args.policy_device), "SO101_LANG": args.lang,
           "SO101_POLICY_CAMERAS": ",".join(real_cameras)}
    if not args.task:
        del env["SO101_TASK"]
    root = args.root if args.policy_machine and args.root else ROOT  # the project's folder on the policy's machine
    with_policy(descriptor, body.node_id, chosen.inputs, env, str(chosen.python), root)
    if chosen.recipe is not None:
        with_perception(descriptor, body.node_id, chosen.perception_env(args.lang), str(chosen.python),
                        root, watched_by_policy=bool(real_cameras))


def add_leader(descriptor: dict, body: BodyKind, port: str | None, calibration_file: Path | None,
               follower_port: str | None, lang: str) -> str | None:
    """The leader node added to `descriptor`, driving `body`; or, in one line, why it cannot be
    (a missing option, the follower's own port, a calibration file that cannot be a leader's)."""
    from so101.feetech.calibration import CalibrationError, load_calibration

    if not port or calibration_file is None:
        return ("--leader PORT and --leader-calibration FILE go together (no leader? `so101 fake-arm` emulates one; "
                "`so101 calibrate --leader` makes the file)")
    if follower_port and os.path.realpath(port) == os.path.realpath(follower_port):
        return f"--leader {port} is the follower's --port too: the two arms are on two serial ports"
    calibration_path = calibration_file.expanduser().resolve()
    try:  # checked now, with the file's one-line error; the node checks it against the servos
        load_calibration(calibration_path, role="leader")
    except CalibrationError as error:
        return str(error)
    with_leader(descriptor, body.node_id, {"SO101_LEADER_PORT": port,
                                           "SO101_LEADER_CALIBRATION": str(calibration_path), "SO101_LANG": lang})
    return None


def add_recorder(descriptor: dict, body: BodyKind, dataset_dir: Path, fps: int, lang: str,
                 task: str | None, image_size: tuple[int, int], observed: Observed | None = None,
                 real_cameras: tuple[str, ...] = (), camera_lost: str = "save") -> str | None:
    """The recorder (and a simulation's camera) added to `descriptor`; or why DIR cannot take
    these episodes, in one line, before anything starts. `real_cameras`: the real arm's, whose nodes
    the dataflow has (so101.launch.real_cameras)."""
    from so101.dataset.layout import DatasetError
    from so101.dataset.writer import DatasetWriter

    observed = observed or observed_for(task=task is not None, video=body.simulated, cameras=real_cameras)
    pictures = image_size if observed.front or observed.wrist else None  # the real arm has only the cameras given
    has_wrist = task is not None or "wrist" in real_cameras
    try:  # checked now, and let go: the recorder node opens it again
        DatasetWriter.open(dataset_dir, fps, video_keys_and_sizes(pictures, has_wrist, observed),
                           environment_names=task_named(task).object_state_names if task else (),
                           environment_state=observed.environment).close()
    except DatasetError as error:
        return str(error)
    size_text = f"{pictures[0]}x{pictures[1]}" if pictures else ""
    recorder_env = {"SO101_RECORD_DIR": str(dataset_dir), "SO101_RECORD_FPS": str(fps),
                    "SO101_RECORD_IMAGE_SIZE": size_text, "SO101_LANG": lang, OBSERVE_ENV_VAR: str(observed)}
    if real_cameras and pictures:  # their own nodes, already in the dataflow
        recorder_env.update({"SO101_RECORD_CAMERAS": ",".join(real_cameras), "SO101_RECORD_CAMERA_LOST": camera_lost})
    camera_env = {"SO101_RECORD_IMAGE_SIZE": size_text} if pictures and body.simulated else None
    with_recorder(descriptor, body.node_id, recorder_env, camera_env, picture_hz=fps)
    return None
