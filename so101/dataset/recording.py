"""What the recorder node does, without dora: sample frames at the dataset's rate, answer the
prompt's commands, and save episodes in the background.

The node (nodes/recorder.py) hands `Recording` the body's latest `joint_state`, `gripper_state`
and `joint_target` (and, with a task, `object_state` and `task_status`), the camera's latest
`image`, the prompt's `record_cmd` messages and the time at each of its ticks; `Recording` says what to reply. Each frame samples the latest state
and target at the frame's tick; its timestamp is frame_index / fps (LeRobot's rule), so a
recorder that fell behind adds the frames it owes, and the episode keeps the wall clock's length.
The node gives each tick and picture the time it was sent (dora's stamp): a recorder that stalls
(it yields the CPU to the body) and then reads its queue adds each frame with the picture sent
before that frame was due, not the picture newest when it caught up (which left the frames of the
stall with one picture, then skipped those that came during it). Saving runs in a thread: the recorder goes on answering and
sampling while an episode is written.

Real cameras stamp each picture with the time it was captured, and the body's states come stamped
with the time they were sent: a frame then takes the state nearest the front picture's capture, as
LeRobot's recorder reads the arm and the cameras at one moment. A real camera that sends nothing for
CAMERA_SILENT_S (so101.cameras.sources) stops the episode, saved up to then or discarded, as the user chose.
"""

from __future__ import annotations

import threading
import time
from bisect import bisect_left
from collections import deque
from typing import Any, Callable, Mapping, Protocol, Sequence

import numpy as np
import numpy.typing as npt

from so101.bodies.camera_file import DEFAULT_SIZE
from so101.bodies.scenario import Scenario
from so101.cameras.sources import silent_camera
from so101.dataset.features import (
    ACTION_KEY, ENVIRONMENT_KEY, IMAGE_KEY, REWARD_KEY, STATE_KEY, SUCCESS_KEY, WRIST_IMAGE_KEY, to_lerobot,
)
from so101.dataset.messages import COMMANDS, RecordCommand
from so101.observe import ALL_OBSERVED, Observed
from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS
from so101.tasks.cube_to_box import CubeToBox

# A recorder that stalled longer than this many frames (a suspended laptop) starts counting
# afresh rather than fill the gap with copies of one sample.
MAX_FRAMES_OWED = 30
# The states kept to pair a picture with: about 1 s of the real arm's 50 a second, 1.2 s of a simulation's 250.
STATE_HISTORY = 300
# A picture sent at the very instant a frame is due belongs to that frame: the frames before it come first.
FRAME_EPSILON_S = 1e-6
CAMERA_LOST_CHOICES = ("save", "discard")  # what becomes of the episode a camera stopped

