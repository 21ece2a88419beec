"""Episode videos as LeRobot 0.4.x makes them: encode while recording, join by remuxing, decode a range.

LeRobot's encoder settings (lerobot/datasets/video_utils.py `_get_codec_options`, used by both its
PNG-then-encode path and its streaming encoder): libsvtav1, yuv420p, a keyframe every 2 frames
(g=2, so any frame decodes after at most one other), crf 30, SVT-AV1 preset 12. Episodes of a
dataset share one mp4 per file index; episode k's frames sit at its `from_timestamp` +
frame_index / fps, which `concatenate` makes true by shifting each input's packets by the
durations before it (no re-encoding, as LeRobot's own concatenation).
"""

from __future__ import annotations

import os
import queue
import threading
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, cast

import numpy as np
import numpy.typing as npt

# SVT-AV1 prints its configuration (info) and two warnings about preset 12 straight to stderr for
# every episode, in the middle of the prompt's output; level 1 keeps its errors. Read when an
# encoder starts; a value the user set wins.
os.environ.setdefault("SVT_LOG", "1")

import av  # noqa: E402  (after SVT_LOG, which the encoder reads)

VIDEO_CODEC = "libsvtav1"
PIXEL_FORMAT = "yuv420p"
GOP_SIZE = 2
CRF = 30
SVT_PRESET = 12
# One encoder thread (SVT-AV1's lp=1): the machine this runs on may have 2 cores, and the physics
# loop (another process) must keep its 4 ms steps; SVT-AV1 otherwise sizes its threads to every
# core. Measured at 320x240: ~300 frames/s encoded, ten times the recording rate; the recording
# process uses ~20% of one core at 30 fps (encoding, image statistics, copies).
ENCODER_THREADS = 1
# Frames waiting for the encoder thread (2 s at 30 fps; 14 MB at 320x240). When full, add() waits:
# a dropped frame would shift every later picture against its data row.
QUEUE_FRAMES = 60

Image = npt.NDArray[np.uint8]


def scheduling_policy() -> int | None:
    """The calling thread's scheduling policy (None off Linux): what the encoder's side effects are undone to."""
    try:
        return os.sched_getscheduler(0)
    except (AttributeError, OSError):
        return None


def _no_realtime_threads(policy: int | None) -> None:
    """Every thread of this process that runs under a real-time policy goes back under `policy`, the
    one its creator had before the encoder started: SVT-AV1 sets real-time policies when it can (as
    root), on its own threads and on the process's main thread, and a real-time thread pre-empts the
    physics loop on the same cores (measured: the simulation's per-tick work reached 18 ms at p99,
    and 15% of its ticks were missed, while an episode with video recorded; in the test process, a
    main thread left SCHED_FIFO starved every later test's emulated arm and window)."""
    if policy is None or policy in (os.SCHED_FIFO, os.SCHED_RR):
        return
    try:
        tasks = os.listdir("/proc/self/task")
    except OSError:
        return
    for task in tasks:
        try:
            if os.sched_getscheduler(int(task)) in (os.SCHED_FIFO, os.SCHED_RR):
                os.sched_setscheduler(int(task), policy, os.sched_param(0))
        except OSError:  # gone meanwhile, or not ours to change
            pass


def _codec_options(threads: int) -> dict[str, str]:
    # The keys LeRobot passes (g, crf, preset; `lp` through svtav1-params for its encoder_threads).
    return {"g": str(GOP_SIZE), "crf": str(CRF), "preset": str(SVT_PRESET), "svtav1-params": f"lp={threads}"}


@dataclass
class EncodedVideo:
    """A finished episode video: where it is, its frames, and what `inspect` said of each frame."""

    path: Path
    frames: int
    duration_s: float
    inspected: list[Any] = field(default_factory=list)


class VideoWriteError(Exception):
    """The encoder could not write the video (full disk, ...); str() is one line."""


