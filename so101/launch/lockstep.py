"""What `so101 eval` and `so101 demos` share: a lockstep dataflow of a body, a driver and the episodes'
runner (nodes/episodes.py), run with `dora run` while each episode's line is shown as it ends.

The graph: the body (its node file, SO101_LOCKSTEP_FPS set) publishes each frame; the driver
(nodes/expert.py, or nodes/policy.py under its own Python) answers it with the body's `joint_cmd`. The runner, beside that loop, hears
both (the driver's answer as `action`), records and judges each frame, and ends the episode by
laying out the next (`task_cmd`). Its writing and encoding are off the loop's path, and still
every episode ends at the same frame: the body holds still after an episode's last frame
(SO101_EPISODE_FRAMES, or success) until the reset comes, so the next episode starts from the
same history however late the runner is (a body that ran on past the end did not: a PyBullet
episode after another came out a frame longer on one run than on another). With `--idle` there
is no driver: the runner answers each frame with home.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Callable

from so101.bodies.looks import DEFAULT_LOOKS, LOOKS_CHOICES
from so101.bodies.physics import DEFAULT_PHYSICS, physics_mode
from so101.bodies.registry import BODIES, SIMULATED_BODIES, BodyKind
from so101.bodies.scenario import SCENARIO_ENV_VAR, Scenario
from so101.launch.camera_poses import add_backdrop_option, add_camera_pose_option
from so101.launch.on_cluster import ClusterPlace, joined_cluster
from so101.runtime.argtypes import add_language_option, number, parsed_by, whole_number
from so101.runtime.dataflow import (
    EXPERT_NODE_FILE, PERCEPTION_NODE_FILE, PERCEPTION_NODE_ID, ROOT, node_launch, write_dataflow,
)
from so101.runtime.dora_run import REFUSAL, Dataflow, port_held_problem, refusal
from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS
from so101.tasks import TASKS
from so101.tasks.episodes import DEFAULT_TIME_LIMIT_S, EpisodeClock, Outcome, read_outcomes, seeds_for, split_seeds

if TYPE_CHECKING:
    from so101.policy.choice import ChosenPolicy

EPISODES_NODE_FILE = ROOT / "nodes" / "episodes.py"
BODY_FRAME_OUTPUTS = ["joint_state", "gripper_state", "object_state", "task_status"]
MAX_WORKERS = 16
WORKERS_MACHINE = "local"  # the daemon's machine id when --workers runs several dataflows here
# A run whose dataflow said nothing for this long (no episode ended, dora did not exit) is stuck.
STALL_S = 300.0
INTERRUPTED = "stopped (Ctrl-C, or a signal): the episode running was dropped"


def add_physics_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--physics", type=parsed_by(physics_mode), default=DEFAULT_PHYSICS, metavar="fixed|varied|FILE.json",
                        help="the task's physics: fixed (default, each simulator's own), varied (each episode's seed "
                             "draws the cube's size, mass and friction, the servos' stiffness, damping, delay and speed "
                             "limit, a calibration up to 2° off and the gripper's force; a dataset keeps them by "
                             "episode) or a JSON file of ranges to vary within (docs/loop/physics.md)")


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", choices=sorted(TASKS), required=True, help="the task (cube_to_box)")
    parser.add_argument("--episodes", type=whole_number(1, 100_000), default=10, metavar="N",
                        help="how many episodes (default 10)")
    parser.add_argument("--seed", type=whole_number(0, 2**31), default=0, metavar="S",
                        help="episode i is laid out from seed S + i (default 0)")
    parser.add_argument("--body", choices=[*SIMULATED_BODIES, "real"], default="pybullet",
                        help="the simulator (default pybullet); the real arm is refused: it has no object state")
    parser.add_argument("--time-limit", type=number(lambda value: 0 < value <= 3600, "a number of seconds above 0, at most 3600"),
                        default=DEFAULT_TIME_LIMIT_S, metavar="SECONDS",
                        help=f"simulated seconds an episode may take before it fails (default {DEFAULT_TIME_LIMIT_S:g})")
    parser.add_argument("--noise", type=number(lambda value: 0 <= value <= 10, "a scale from 0 to 10"), default=0.0,
                        metavar="SCALE", help="the expert's perturbations, as a multiple of its standard ones (default 0)")
    parser.add_argument("--misses", type=number(lambda value: 0 <= value <= 1, "a share from 0 to 1"), default=0.0,
                        metavar="SHARE", help="the share of episodes whose first grasp the expert puts 30-45 mm beside "
                             "the cube on purpose, so that they show its recovery (default 0)")
    parser.add_argument("--looks", choices=LOOKS_CHOICES, default=DEFAULT_LOOKS,
                        help="the cameras' pictures: fixed (default, one look), varied (each episode's seed draws "
                             "its light, floor and object colours and camera placement; a dataset keeps them by episode) "
                             "or unseen (looks held out of varied's palettes and spreads, to score eyes on looks they "
                             "never saw)")
    add_camera_pose_option(parser)
    add_backdrop_option(parser)
    add_physics_option(parser)
    parser.add_argument("--workers", type=whole_number(1, MAX_WORKERS), default=1, metavar="K",
                        help="dataflows run at once, each on its share of the seeds; the results are merged in seed "
                             "order (default 1)")
    parser.add_argument("--coordinator", default=None, metavar="ADDR[:PORT]",
                        help="run on the dora cluster of this coordinator (its token in DORA_AUTH_TOKEN, as for "
                             "`dora start`): each worker's body and driver on its machines in turn")
    parser.add_argument("--machine", default=None, metavar="ID",
                        help="with --coordinator: the machine id of this machine's daemon, where the episodes' runners "
                             "run and keep what they write")
    parser.add_argument("--root", type=PurePath, default=None, metavar="FOLDER",
                        help="with --coordinator: the project's folder on the cluster's other machines (default: this "
                             "checkout's, the same path everywhere)")
    add_language_option(parser, "the nodes' logs")
    parser.add_argument("--log", type=Path, default=None, metavar="FILE",
                        help="dora's log (default: run.log in the run's work folder under out/; with --workers, the "
                             "nodes' logs are in that folder's dora/)")


@dataclass(frozen=True)
class Driver:
    """The node that answers each frame with the body's joint_cmd: its id, its file, what it reads
    of the body's frame, its settings, and an interpreter of its own (the policy environment's) or
    None for this project's."""

    node_id: str
    node_file: Path
    inputs: tuple[str, ...]
    env: dict[str, str]
    python: str | None = None
    # The perception node's settings where eyes fill the driver's object_state (a seeing recipe), else None.
    perception_env: dict[str, str] | None = None
    # With perception_env: the eyes' object_state goes to the driver and the runner as `seen_state`, beside the
    # simulator's (DAgger behind the eyes: the learner reads what they found, the expert the truth), not in its place.
    eyes_beside: bool = False


