"""The dataflow description (dataflow.yml at the top of the project): its facts and its copies."""

from __future__ import annotations

import re
from pathlib import Path, PurePath

ROOT = Path(__file__).resolve().parents[2]
DATAFLOW_FILE = ROOT / "dataflow.yml"
# The keyboard prompt, a dynamic node: `so101 teleop` and `so101 cluster-demo` start it themselves.
PROMPT_NODE_FILE = ROOT / "nodes" / "keyboard_control.py"
PROMPT_NODE_ID = "keyboard_control"
# `so101 teleop --record` adds these two; `so101 replay` starts the replay node as the prompt is started.
RECORDER_NODE_FILE = ROOT / "nodes" / "recorder.py"
CAMERA_NODE_FILE = ROOT / "nodes" / "camera.py"
CAMERA_NODE_ID = "camera"
# `so101 teleop --body real --camera NAME=SOURCE` adds one of these per real camera, as camera_NAME.
REAL_CAMERA_NODE_FILE = ROOT / "nodes" / "real_camera.py"
# Each real camera's picture reaches the recorder and the policy on the input the simulated camera's
# picture of the same camera has.
PICTURE_OF_CAMERA = {"front": "image", "wrist": "wrist_image"}
# A real camera node sends its newest picture at each of these ticks (a picture waits at most this long).
REAL_CAMERA_TICK = "dora/timer/millis/5"
REPLAY_NODE_FILE = ROOT / "nodes" / "replay.py"
REPLAY_NODE_ID = "replay"
# `so101 teleop --leader` puts the leader node between the prompt and the body (dataflow_leader.yml).
LEADER_NODE_FILE = ROOT / "nodes" / "leader_node.py"
LEADER_NODE_ID = "leader"
LEADER_DATAFLOW_FILE = ROOT / "dataflow_leader.yml"
LEADER_TICK = "dora/timer/millis/10"
EXPERT_NODE_FILE = ROOT / "nodes" / "expert.py"
EXPERT_NODE_ID = "expert"
# The expert's pace at the prompt: a target every 40 ms, as in lockstep (25 frames a second).
EXPERT_TICK = "dora/timer/millis/40"
# `so101 teleop --policy` puts a trained policy between the prompt and the body, run by its own Python;
# `so101 eval --policy` drives the body with it in lockstep.
POLICY_NODE_FILE = ROOT / "nodes" / "policy.py"
# A seeing recipe's eyes (so101.perception): the front picture and the joints in, object_state out, for the policy.
PERCEPTION_NODE_FILE = ROOT / "nodes" / "perception.py"
PERCEPTION_NODE_ID = "perception"
POLICY_NODE_ID = "policy"
# The policy's pace at the prompt: an action every 40 ms, the rate of the datasets it learns from (25 fps).
POLICY_TICK = "dora/timer/millis/40"
# The policy node's line once LeRobot has loaded the policy (nodes/policy.py), in its two languages.
POLICY_READY_MARKS = ("policy loaded from", "策略已加载")
# `so101 teleop --web` adds the web view; its "serving" line, as nodes/web_view.py prints it.
WEB_VIEW_NODE_FILE = ROOT / "nodes" / "web_view.py"
WEB_VIEW_NODE_ID = "web_view"
WEB_VIEW_MARKS = ("web view: http://",)
# The recorder samples at its frame rate by its own clock, woken this often (the frame's jitter).
RECORDER_TICK = "dora/timer/millis/5"
# The period of dataflow.yml's `dora/timer/millis/4` tick, and so of the physics step
# (tests/test_dataflow_file.py holds the two equal). Tools that simulate without the
# dataflow (plot-step, snapshot, bench) step with it too.
TICK_PERIOD_S = 0.004
# The start of the simulation node's "loaded" log line, in its two languages (so101/bodies/node_loop.py):
# every body logs it once the arm is loaded, just before it starts publishing joint_state.
LOADED_MARKS = ("SO-101 loaded", "SO-101 加载完成")
# The leader node's line once its servos are checked and read (nodes/leader_node.py), in its two languages.
LEADER_READY_MARKS = ("SO-101 leader ready", "SO-101 主臂就绪")

_TIMER = re.compile(r"^dora/timer/(millis|secs)/(\d+(?:\.\d+)?)$")