class StreamingEncoder:
    """Encodes frames to an mp4 in a background thread, one at a time as they come.

    `inspect(frame)`, if given, runs in the encoder thread for every frame and its results come
    back in order with `finish()` (the dataset's image statistics use it, off the caller's thread).
    PyAV encodes without holding the GIL, so the caller's thread keeps running (measured at
    320x240: add() takes ~0.2 ms while a frame's encoding takes ~3 ms).
    """

    def __init__(self, path: Path, fps: int, width: int, height: int,
                 inspect: Callable[[Image], Any] | None = None, threads: int = ENCODER_THREADS):
        self.path = path
        self.fps = fps
        self.width, self.height = width, height
        self._policy = scheduling_policy()  # the creator's, before SVT-AV1 changes any
        self._inspect = inspect
        self._threads = threads
        self._queue: queue.Queue[Image | None] = queue.Queue(maxsize=QUEUE_FRAMES)
        self._inspected: list[Any] = []
        self._frames_written = 0
        self._error: BaseException | None = None
        self._cancelled = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"encode-{path.name}", daemon=True)
        self._thread.start()

    def add(self, image: Image) -> None:
        """Queue one (height, width, 3) uint8 frame; a copy is kept, the caller may reuse its array.

        After a failure frames are ignored: the error is reported by finish()."""
        if self._error is not None or self._cancelled.is_set():
            return
        self._queue.put(np.array(image, dtype=np.uint8, copy=True))

    def finish(self) -> EncodedVideo:
        """Wait for every queued frame, close the file and return it (VideoWriteError if it failed)."""
        self._queue.put(None)
        self._thread.join()
        if self._error is not None:
            raise VideoWriteError(one_line(self._error))
        try:
            length_s = duration_s(self.path)
        except (OSError, av.FFmpegError) as error:
            raise VideoWriteError(one_line(error)) from error
        return EncodedVideo(self.path, self._frames_written, length_s, self._inspected)

    def cancel(self) -> None:
        """Stop encoding and remove the file."""
        self._cancelled.set()
        try:
            self._queue.put_nowait(None)
        except queue.Full:
            pass  # the thread sees the cancel flag at its next frame
        self._thread.join()
        self.path.unlink(missing_ok=True)

    def _run(self) -> None:
        container = None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            container = av.open(str(self.path), "w")
            stream = cast(av.VideoStream, container.add_stream(VIDEO_CODEC, rate=self.fps,
                                                               options=_codec_options(self._threads)))
            stream.width, stream.height, stream.pix_fmt = self.width, self.height, PIXEL_FORMAT
            time_base = Fraction(1, self.fps)
            stream.time_base = time_base
            while True:
                image = self._queue.get()
                if image is None or self._cancelled.is_set():
                    break
                if self._inspect is not None:
                    self._inspected.append(self._inspect(image))
                frame = av.VideoFrame.from_ndarray(image, format="rgb24")
                # Explicit pts: frame i is at i / fps exactly, which the episode's timestamps say.
                frame.pts, frame.time_base = self._frames_written, time_base
                container.mux(stream.encode(frame))
                if self._frames_written == 0:  # the encoder's threads exist once it took its first frame
                    _no_realtime_threads(self._policy)
                self._frames_written += 1
            if not self._cancelled.is_set():
                container.mux(stream.encode(None))
            _no_realtime_threads(self._policy)
        except Exception as error:  # noqa: BLE001 - reported by finish(), never lost in the thread
            self._error = error
            while True:  # unblock a caller waiting on a full queue
                try:
                    self._queue.get_nowait()
                except queue.Empty:
                    break
        finally:
            if container is not None:
                try:
                    container.close()
                except Exception as error:  # noqa: BLE001 - closing writes the index: a full disk shows here
                    self._error = self._error or error


def one_line(error: BaseException) -> str:
    """An error as one line: an OSError's reason, else its text."""
    if isinstance(error, OSError) and error.strerror:
        return error.strerror
    return " ".join(str(error).split()) or type(error).__name__