TEXT = {
    "zh": {
        "started": "● 录制第 {episode} 段:任务 '{task}'(停止: stop,放弃: discard)",
        "already": "正在录制第 {episode} 段:先 stop 或 discard",
        "not_recording": "没有正在录制的片段(开始: record 任务描述)",
        "no_state": "还没有收到 joint_state,无法开始录制",
        "no_task": "record 需要任务描述,例如: record 把方块放进盒子",
        "saving": "■ 第 {episode} 段:{frames} 帧({seconds:.1f} 秒),保存中…",
        "empty": "第 {episode} 段没有帧,未保存",
        "saved": "✓ 第 {episode} 段已保存:{frames} 帧,{seconds:.1f} 秒(用时 {save_s:.1f} 秒)→ {root}",
        "save_failed": "✗ 第 {episode} 段未保存: {error}",
        "discarded": "第 {episode} 段已放弃({frames} 帧)",
        "episodes_none": "{root}:还没有片段",
        "episodes_head": "{root}:{count} 段,{fps} 帧/秒",
        "episode_line": "  {index:>3}: {frames:>5} 帧 {seconds:>6.1f} 秒  {tasks}",
        "pending": "  (保存中: {pending})",
        "unknown": "录制器不认识这条指令: {command!r}(可用: {accepted})",
        "stopping_save": "数据流停止:保存未结束的第 {episode} 段",
        "waiting_picture": "(等待第一张画面,之后开始计帧)",
        "camera_lost": "✗ {camera} 相机 {seconds:.1f} 秒没有画面:{result}",
        "camera_silent": "{camera} 相机 {seconds:.1f} 秒没有画面:未开始录制(相机插好了吗?)",
    },
    "en": {
        "started": "● recording episode {episode}: task '{task}' (stop: stop, drop: discard)",
        "already": "episode {episode} is recording: stop or discard it first",
        "not_recording": "no episode is recording (start one: record TASK TEXT)",
        "no_state": "no joint_state has come yet: cannot record",
        "no_task": "record needs a task text, e.g.: record put the cube in the box",
        "saving": "■ episode {episode}: {frames} frames ({seconds:.1f} s), saving...",
        "empty": "episode {episode} has no frames: not saved",
        "saved": "✓ episode {episode} saved: {frames} frames, {seconds:.1f} s (took {save_s:.1f} s) -> {root}",
        "save_failed": "✗ episode {episode} not saved: {error}",
        "discarded": "episode {episode} discarded ({frames} frames)",
        "episodes_none": "{root}: no episodes yet",
        "episodes_head": "{root}: {count} episodes, {fps} fps",
        "episode_line": "  {index:>3}: {frames:>5} frames {seconds:>6.1f} s  {tasks}",
        "pending": "  (saving: {pending})",
        "unknown": "the recorder does not know {command!r} (accepted: {accepted})",
        "stopping_save": "the dataflow stops: saving the unfinished episode {episode}",
        "waiting_picture": "(waiting for the first picture; frames count from then)",
        "camera_lost": "✗ the {camera} camera sent no picture for {seconds:.1f} s: {result}",
        "camera_silent": "the {camera} camera has sent no picture for {seconds:.1f} s: not recording (is it plugged in?)",
    },
}


class Episode(Protocol):
    """An episode being written (so101.dataset.episode.EpisodeRecorder)."""

    frames: int
    seed: int | None  # the task's layout, and its scenario as drawn, kept by episode in info.json
    scenario: dict[str, object] | None

    def add_frame(self, frame: Mapping[str, Any]) -> None: ...  # feature key -> value

    def save(self) -> object: ...

    def discard(self) -> None: ...


class Writer(Protocol):
    """A dataset open for appending (so101.dataset.writer.DatasetWriter)."""

    episodes: list  # of EpisodeSummary: index, length, tasks, duration_s

    def start_episode(self, task: str) -> Episode: ...


def nearest_in_time(history: Sequence[tuple[float, Any]], when_s: float) -> tuple[float, Any] | None:
    """The (time, value) of `history` (in time order) nearest `when_s`; None for an empty history."""
    if not history:
        return None
    index = bisect_left([stamp for stamp, _ in history], when_s)
    candidates = [history[at] for at in (index - 1, index) if 0 <= at < len(history)]
    return min(candidates, key=lambda each: abs(each[0] - when_s))


class FrameClock:
    """Frames due at the dataset's rate, counted from the episode's first frame (so rounding
    never adds up)."""

    def __init__(self, fps: float, start_s: float):
        self.period_s = 1.0 / fps
        self._origin_s = start_s
        self.frames = 0

    def due(self, now_s: float) -> int:
        """How many frames to add now (each with the latest sample); 0 until the next one is due."""
        owed = int((now_s - self._origin_s) / self.period_s) + 1 - self.frames
        if owed > MAX_FRAMES_OWED:  # a stall: one frame now, and count from here
            self._origin_s, owed = now_s - self.frames * self.period_s, 1
        owed = max(owed, 0)
        self.frames += owed
        return owed