def timer_period_s(node_config: dict, input_id: str = "tick") -> float | None:
    """The period of a `dora/timer/...` input in seconds, or None if that input is not a timer.

    `node_config` is what `Node.node_config()` returns: {"inputs": {id: source-or-mapping}, ...}.
    """
    spec = (node_config or {}).get("inputs", {}).get(input_id)
    source = spec.get("source") if isinstance(spec, dict) else spec
    match = _TIMER.match(source or "") if isinstance(source, str) else None
    if not match:
        return None
    unit, amount = match.groups()
    return float(amount) / (1000.0 if unit == "millis" else 1.0)


# A tick makes up for at most this many periods: a longer stall (a debugger, a suspended
# laptop) is let go rather than replayed as one sudden burst of motion.
MAX_STEPS_PER_TICK = 10


class TickClock:
    """Physics steps owed at each timer tick, so that simulated time follows the timer.

    dora keeps one waiting tick (queue_size 1) and drops older ones when the node is
    late, so on a busy machine a tick can come 8 ms after the last: it owes two steps.
    Counted from the first tick, not tick to tick, so rounding never adds up: simulated
    time stays within a step of the timer's. `stamp`s are the ticks' metadata timestamps
    (when the timer fired); without one (a tick that is not a dora timer, a test's mock)
    a tick is one step.
    """

    def __init__(self, period_s: float):
        self.period_s = period_s
        self._origin = None  # the stamp the count starts from
        self._steps = 0  # steps taken since then

    def steps_due(self, stamp) -> int:
        if stamp is None:
            return 1
        if self._origin is None:
            self._origin, self._steps = stamp, 1
            return 1
        owed = round((stamp - self._origin).total_seconds() / self.period_s) + 1 - self._steps
        steps = min(max(owed, 1), MAX_STEPS_PER_TICK)
        if owed > MAX_STEPS_PER_TICK:  # a stall: take what is allowed, count afresh from here
            self._origin, self._steps = stamp, 1
        else:
            self._steps += steps
        return steps


def dataflow_copy(node_env: dict[str, str], dataflow_file: Path = DATAFLOW_FILE, root: PurePath = ROOT) -> dict:
    """A dataflow file (dataflow.yml by default) as a dict to run from elsewhere: every node
    that runs a file gets its path made absolute (under `root`, the project's folder on the
    machine that runs it: this checkout by default) and `node_env` over its own `env:` (which
    dora ranks above the shell's)."""
    import yaml

    descriptor = yaml.safe_load(dataflow_file.read_text(encoding="utf-8"))
    for node in descriptor["nodes"]:
        if node.get("path", "dynamic") != "dynamic":
            node["path"] = str(root / node["path"])
            node["env"] = {**(node.get("env") or {}), **node_env}
    return descriptor


def tell_nodes(descriptor: dict, node_ids: tuple[str, ...], env: dict[str, str]) -> bool:
    """`env` over the own settings of each of the dataflow's nodes named in `node_ids`; False when it has none of them."""
    told = False
    for node in descriptor["nodes"]:
        if node["id"] in node_ids:
            node["env"] = {**(node.get("env") or {}), **env}
            told = True
    return told


def has_dynamic_node(dataflow_file: Path | None, node_id: str) -> bool:
    """Whether the dataflow in `dataflow_file` waits for `node_id` to join it (`path: dynamic`);
    False for a file that cannot be read as one."""
    import yaml

    if dataflow_file is None:
        return False
    try:
        nodes = yaml.safe_load(dataflow_file.read_text(encoding="utf-8"))["nodes"]
        return any(node.get("id") == node_id and node.get("path") == "dynamic" for node in nodes)
    except (OSError, UnicodeDecodeError, yaml.YAMLError, TypeError, KeyError, AttributeError):
        return False


def dataflow_text(descriptor: dict, source: str = DATAFLOW_FILE.name) -> str:
    import yaml

    return (f"# Written from {source}; edit that file, not this one.\n"
            + yaml.safe_dump(descriptor, sort_keys=False, allow_unicode=True))


def write_dataflow(descriptor: dict, path: Path) -> Path:
    path.write_text(dataflow_text(descriptor), encoding="utf-8")
    return path