def duration_s(path: Path) -> float:
    """The video's duration in seconds, as LeRobot's get_video_duration_in_s reads it."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        if stream.duration is not None and stream.time_base is not None:
            return float(stream.duration * stream.time_base)
        return float(container.duration / av.time_base) if container.duration else 0.0


def video_info(path: Path) -> dict[str, Any]:
    """The `info` LeRobot stores for a video feature in info.json (its get_video_info)."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        info: dict[str, Any] = {
            "video.height": stream.height,
            "video.width": stream.width,
            "video.codec": stream.codec_context.codec.canonical_name,
            "video.pix_fmt": stream.pix_fmt,
            "video.is_depth_map": False,
            "video.fps": int(stream.base_rate) if stream.base_rate else 0,
            "video.channels": 3,
        }
        audio = container.streams.audio
        if audio:
            # Never ours; LeRobot describes an audio track when a video it reads has one.
            info.update({"audio.channels": audio[0].channels, "audio.codec": audio[0].codec_context.codec.canonical_name,
                         "audio.bit_rate": audio[0].bit_rate, "audio.sample_rate": audio[0].sample_rate,
                         "audio.bit_depth": audio[0].format.bits, "audio.channel_layout": audio[0].layout.name,
                         "has_audio": True})
        else:
            info["has_audio"] = False
    return info


def concatenate(inputs: list[Path], output: Path) -> list[float]:
    """Join mp4 videos into `output` by copying their packets, each input shifted by the durations
    of those before it. Returns each input's start in the output, in seconds.

    The inputs must share codec, size and frame rate (every episode of a dataset does)."""
    if not inputs:
        raise ValueError("concatenate needs at least one video")
    starts_s: list[float] = []
    offset_s = Fraction(0)
    # faststart puts the index first, as LeRobot's concatenation does, so a reader starts quickly.
    with av.open(str(output), "w", format="mp4", options={"movflags": "faststart"}) as out:
        out_stream = None
        for path in inputs:
            with av.open(str(path)) as source:
                in_stream = source.streams.video[0]
                if out_stream is None:
                    out_stream = out.add_stream_from_template(in_stream, opaque=True)
                    out_stream.time_base = in_stream.time_base
                starts_s.append(float(offset_s))
                assert in_stream.time_base is not None
                shift = round(offset_s / in_stream.time_base)
                for packet in source.demux(in_stream):
                    if packet.dts is None:  # the demuxer's empty flush packet
                        continue
                    packet.dts += shift
                    if packet.pts is not None:
                        packet.pts += shift
                    packet.stream = out_stream
                    out.mux(packet)
                offset_s += Fraction(in_stream.duration or 0) * in_stream.time_base
    return starts_s


def decode(path: Path, from_s: float, to_s: float, fps: int) -> Iterator[Image]:
    """The frames shown from `from_s` (included) to `to_s` (excluded), as (height, width, 3) uint8."""
    half_frame_s = 0.5 / fps  # a frame belongs to the range its timestamp rounds into
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        stream.thread_type = "NONE"  # one thread: replay runs beside the physics loop too
        assert stream.time_base is not None
        # seek lands on the keyframe at or before from_s; frames before it are decoded and skipped.
        container.seek(max(0, round(from_s / stream.time_base)), stream=stream, backward=True, any_frame=False)
        for frame in container.decode(stream):
            if frame.time is None:
                continue
            if frame.time < from_s - half_frame_s:
                continue
            if frame.time >= to_s - half_frame_s:
                break
            yield cast(Image, frame.to_ndarray(format="rgb24"))


def picture_changes(pictures: Iterable[Image], threshold_levels: float) -> list[bool]:
    """For each of a video's decoded `pictures`, whether it differs from the one before by more than
    `threshold_levels` grey levels on average (the first: False): a camera that fell behind repeats its
    last picture, and a repeat decodes a little differently each time (lossy video), a new picture by more."""
    changes, before = [], None
    for picture in pictures:
        now = picture.astype(np.int16)
        changes.append(before is not None and float(np.abs(now - before).mean()) > threshold_levels)
        before = now
    return changes


def new_pictures(pictures: Iterable[Image], threshold_levels: float) -> int:
    """How many of a video's decoded `pictures` are new (`picture_changes`)."""
    return sum(picture_changes(pictures, threshold_levels))


def new_while_moving(changes: list[bool], states: np.ndarray, still_deg: float = 0.01) -> float:
    """The share of the frames in which the arm moved (a joint of `states`, one row a frame, changed by
    more than `still_deg` since the frame before) whose picture is new (`changes`); 0 where it never moved."""
    moved = np.any(np.abs(np.diff(states, axis=0)) > still_deg, axis=1)
    new = np.asarray(changes[1:len(moved) + 1], dtype=bool)
    return float(np.sum(new & moved[:len(new)]) / np.sum(moved)) if np.any(moved) else 0.0