class Recording:
    """The recorder's state: the latest inputs, the episode in progress, the saves under way.

    `say(line)` reports what happens later (a save that ended); commands return their replies.
    `needs_image`: the dataset has video, so a frame waits for the first picture.
    `observed`: what the frames show (so101.observe), as far as the body has it.
    `task`: the body runs this task (so101.tasks), so a frame holds its objects' poses, its reward
    and whether it succeeded, and waits for the first object_state; with video, the wrist camera's
    picture too, and it waits for the first of those.
    `wrist`: a wrist camera without a task (the real arm's); `camera_lost`: the cameras are real, and
    one that stops ends the episode, `save`d up to then or `discard`ed ("" for a simulation's camera,
    which draws only when something moved). `log` hears how far apart each episode's pictures and
    states were taken, where the pictures say when.
    """

    def __init__(self, writer: Writer, root: str, fps: int, lang: str, needs_image: bool,
                 say: Callable[[str], None], clock: Callable[[], float] = time.monotonic, task: CubeToBox | None = None,
                 scenario: Scenario = Scenario(), observed: Observed = ALL_OBSERVED, wrist: bool = False,
                 image_size: tuple[int, int] | None = None, camera_lost: str = "",
                 log: Callable[[str], None] = lambda line: None):
        self.writer, self.root, self.fps = writer, root, fps
        self.text = TEXT[lang]
        self.needs_image = needs_image and observed.front
        self.say = say
        self.clock = clock
        self.arm_deg: tuple[float, ...] | None = None
        self.gripper_deg: float | None = None
        self.targets_deg: tuple[float, ...] | None = None
        self.image: npt.NDArray[np.uint8] | None = None
        self.task = task
        self.object_state: npt.NDArray[np.float32] | None = None
        self.wrist_image: npt.NDArray[np.uint8] | None = None
        self.needs_wrist_image = needs_image and (task is not None or wrist) and observed.wrist
        self.camera_lost, self.log = camera_lost, log
        self._arrived_s: dict[str, float] = {}  # camera -> when its newest picture came
        self.captured_s: float | None = None  # when the newest front picture was taken, where it says
        self._arm_history: deque[tuple[float, tuple[float, ...]]] = deque(maxlen=STATE_HISTORY)
        self._gripper_history: deque[tuple[float, float]] = deque(maxlen=STATE_HISTORY)
        self._pairing_s = 0.0  # the episode's widest gap between a picture and its state
        self.shows_environment = observed.environment
        self.success = False
        self.scenario = scenario  # the pictures' looks, cameras and the physics, drawn from the layout's seed
        self.image_size = image_size  # the pictures' size
        self.seed: int | None = None  # the layout's, from task_status
        self.episode: Episode | None = None
        self.episode_index = 0  # the index of the episode recording (or of the next one)
        self._frame_clock: FrameClock | None = None
        self._lock = threading.Lock()  # one save at a time, in episode order
        self._saves: list[threading.Thread] = []
        self._pending: dict[int, int] = {}  # episode index -> frames, while it saves
        self.last_task = ""

    # -- inputs --------------------------------------------------------------------------
    def on_joint_state(self, arm_deg: Sequence[float], sent_s: float | None = None) -> None:
        if len(arm_deg) == NUM_ARM_JOINTS:
            self.arm_deg = tuple(float(angle) for angle in arm_deg)
            if sent_s is not None:
                self._arm_history.append((sent_s, self.arm_deg))

    def on_gripper_state(self, gripper_deg: Sequence[float], sent_s: float | None = None) -> None:
        if len(gripper_deg) == 1:
            self.gripper_deg = float(gripper_deg[0])
            if sent_s is not None:
                self._gripper_history.append((sent_s, self.gripper_deg))

    def on_joint_target(self, targets_deg: Sequence[float]) -> None:
        if len(targets_deg) == len(ACTUATED_JOINTS):
            self.targets_deg = tuple(float(angle) for angle in targets_deg)

    def on_image(self, rgb: npt.NDArray[np.uint8], captured_s: float | None = None, sent_s: float | None = None) -> None:
        """The front camera's newest picture; `sent_s` (when it was sent, on the ticks' clock): the frames due
        before then are added first, with the picture before it."""
        self._frames_before(sent_s)
        self.image, self.captured_s = rgb, captured_s
        self._arrived_s["front"] = self.clock()

    def on_wrist_image(self, rgb: npt.NDArray[np.uint8], captured_s: float | None = None,
                       sent_s: float | None = None) -> None:
        self._frames_before(sent_s)
        self.wrist_image = rgb
        self._arrived_s["wrist"] = self.clock()

    def _frames_before(self, sent_s: float | None) -> None:
        if sent_s is not None and self.episode is not None and self._frame_clock is not None:
            self._add_due(sent_s - FRAME_EPSILON_S)

    def on_object_state(self, values: Sequence[float]) -> None:
        if self.task is not None and len(values) == len(self.task.object_state_names):
            self.object_state = np.array(values, dtype=np.float32)

    def on_task_status(self, success: bool, seed: int | None = None) -> None:
        self.success = bool(success)
        if seed is not None:
            self.seed = seed

    def state_deg(self) -> tuple[float, ...] | None:
        if self.arm_deg is None or self.gripper_deg is None:
            return None
        return self.arm_deg + (self.gripper_deg,)

    def state_at_picture(self) -> tuple[float, ...] | None:
        """The state of the moment the front picture was taken (the nearest one sent), where the picture and
        the states say when; else the latest."""
        arm = nearest_in_time(self._arm_history, self.captured_s) if self.captured_s is not None else None
        gripper = nearest_in_time(self._gripper_history, self.captured_s) if self.captured_s is not None else None
        if arm is None or gripper is None or self.captured_s is None:
            return self.state_deg()
        self._pairing_s = max(self._pairing_s, abs(arm[0] - self.captured_s))
        return arm[1] + (gripper[1],)

    def silent_camera(self) -> tuple[str, float] | None:
        """(camera, seconds) of a real camera whose newest picture is older than CAMERA_SILENT_S
        (so101.cameras.sources); None when all send."""
        if not self.camera_lost:
            return None
        needed = [name for name, needs in (("front", self.needs_image), ("wrist", self.needs_wrist_image)) if needs]
        return silent_camera(self._arrived_s, needed, self.clock())

    # -- the frame clock -----------------------------------------------------------------
    def tick(self, now_s: float | None = None) -> int:
        """Add the frames due at `now_s` (the tick's time; None: the clock's now); returns how many were added."""
        if self.episode is None:
            return 0
        silent = self.silent_camera() if self._frame_clock is not None else None
        if silent is not None:  # the camera stopped: the episode ends here, as the user chose
            def announce(result: str) -> None:
                self.say(self.text["camera_lost"].format(camera=silent[0], seconds=silent[1], result=result))
            if self.camera_lost == "save":
                self.stop(announce)
            else:
                announce(self.discard())
            return 0
        return self._add_due(self.clock() if now_s is None else now_s)

    def _add_due(self, now_s: float) -> int:
        """Add the frames due at `now_s`, each with the latest state, target and pictures."""
        assert self.episode is not None
        state = self.state_at_picture()
        if (state is None or (self.needs_image and self.image is None)
                or (self.needs_wrist_image and self.wrist_image is None)
                or (self.task is not None and self.object_state is None)):
            return 0
        if self._frame_clock is None:  # the first frame: everything it needs has come
            self._frame_clock = FrameClock(self.fps, now_s)
        due = self._frame_clock.due(now_s)
        if due:
            # `action` is what the body was told to reach; until the body has said, where it stands.
            frame: dict[str, Any] = {STATE_KEY: to_lerobot(state),
                                     ACTION_KEY: to_lerobot(self.targets_deg if self.targets_deg is not None else state)}
            if self.needs_image:
                frame[IMAGE_KEY] = self.image
            if self.needs_wrist_image:
                frame[WRIST_IMAGE_KEY] = self.wrist_image
            if self.task is not None and self.shows_environment:
                frame[ENVIRONMENT_KEY] = self.object_state
            if self.task is not None:
                frame[REWARD_KEY] = np.array([self.task.reward(self.success)], dtype=np.float32)
                frame[SUCCESS_KEY] = np.array([self.success])
            for _ in range(due):
                self.episode.add_frame(frame)
        return due

    # -- commands ------------------------------------------------------------------------
    def command(self, message: RecordCommand | str) -> list[str]:
        if isinstance(message, str):  # what came could not be decoded
            return [self.text["unknown"].format(command=message, accepted=", ".join(COMMANDS))]
        name = message.command
        if name == "toggle":
            name = "stop" if self.episode is not None else "record"
        if name == "record":
            return [self.start(message.task or self.last_task)]
        if name == "stop":
            return [self.stop()]
        if name == "discard":
            return [self.discard()]
        if name == "episodes":
            return self.episode_lines()
        return [self.text["unknown"].format(command=name, accepted=", ".join(COMMANDS))]

    def start(self, task: str) -> str:
        if self.episode is not None:
            return self.text["already"].format(episode=self.episode_index)
        if not task:
            return self.text["no_task"]
        if self.state_deg() is None:
            return self.text["no_state"]
        silent = self.silent_camera()
        if silent is not None:
            return self.text["camera_silent"].format(camera=silent[0], seconds=silent[1])
        # The writer numbers episodes as they are saved: after those saved and those saving (a
        # save that fails gives its number back).
        self.episode_index = len(self.writer.episodes) + len(self._pending)
        self.episode = self.writer.start_episode(task)
        if self.task is not None and self.seed is not None:  # the layout it starts from, its physics, how it looks
            self.episode.seed = self.seed
            names = tuple(name for name, shown in (("front", self.needs_image), ("wrist", self.needs_wrist_image))
                          if shown)
            self.episode.scenario = self.scenario.metadata(self.seed, names, self.image_size or DEFAULT_SIZE)
            if self.camera_lost:  # real cameras: where they stood is not the simulation's to say
                self.episode.scenario.pop("cameras", None)
        self._frame_clock, self._pairing_s = None, 0.0
        self.last_task = task
        line = self.text["started"].format(episode=self.episode_index, task=task)
        if (self.needs_image and self.image is None) or (self.needs_wrist_image and self.wrist_image is None):
            line += " " + self.text["waiting_picture"]
        return line

    def recording_now(self) -> tuple[int, str] | None:
        """(episode index, task) of the episode recording, or None: what `record_status` carries for the web view."""
        return (self.episode_index, self.last_task) if self.episode is not None else None

    def stop(self, announce: Callable[[str], None] | None = None) -> str:
        """End the episode in progress and save it in the background; `announce` hears the reply before the
        save starts (so that it comes before the save's own news)."""
        episode = self.episode
        if episode is None:
            return self.text["not_recording"]
        index, frames = self.episode_index, episode.frames
        self.episode, self._frame_clock = None, None
        if self.captured_s is not None and frames:
            self.log(f"episode {index}: each picture paired with the state sent nearest its capture, "
                     f"at most {self._pairing_s * 1000:.0f} ms apart")
        if frames == 0:
            episode.discard()
            reply = self.text["empty"].format(episode=index)
            if announce is not None:
                announce(reply)
            return reply
        self._pending[index] = frames
        reply = self.text["saving"].format(episode=index, frames=frames, seconds=frames / self.fps)
        if announce is not None:
            announce(reply)
        saving = threading.Thread(target=self._save, args=(episode, index, frames), name=f"save-{index}")
        self._saves.append(saving)
        saving.start()
        return reply

    def _save(self, episode: Episode, index: int, frames: int) -> None:
        started = time.monotonic()
        with self._lock:
            try:
                episode.save()
            except Exception as error:  # noqa: BLE001 - a failed save is reported; the recorder goes on
                reason = " ".join(str(error).split()) or type(error).__name__
                self.say(self.text["save_failed"].format(episode=index, error=reason))
            else:
                self.say(self.text["saved"].format(episode=index, frames=frames, seconds=frames / self.fps,
                                                   save_s=time.monotonic() - started, root=self.root))
            finally:
                self._pending.pop(index, None)

    def discard(self) -> str:
        episode = self.episode
        if episode is None:
            return self.text["not_recording"]
        frames = episode.frames
        self.episode, self._frame_clock = None, None
        episode.discard()
        return self.text["discarded"].format(episode=self.episode_index, frames=frames)

    def episode_lines(self) -> list[str]:
        episodes = list(self.writer.episodes)
        if not episodes:
            lines = [self.text["episodes_none"].format(root=self.root)]
        else:
            lines = [self.text["episodes_head"].format(root=self.root, count=len(episodes), fps=self.fps)]
            lines += [self.text["episode_line"].format(index=each.index, frames=each.length, seconds=each.duration_s,
                                                       tasks=" | ".join(each.tasks)) for each in episodes]
        if self._pending:
            lines.append(self.text["pending"].format(pending=", ".join(str(index) for index in sorted(self._pending))))
        return lines

    # -- the end -------------------------------------------------------------------------
    def close(self) -> None:
        """The dataflow stops: save the unfinished episode (it is whole up to now), and wait for every save."""
        if self.episode is not None:
            self.say(self.text["stopping_save"].format(episode=self.episode_index))
            self.say(self.stop())
        for saving in self._saves:
            saving.join()