def _node(descriptor: dict, node_id: str) -> dict:
    return next(node for node in descriptor["nodes"] if node["id"] == node_id)


# The recorder and the camera only use the newest state and tick, but each drop out of a full queue
# is a warning line in dora's log: their queues hold what comes while they encode a frame (a few ms)
# or draw a picture (up to a few hundred ms), so they read everything and nothing is dropped.
PICTURE_OUTPUTS = ("image", "wrist_image")  # the camera node's
STATE_QUEUE = 500  # 2 s of the body's 250 states a second
TICK_QUEUE = 100


def _queued(source: str, queue_size: int) -> dict:
    return {"source": source, "queue_size": queue_size}


def with_recorder(descriptor: dict, body_node_id: str, recorder_env: dict[str, str], camera_env: dict[str, str] | None,
                  picture_hz: float, root: PurePath = ROOT) -> dict:
    """A dataflow (dataflow_copy's dict) with the recorder added, and the camera node when
    `camera_env` is given: the body also publishes `joint_target`, the prompt sends `record_cmd`
    and hears `record_status`."""
    body = _node(descriptor, body_node_id)
    body["outputs"] = [*body["outputs"], "joint_target"]
    prompt = _node(descriptor, PROMPT_NODE_ID)
    prompt["outputs"] = [*prompt["outputs"], "record_cmd"]
    prompt["inputs"] = {**prompt["inputs"], "record_status": {"source": "recorder/record_status", "queue_size": 100}}
    recorder_inputs = {
        "tick": _queued(RECORDER_TICK, TICK_QUEUE),
        "joint_state": _queued(f"{body_node_id}/joint_state", STATE_QUEUE),
        "gripper_state": _queued(f"{body_node_id}/gripper_state", STATE_QUEUE),
        "joint_target": _queued(f"{body_node_id}/joint_target", TICK_QUEUE),
        # Every command must arrive: the default queue keeps 10.
        "record_cmd": {"source": f"{PROMPT_NODE_ID}/record_cmd", "queue_size": 100},
    }
    task = body_task(descriptor, body_node_id)
    if task:  # the frames hold its objects, reward and success
        recorder_inputs["object_state"] = _queued(f"{body_node_id}/object_state", STATE_QUEUE)
        recorder_inputs["task_status"] = {"source": f"{body_node_id}/task_status", "queue_size": 100}
        recorder_env = {**recorder_env, "SO101_TASK": task}
    if camera_env is not None:
        with_camera(descriptor, body_node_id, camera_env, picture_hz, root)
    if camera_env is not None or recorder_env.get("SO101_RECORD_CAMERAS"):  # a simulation's camera, or real ones
        recorder_inputs.update({name: _queued(source, TICK_QUEUE) for name, source in picture_sources(descriptor).items()})
    descriptor["nodes"].append({
        "id": "recorder", "path": str(root / RECORDER_NODE_FILE.relative_to(ROOT)), "restart_policy": "never",
        "inputs": recorder_inputs, "outputs": ["record_status"], "env": recorder_env,
    })
    return descriptor


def with_camera(descriptor: dict, body_node_id: str, camera_env: dict[str, str], picture_hz: float,
                root: PurePath = ROOT) -> dict:
    """A dataflow with the camera node, which draws the body's `image` (and with a task `wrist_image`)
    `picture_hz` times a second. One camera serves every node that reads pictures (the recorder, a
    policy that sees): where there is one, it is kept, at the higher of the two rates; its
    pictures' size is one (so101 teleop refuses two sizes before it gets here), its settings the
    union of the callers'."""
    period_ms = max(1, round(1000 / picture_hz))
    timer = f"dora/timer/millis/{period_ms}"
    if any(node["id"] == CAMERA_NODE_ID for node in descriptor["nodes"]):
        camera = _node(descriptor, CAMERA_NODE_ID)
        camera["env"] = {**camera["env"], **camera_env}
        if period_ms < 1000 * (timer_period_s(camera) or 0.0):
            _retarget(camera, "tick", timer)
        return descriptor
    camera_inputs = {
        "tick": _queued(timer, TICK_QUEUE),
        "joint_state": _queued(f"{body_node_id}/joint_state", STATE_QUEUE),
        "gripper_state": _queued(f"{body_node_id}/gripper_state", STATE_QUEUE),
    }
    camera_outputs = ["image"]
    task = body_task(descriptor, body_node_id)
    if task:  # its objects are in the pictures, and the wrist camera's too; the seed, for varied looks
        camera_inputs["object_state"] = _queued(f"{body_node_id}/object_state", STATE_QUEUE)
        camera_inputs["task_status"] = {"source": f"{body_node_id}/task_status", "queue_size": 10}
        camera_env = {**camera_env, "SO101_TASK": task}
        camera_outputs.append("wrist_image")
    descriptor["nodes"].append({
        "id": CAMERA_NODE_ID, "path": str(root / CAMERA_NODE_FILE.relative_to(ROOT)), "restart_policy": "never",
        "inputs": camera_inputs, "outputs": camera_outputs, "env": camera_env,
    })
    return descriptor