def expert_driver(args: argparse.Namespace, learner: "ChosenPolicy | None" = None) -> Driver:
    """The expert as the driver; with `learner` (DAgger: `so101 demos --learner`), under the policy environment's
    Python, the learner driving each episode until the expert takes over (SO101_EXPERT_LEARNER); a seeing recipe's
    learner behind its eyes, the perception node beside the expert."""
    env = {"SO101_TASK": args.task, "SO101_EXPERT_NOISE": repr(args.noise), "SO101_EXPERT_MISSES": repr(args.misses)}
    if learner is None:
        return Driver("expert", EXPERT_NODE_FILE, ("joint_state", "gripper_state", "object_state"), env)
    env.update({"SO101_EXPERT_LEARNER": str(learner.folder), "SO101_EXPERT_TAKEOVER_S": repr(args.takeover_s),
                "SO101_EXPERT_LEARNER_SEES": "1" if learner.recipe else "0", "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "1"})
    return Driver("expert", EXPERT_NODE_FILE, ("joint_state", "gripper_state", "object_state"), env,
                  python=str(learner.python), perception_env=learner.perception_env(args.lang) if learner.recipe else None,
                  eyes_beside=learner.recipe is not None)


@dataclass(frozen=True)
class Flow:
    """One lockstep run: its body, its driver (None: idle, the runner holds home), the runner's settings."""

    body: BodyKind
    driver: Driver | None
    runner_env: dict[str, str]
    lang: str
    pictures: tuple[str, ...] = ()  # the body's picture outputs: "image", "wrist_image"
    picture_size: str = ""  # WIDTHxHEIGHT
    body_env: dict[str, str] = field(default_factory=dict)  # more of the body's settings (so101 bench: its tick log)


@dataclass(frozen=True)
class Placement:
    """Where one lockstep run's nodes go on a cluster: the machine ids of the body's daemon, the
    runner's (this machine's: it writes the results here) and the driver's."""

    body: str
    runner: str
    driver: str


def queued(source: str) -> dict:
    return {"source": source, "queue_size": 100, "queue_policy": "backpressure"}


def flows_for(args: argparse.Namespace, work: Path, driver: Driver | None, pictures: tuple[str, ...],
              picture_size: tuple[int, int] | None, runner_env: Callable[[Path], dict[str, str]]) -> list[Flow]:
    """The runs add_common_arguments' options ask for, one per worker, each on its run of the seeds
    (in order): `pictures` (the body's picture outputs) at `picture_size` (None: none), each
    runner's results in its folder (`work`, or work/worker-K with several), and its own settings
    `runner_env(folder)`."""
    size = f"{picture_size[0]}x{picture_size[1]}" if picture_size else ""
    seed_runs = split_seeds(seeds_for(args.seed, args.episodes), args.workers)
    flows = []
    for worker, seeds in enumerate(seed_runs):
        folder = work if len(seed_runs) == 1 else work / f"worker-{worker}"
        folder.mkdir(parents=True, exist_ok=True)
        env = {"SO101_TASK": args.task, "SO101_SEED": str(seeds[0]), "SO101_EPISODES": str(len(seeds)),
               "SO101_TIME_LIMIT_S": repr(args.time_limit), "SO101_EPISODES_OUT": str(folder / "episodes.jsonl"),
               "SO101_LOCKSTEP_PICTURES": size, **runner_env(folder)}
        env.update(scenario_of(args, pictured=bool(size)).env())  # the body has it, the runner keeps it
        flows.append(Flow(BODIES[args.body], driver=driver, runner_env=env, lang=args.lang,
                          pictures=pictures if size else (), picture_size=size))
    return flows


def scenario_of(args: argparse.Namespace, pictured: bool = True) -> Scenario:
    """The scenario --looks, --camera-pose, --physics and --backdrop ask for; the looks, the cameras and the
    backdrops only where there are pictures (`pictured`) to draw them in."""
    return Scenario(looks=args.looks if pictured else DEFAULT_LOOKS,
                    camera_poses=dict(getattr(args, "camera_poses", {})) if pictured else {}, physics=args.physics,
                    backdrops=dict(getattr(args, "backdrops", {})) if pictured else {})


def unpictured_problem(args: argparse.Namespace, pictured: bool, how: str) -> str | None:
    """One line where --looks, --camera-pose or --backdrop is given to a run that draws no pictures (`how`
    says what would draw them); None otherwise."""
    given = [option for option, value in (("--looks", args.looks != DEFAULT_LOOKS), ("--camera-pose", args.camera_poses),
                                          ("--backdrop", getattr(args, "backdrops", {}))) if value]
    if given and not pictured:
        return f"{given[0]} shapes a task's pictures, and this run draws none: it goes with {how}"
    return None


def backdrop_lines(args: argparse.Namespace, size: tuple[int, int] | None) -> list[str]:
    """What each --backdrop is, said once: its photos, and how they fit the pictures."""
    from so101.bodies.backdrop import POOLS, backdrop_photos, read_photo
    from so101.bodies.backdrop_pool import with_unseen_pool

    lines = []
    looks = getattr(args, "looks", DEFAULT_LOOKS) if size else DEFAULT_LOOKS  # looks only where pictures are drawn
    for name, path in sorted(with_unseen_pool(looks, getattr(args, "backdrops", {})).items()):
        photos = backdrop_photos(path)
        if path in POOLS:
            which = f"the {path} backdrops ({len(photos)} pictures in {photos[0].parent}), one a seed"
        elif len(photos) == 1:
            height, width = read_photo(photos[0].resolve()).shape[:2]
            which = f"{path}, {width}x{height}"
        else:
            which = f"{len(photos)} photos in {path}, one a seed"
        fit = f"scaled to cover the {size[0]}x{size[1]} pictures and cropped about the centre" if size else ""
        lines.append(f"the {name} camera's backdrop: {which}; {fit}")
    return lines


def lockstep_dataflow(flow: Flow, placement: Placement | None = None, root: PurePath = ROOT) -> dict:
    """The dataflow's descriptor: the body, the driver and the runner, every node's path absolute
    under `root` (the project's folder on the machines that run them); with a `placement`, each on
    its daemon, and the nodes on the runner's (this machine's) under this checkout's folder."""
    body_id, driver = flow.body.node_id, flow.driver
    machine_of = ({body_id: placement.body, "episodes": placement.runner,
                   **({driver.node_id: placement.driver, PERCEPTION_NODE_ID: placement.driver} if driver else {})}
                  if placement else {})

    def under(node_id: str) -> PurePath:
        return ROOT if placement is not None and machine_of[node_id] == placement.runner else root

    fps = DEFAULT_LOCKSTEP_FPS
    last_frame = EpisodeClock(fps, float(flow.runner_env["SO101_TIME_LIMIT_S"])).limit_frames
    frame_outputs = [*BODY_FRAME_OUTPUTS, *flow.pictures]
    runner_inputs = {output: queued(f"{body_id}/{output}") for output in frame_outputs}
    nodes = [{
        "id": body_id, **node_launch(flow.body.node_file, under(body_id)), "restart_policy": "never",
        # The driver answers the body itself; the runner, beside the loop, only ends episodes (task_cmd).
        "inputs": {"joint_cmd": queued(f"{driver.node_id}/joint_cmd" if driver else "episodes/joint_cmd"),
                   "task_cmd": queued("episodes/task_cmd")},
        "outputs": frame_outputs,
        "env": {"SO101_MODE": "direct", "SO101_LANG": flow.lang, "SO101_TASK": flow.runner_env["SO101_TASK"],
                "SO101_SEED": flow.runner_env["SO101_SEED"], "SO101_LOCKSTEP_FPS": str(fps),
                "SO101_EPISODE_FRAMES": str(last_frame), "SO101_LOCKSTEP_PICTURES": flow.picture_size,
                **{key: value for key, value in flow.runner_env.items() if key == SCENARIO_ENV_VAR},
                **flow.body_env},
    }]
    if driver is not None:
        runner_inputs["action"] = queued(f"{driver.node_id}/joint_cmd")
        driver_inputs = {name: queued(f"{body_id}/{name}") for name in driver.inputs if name in frame_outputs}
        if driver.perception_env is not None:  # the eyes, beside the driver: its object_state is theirs
            seen = queued(f"{PERCEPTION_NODE_ID}/object_state")
            driver_inputs["seen_state" if driver.eyes_beside else "object_state"] = seen
            if driver.eyes_beside:
                runner_inputs["seen_state"] = seen
            nodes.append({
                "id": PERCEPTION_NODE_ID, "restart_policy": "never",
                **node_launch(PERCEPTION_NODE_FILE, under(driver.node_id), driver.python),
                "inputs": {name: queued(f"{body_id}/{name}") for name in ("image", "joint_state")},
                "outputs": ["object_state"],
                # the scenario's camera poses: the eyes see from where the pictures were drawn
                "env": {"SO101_LANG": flow.lang, **driver.perception_env,
                        **{key: value for key, value in flow.runner_env.items() if key == SCENARIO_ENV_VAR}},
            })
        nodes.append({
            "id": driver.node_id, "restart_policy": "never",
            **node_launch(driver.node_file, under(driver.node_id), driver.python),
            "inputs": driver_inputs, "outputs": ["joint_cmd"],
            "env": {"SO101_LANG": flow.lang, "SO101_LOCKSTEP_FPS": str(fps), **driver.env},
        })
    nodes.append({
        "id": "episodes", **node_launch(EPISODES_NODE_FILE, under("episodes")), "restart_policy": "never",
        "inputs": runner_inputs, "outputs": ["task_cmd"] if driver else ["joint_cmd", "task_cmd"],
        "env": {"SO101_LANG": flow.lang, "SO101_LOCKSTEP_FPS": str(fps),
                **({} if driver else {"SO101_IDLE": "1"}), **flow.runner_env},
    })
    if placement is not None:
        nodes = [{"deploy": {"machine": machine_of[str(node["id"])]}, **node} for node in nodes]
    return {"nodes": nodes}


def log_place(args: argparse.Namespace, work: Path) -> Path:
    """Where dora's logs go: --log's file, or run.log in the work folder; with workers or a cluster,
    the nodes' logs under the work folder's dora/ (on a cluster, the other machines' stay there)."""
    if args.workers > 1 or args.coordinator:
        return work / "dora"
    return args.log or work / "run.log"


def refuse_real(command: str, body: str) -> str | None:
    if body == "real":
        return (f"so101 {command}: the real arm has no object state (where the cube is, whether it is in the box): "
                f"{command} runs on {' or '.join(SIMULATED_BODIES)}")
    return None


def work_folder(command: str) -> Path:
    folder = ROOT / "out" / f"{command}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


class _OneRun:
    """One dataflow under `dora run` (its own coordinator and daemon, dynamic-node port included)."""

    poll_s = 1.0  # how often problem() is asked

    def __init__(self, dataflow_file: Path, log_file: Path, env: dict[str, str]):
        self.log_file = log_file
        self.dataflow = Dataflow(dataflow_file, log_file, env, ())

    def problem(self) -> str | None:
        """None while it runs; once dora exited, why."""
        code = self.dataflow.process.poll()
        if code is None:
            return None
        return refusal(self.log_file) or f"the dataflow ended (exit code {code}) before its episodes did: see {self.log_file}"

    def wait(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while self.dataflow.process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)

    def stop(self) -> None:
        self.dataflow.stop()


class _Workers:
    """Dataflows started with `dora start` on one coordinator: on this machine, a coordinator and a
    daemon of the run's own, on free ports (so they need no port of the prompt's); on a cluster
    (`place`), its daemons, each worker's body and driver on the next machine in turn; with a policy
    machine, every body on this machine's daemon and every policy on that one."""

    def __init__(self, command: str, flows: list[Flow], work: Path, place: ClusterPlace | None):
        from so101.runtime.cluster import Cluster, ClusterError

        self.names = [f"{command}-{os.getpid()}-{index}" for index in range(len(flows))]
        self.uuids: dict[str, str] = {}
        self.node_ids = [[flow.body.node_id, *([flow.driver.node_id] if flow.driver else []),
                          *([PERCEPTION_NODE_ID] if flow.driver and flow.driver.perception_env is not None else []),
                          "episodes"] for flow in flows]
        self.logs = work / "dora" / f"daemon-{WORKERS_MACHINE}"
        # dora 1.1's coordinator lets a client that is not on loopback connect about 20 times, then answers
        # 429 Too Many Requests for a while (seen: a minute): a coordinator elsewhere is asked every 5 s.
        self.poll_s = 1.0 if place is None or place.coordinator_addr.startswith("127.") else 5.0
        root: PurePath = ROOT
        if place is None:
            self.cluster = Cluster(work / "dora", auth=False)
            machines, here = [WORKERS_MACHINE], WORKERS_MACHINE
        else:
            self.cluster, machines = joined_cluster(place, work / "dora")
            here, root = place.here, place.root
        if place is not None and place.policy_machine is not None:
            self.placements = [Placement(here, here, place.policy_machine)] * len(flows)
        else:
            self.placements = [Placement(machines[index % len(machines)], here, machines[index % len(machines)])
                               for index in range(len(flows))]
        try:
            if place is None:
                self.cluster.start_coordinator()
                self.cluster.start_daemon(WORKERS_MACHINE)
            for name, flow, placement in zip(self.names, flows, self.placements):
                folder = Path(flow.runner_env["SO101_EPISODES_OUT"]).parent
                try:
                    self.cluster.start_dataflow(
                        write_dataflow(lockstep_dataflow(flow, placement, root), folder / "dataflow.yml"), name)
                except ClusterError as error:
                    driver = flow.driver
                    if driver is None or placement.driver == here or f"node {driver.node_id}" not in str(error):
                        raise
                    # Its daemon could not start it: the paths it was given are this machine's guesses at that one's.
                    raise ClusterError(f"{error} (on machine {placement.driver!r}: is {driver.python or 'python'} "
                                       f"there, and the project at {root}?)") from None
        except BaseException:
            self.stop()  # the dataflows started before, and a coordinator and daemon of this run's own
            raise

    def _states(self) -> dict[str, str]:
        """This run's dataflows that the coordinator lists, by name: their status."""
        listed = self.cluster.cli("list", "--format", "json", timeout_s=20)
        states = {}
        for line in listed.stdout.splitlines():
            try:
                entry = json.loads(line)
            except ValueError:
                continue
            if entry.get("name") in self.names:
                states[entry["name"]] = str(entry.get("status", "")).lower()
                self.uuids[entry["name"]] = str(entry.get("uuid", ""))
        return states

    def _told_by_coordinator(self, name: str) -> str | None:
        """A node's refusal in dataflow `name`, from its log as the coordinator streams it (a node on
        another machine keeps its log there)."""
        for node_id in self.node_ids[self.names.index(name)]:
            try:
                told = self.cluster.cli("logs", self.uuids.get(name) or name, "--node", node_id, timeout_s=20)
            except subprocess.TimeoutExpired:
                continue
            said = REFUSAL.search(told.stdout)
            if said:
                return said.group(1)
        return None

    def problem(self) -> str | None:
        """None while every dataflow runs or finished; else the first refusal or failure."""
        failed = [name for name, state in self._states().items() if state.startswith("fail")]
        if not failed:
            return None
        for node_log in sorted(self.logs.glob("_work/*/out/*/log_*.jsonl")):
            said = refusal(node_log)
            if said:
                return said
        if not self.logs.is_dir():
            said = self._told_by_coordinator(failed[0])
            if said:
                return said
        where = self.logs if self.logs.is_dir() else f"`dora logs {failed[0]} NODE` on the cluster"
        return f"dataflow {failed[0]} failed: see the node logs ({where})"

    def wait(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and any(state == "running" for state in self._states().values()):
            time.sleep(0.2 if self.poll_s <= 1.0 else self.poll_s)

    def stop(self) -> None:
        running = self._states()
        for name in self.names:
            if running.get(name) == "running":
                try:
                    self.cluster.cli("stop", "--name", name, timeout_s=15)
                except subprocess.TimeoutExpired:
                    pass
        self.cluster.stop()


def run_flows(command: str, flows: list[Flow], work: Path, log: Path | None,
              show: Callable[[Outcome, int], None], place: ClusterPlace | None = None) -> tuple[list[Outcome], str | None]:
    """Run `flows` (one or more workers, each on its run of the seeds) to their end, here or on the
    cluster at `place`; show each outcome, with its worker's number, in seed order as soon as the
    ones before it are in. (outcomes, None), or what went wrong in one line."""
    from so101.launch.beside_prompt import TEXT as TELEOP_TEXT
    from so101.runtime.cluster import ClusterError
    from so101.runtime.venv import dora_executable, env_with_bin_first
    from so101.runtime.versions import dora_version_problem

    version_problem = dora_version_problem(dora_executable())
    if version_problem:
        return [], version_problem
    results = [Path(flow.runner_env["SO101_EPISODES_OUT"]) for flow in flows]
    for path in results:
        path.unlink(missing_ok=True)
    runs: _OneRun | _Workers
    if len(flows) == 1 and place is None:
        port_problem = port_held_problem(TELEOP_TEXT[flows[0].lang]["port_held"])
        if port_problem:
            return [], port_problem
        log_file = (log or work / "run.log").expanduser().resolve()
        runs = _OneRun(write_dataflow(lockstep_dataflow(flows[0]), results[0].parent / "dataflow.yml"), log_file,
                       env_with_bin_first(dict(os.environ, SO101_LANG=flows[0].lang)))
    else:
        try:
            runs = _Workers(command, flows, work, place)
        except ClusterError as error:
            return [], str(error)
        if place is not None:
            for index, (flow, placement) in enumerate(zip(flows, runs.placements)):
                first = int(flow.runner_env["SO101_SEED"])
                last = first + int(flow.runner_env["SO101_EPISODES"]) - 1
                driver = flow.driver.node_id if flow.driver else ""
                elsewhere = f", its {driver} on machine {placement.driver!r}" if placement.driver != placement.body else ""
                print(f"{command}: worker {index} (seeds {first}..{last}) on machine {placement.body!r}{elsewhere}",
                      flush=True)
    first_seed = next_seed = min(int(flow.runner_env["SO101_SEED"]) for flow in flows)
    waiting: dict[int, tuple[Outcome, int]] = {}
    outcomes: list[Outcome] = []
    seen = [0] * len(flows)
    finished = [False] * len(flows)

    def collect() -> bool:
        """Read the workers' results; show what is next in seed order. True once every worker is done."""
        nonlocal next_seed
        for worker, path in enumerate(results):
            try:
                worker_outcomes, finished[worker] = read_outcomes(path.read_text(encoding="utf-8").splitlines())
            except (OSError, ValueError, TypeError):
                continue  # not there yet, or a line half written
            for outcome in worker_outcomes[seen[worker]:]:
                waiting[outcome.seed] = (replace(outcome, index=outcome.seed - first_seed), worker)
            seen[worker] = len(worker_outcomes)
        while next_seed in waiting:
            outcome, worker = waiting.pop(next_seed)
            show(outcome, worker)
            outcomes.append(outcome)
            next_seed += 1
        return all(finished)

    problem = None
    shown = 0
    last_news = last_check = time.monotonic()
    # dora runs in sessions of its own: a closed terminal or a `kill` must stop it here, as Ctrl-C does.
    signal.signal(signal.SIGHUP, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        while not collect():
            if len(outcomes) != shown:
                shown, last_news = len(outcomes), time.monotonic()
            if time.monotonic() - last_check >= runs.poll_s:
                last_check = time.monotonic()
                problem = runs.problem()
                if problem:
                    problem = None if collect() else problem  # it may have finished as it was asked
                    break
            if time.monotonic() - last_news > STALL_S:
                problem = f"no episode ended for {STALL_S:g} s: see {log or work}"
                break
            time.sleep(0.1)
        if problem is None:
            runs.wait(20)
    except KeyboardInterrupt:
        problem = INTERRUPTED
    finally:
        # A second Ctrl-C must not cut the clean-up short and leave dora running.
        handlers = {signum: signal.signal(signum, signal.SIG_IGN) for signum in (signal.SIGINT, signal.SIGHUP, signal.SIGTERM)}
        try:
            runs.stop()
        finally:
            for signum, handler in handlers.items():
                signal.signal(signum, handler)
    return outcomes, problem


def fail(line: str) -> int:
    print(line, file=sys.stderr)
    return 1