def real_camera_node_id(name: str) -> str:
    """The node of the real camera `name` (one node per camera)."""
    return f"camera_{name}"


def with_real_cameras(descriptor: dict, camera_envs: dict[str, dict[str, str]], root: PurePath = ROOT) -> dict:
    """A dataflow with a real camera node (nodes/real_camera.py) for each of `camera_envs`, name -> its settings:
    each publishes `image` on its own; the recorder, the policy and the web view take the front camera's as
    `image` and the wrist camera's as `wrist_image` (picture_sources)."""
    body_index = next(index for index, node in enumerate(descriptor["nodes"]) if node.get("path") != "dynamic")
    for offset, (name, env) in enumerate(camera_envs.items()):
        descriptor["nodes"].insert(body_index + offset, {
            "id": real_camera_node_id(name), "path": str(root / REAL_CAMERA_NODE_FILE.relative_to(ROOT)),
            "restart_policy": "never",  # it retries a camera that stopped itself; a crash is said, not hidden
            "inputs": {"tick": {"source": REAL_CAMERA_TICK, "queue_size": 1}}, "outputs": ["image"], "env": env,
        })
    return descriptor


def picture_sources(descriptor: dict) -> dict[str, str]:
    """Where the pictures come from, by the input that takes them (`image`, `wrist_image`): the simulated
    camera node's outputs, or the real camera nodes'; {} for a dataflow without pictures."""
    node_ids = {node["id"] for node in descriptor["nodes"]}
    if CAMERA_NODE_ID in node_ids:
        return {name: f"{CAMERA_NODE_ID}/{name}" for name in _node(descriptor, CAMERA_NODE_ID)["outputs"]}
    return {picture: f"{real_camera_node_id(name)}/image" for name, picture in PICTURE_OF_CAMERA.items()
            if real_camera_node_id(name) in node_ids}


def _retarget(node: dict, input_id: str, source: str) -> None:
    """Point `input_id` of `node` at `source`, keeping its queue settings."""
    spec = node["inputs"][input_id]
    node["inputs"][input_id] = {**spec, "source": source} if isinstance(spec, dict) else source


def node_launch(node_file: PurePath, root: PurePath = ROOT, python: str | None = None) -> dict[str, str]:
    """How dora starts a node file: its path under `root` (the project's folder where it runs); with
    `python`, that interpreter with the file as its argument (the policy environment's)."""
    where = str(root / node_file.relative_to(ROOT))
    return {"path": python, "args": where} if python else {"path": where}


def _before_body(descriptor: dict, body_node_id: str, node_id: str, node_file: PurePath, tick: str,
                 env: dict[str, str], root: PurePath, inputs: dict | None = None, python: str | None = None) -> dict:
    """`node_id` (`node_file`) added between the prompt and the body: the body takes its `joint_cmd`, it
    takes what the body took as `typed_cmd` (with `tick` and `inputs`), and the prompt hears its news on
    `{node_id}_status`. Placed before the body, as dataflow_leader.yml has the leader. With `python`, the
    node runs as that interpreter with the node file as its argument (the policy environment's)."""
    status = f"{node_id}_status"
    prompt = _node(descriptor, PROMPT_NODE_ID)
    prompt["inputs"] = {**prompt["inputs"], status: {"source": f"{node_id}/{status}", "queue_size": 100}}
    body = _node(descriptor, body_node_id)
    typed_input = body["inputs"]["joint_cmd"]
    _retarget(body, "joint_cmd", f"{node_id}/joint_cmd")
    node = {
        "id": node_id, **node_launch(node_file, root, python),
        "inputs": {"tick": {"source": tick, "queue_size": 1}, "typed_cmd": typed_input, **(inputs or {})},
        "outputs": ["joint_cmd", status], "env": env,
    }
    descriptor["nodes"].insert(descriptor["nodes"].index(body), node)
    return descriptor


def with_leader(descriptor: dict, body_node_id: str, leader_env: dict[str, str], root: PurePath = ROOT) -> dict:
    """A dataflow (dataflow_copy's dict) whose body takes `joint_cmd` from the leader node, which takes the
    prompt's `joint_cmd` as `typed_cmd` and tells the prompt its news on `leader_status`: dataflow_leader.yml's
    graph, on any body (tests/test_dataflow_file.py holds the two equal)."""
    return _before_body(descriptor, body_node_id, LEADER_NODE_ID, LEADER_NODE_FILE, LEADER_TICK, leader_env, root)


def with_task(descriptor: dict, body_node_id: str, task_name: str, seed: int) -> dict:
    """A dataflow (dataflow_copy's dict) whose body runs a task (so101.tasks) from `seed`: it publishes
    `object_state` and `task_status`, which the prompt hears, and takes `task_cmd` (`reset`) from the prompt."""
    body = _node(descriptor, body_node_id)
    body["env"] = {**(body.get("env") or {}), "SO101_TASK": task_name, "SO101_SEED": str(seed)}
    body["outputs"] = [*body["outputs"], "object_state", "task_status"]
    body["inputs"] = {**body["inputs"], "task_cmd": {"source": f"{PROMPT_NODE_ID}/task_cmd", "queue_size": 100}}
    prompt = _node(descriptor, PROMPT_NODE_ID)
    prompt["outputs"] = [*prompt["outputs"], "task_cmd"]
    prompt["inputs"] = {**prompt["inputs"],
                        "task_status": {"source": f"{body_node_id}/task_status", "queue_size": 100},
                        "object_state": _queued(f"{body_node_id}/object_state", STATE_QUEUE)}
    return descriptor


def with_expert(descriptor: dict, body_node_id: str, expert_env: dict[str, str], root: PurePath = ROOT) -> dict:
    """A dataflow (with_task's, and with_leader's if it has one) whose body takes `joint_cmd` from the
    task's expert, which passes on what came before it (the prompt's, the leader's) as `typed_cmd`
    and drives on its own when the prompt's `expert` asks (`expert_cmd`), telling it on `expert_status`."""
    prompt = _node(descriptor, PROMPT_NODE_ID)
    prompt["outputs"] = [*prompt["outputs"], "expert_cmd"]
    observed = {name: _queued(f"{body_node_id}/{name}", STATE_QUEUE)
                for name in ("joint_state", "gripper_state", "object_state")}
    return _before_body(descriptor, body_node_id, EXPERT_NODE_ID, EXPERT_NODE_FILE, EXPERT_TICK, expert_env, root,
                        {"expert_cmd": {"source": f"{PROMPT_NODE_ID}/expert_cmd", "queue_size": 10}, **observed})


def with_policy(descriptor: dict, body_node_id: str, observed: tuple[str, ...], policy_env: dict[str, str], python: str,
                root: PurePath = ROOT) -> dict:
    """A dataflow whose body takes `joint_cmd` from the policy node (under the policy environment's
    `python`), which passes on what came before it (the prompt's, the leader's, the expert's) as
    `typed_cmd`, reads the body's `observed` outputs, and drives when the prompt's `policy on` asks
    (`policy_cmd`), telling it on `policy_status`."""
    prompt = _node(descriptor, PROMPT_NODE_ID)
    prompt["outputs"] = [*prompt["outputs"], "policy_cmd"]
    # Its pictures from the camera node (with_camera): only the newest matters, so one is queued.
    pictures = picture_sources(descriptor)
    inputs = {name: {"source": pictures[name], "queue_size": 1} if name in PICTURE_OUTPUTS
              else _queued(f"{body_node_id}/{name}", STATE_QUEUE) for name in observed}
    return _before_body(descriptor, body_node_id, POLICY_NODE_ID, POLICY_NODE_FILE, POLICY_TICK, policy_env, root,
                        {"policy_cmd": {"source": f"{PROMPT_NODE_ID}/policy_cmd", "queue_size": 10}, **inputs}, python)


def with_perception(descriptor: dict, body_node_id: str, perception_env: dict[str, str], python: str,
                    root: PurePath = ROOT, watched_by_policy: bool = False) -> dict:
    """with_policy's dataflow with a seeing recipe's eyes (nodes/perception.py, under the policy environment's
    `python`) between the front camera and the policy: they take the newest front picture and the body's
    joints, and the policy's object_state is theirs, not the body's. They forget where they last saw the cube
    at each `policy on` (the prompt's `policy_cmd`) and each new layout (the body's `task_status`, with a task).
    `watched_by_policy` (a real camera): the policy takes the front picture too, to stop when it goes silent
    (SO101_POLICY_CAMERAS)."""
    pictures = picture_sources(descriptor)
    inputs: dict[str, object] = {"image": {"source": pictures["image"], "queue_size": 1},
                                 "joint_state": _queued(f"{body_node_id}/joint_state", STATE_QUEUE),
                                 "policy_cmd": {"source": f"{PROMPT_NODE_ID}/policy_cmd", "queue_size": 10}}
    if body_task(descriptor, body_node_id):
        inputs["task_status"] = {"source": f"{body_node_id}/task_status", "queue_size": 100}
    node = {"id": PERCEPTION_NODE_ID, **node_launch(PERCEPTION_NODE_FILE, root, python), "inputs": inputs,
            "outputs": ["object_state"], "env": perception_env}
    policy = _node(descriptor, POLICY_NODE_ID)
    _retarget(policy, "object_state", f"{PERCEPTION_NODE_ID}/object_state")
    if watched_by_policy:
        policy["inputs"]["image"] = {"source": pictures["image"], "queue_size": 1}
    descriptor["nodes"].insert(descriptor["nodes"].index(policy), node)
    return descriptor


def body_task(descriptor: dict, body_node_id: str) -> str:
    """The task the body runs (with_task's), or "" for none."""
    body = _node(descriptor, body_node_id)
    return (body.get("env") or {}).get("SO101_TASK", "") if "object_state" in body["outputs"] else ""


def with_web_view(descriptor: dict, body_node_id: str, web_env: dict[str, str], root: PurePath = ROOT) -> dict:
    """A dataflow (dataflow_copy's dict) with the web view added: it reads the body's state and, where the
    dataflow has them, the camera's pictures, the recorder's `record_status` and a task's `object_state`
    and `task_status` (the page then draws the task's objects, each layout in its look)."""
    inputs = {
        "joint_state": _queued(f"{body_node_id}/joint_state", STATE_QUEUE),
        "gripper_state": _queued(f"{body_node_id}/gripper_state", STATE_QUEUE),
    }
    node_ids = {node["id"] for node in descriptor["nodes"]}
    front = picture_sources(descriptor).get("image")
    if front:
        inputs["image"] = _queued(front, TICK_QUEUE)
    if "recorder" in node_ids:
        inputs["record_status"] = {"source": "recorder/record_status", "queue_size": 100}
    task = body_task(descriptor, body_node_id)
    if task:
        inputs["object_state"] = _queued(f"{body_node_id}/object_state", STATE_QUEUE)
        inputs["task_status"] = {"source": f"{body_node_id}/task_status", "queue_size": 10}
        web_env = {**web_env, "SO101_TASK": task}
    descriptor["nodes"].append({
        "id": WEB_VIEW_NODE_ID, "path": str(root / WEB_VIEW_NODE_FILE.relative_to(ROOT)), "restart_policy": "never",
        "inputs": inputs, "env": web_env,
    })
    return descriptor


def with_replay(descriptor: dict, body_node_id: str) -> dict:
    """A dataflow (dataflow_copy's dict) whose body takes `joint_cmd` from the replay node (dynamic,
    started by `so101 replay`) instead of the prompt."""
    prompt = _node(descriptor, PROMPT_NODE_ID)
    prompt["id"] = REPLAY_NODE_ID
    _retarget(_node(descriptor, body_node_id), "joint_cmd", f"{REPLAY_NODE_ID}/joint_cmd")
    return descriptor
