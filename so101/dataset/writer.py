"""The writer: adds episodes to a LeRobot v3.0 dataset (creating it), one saved episode at a time.

The files and how sessions fill them: layout.py. How a save stays whole through a crash:
commit.py. An episode being recorded: episode.py.
"""

from __future__ import annotations

import json
import os
import threading
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from so101.dataset import parquet_append
from so101.dataset import video as videos
from so101.dataset.commit import (WORK_DIR, CommitIncomplete, Plan, commit, fsync_path, is_ours,
                                  lock_for_writing, not_saved, one_line_os_error, place_durably, recover)
from so101.dataset.episode import EpisodeRecorder
from so101.dataset.features import ENVIRONMENT_KEY, REWARD_KEY, ROBOT_TYPE
from so101.dataset.layout import (CODEBASE_VERSION, DATA_PATH, DEFAULT_CHUNK_SIZE, DEFAULT_DATA_FILE_SIZE_IN_MB,
                                  DEFAULT_VIDEO_FILE_SIZE_IN_MB, EPISODES_DIR, EPISODES_PATH, INFO_PATH, SEEDS_KEY, SCENARIOS_KEY,
                                  STATS_PATH, TASKS_PATH, VIDEO_PATH, DatasetError, EpisodeSummary,
                                  data_schema, episode_row_schema, frame_features, load_info, next_file,
                                  read_episode_rows, read_tasks, recorder_features, summary, tasks_table,
                                  video_keys, write_json)
from so101.dataset.parquet_append import ParquetEnd
from so101.dataset.units import DEGREES, UNITS_KEY
from so101.dataset.stats import (STAT_KEYS, Stats, aggregate_stats, image_histogram, image_stats, stats_from_json,
                                 stats_to_json, vector_stats)

VideoSizes = Mapping[str, tuple[int, int]]  # video feature -> (width, height)


def _size_mb(path: Path) -> float:
    return path.stat().st_size / (1024**2)


def _same_features(have: dict[str, dict[str, Any]], want: dict[str, dict[str, Any]]) -> bool:
    def comparable(features: dict[str, dict[str, Any]]) -> dict[str, tuple[str, list[int], Any]]:
        return {key: (f["dtype"], list(f["shape"]), f.get("names")) for key, f in features.items()}
    return comparable(have) == comparable(want)


def _feature_difference(root: Path, have: dict[str, dict[str, Any]], want: dict[str, dict[str, Any]],
                        video_sizes: VideoSizes) -> str:
    """Why an existing dataset's features are not this recorder's, in one line."""
    unasked = [key for key in video_keys(have) if key not in video_sizes]
    if unasked:
        return (f"{root} has video ({', '.join(unasked)}): record with its image size (and an --observe that shows it), "
                "or use another folder")
    for key, (width, height) in video_sizes.items():
        if key not in have:
            return (f"{root} has no video ({key}): record without an image size (no video), or with an --observe "
                    "that leaves it out, or use another folder")
        if list(have[key]["shape"]) != list(want[key]["shape"]):
            have_height, have_width = have[key]["shape"][:2]
            return (f"{root}'s {key} video is {have_width}x{have_height}, not {width}x{height}: record at "
                    f"{have_width}x{have_height}, or use another folder")
    if (REWARD_KEY in have) != (REWARD_KEY in want):
        return (f"{root} holds a task's episodes (its reward and success): record them with --task"
                if REWARD_KEY in have else
                f"{root} holds episodes without a task: record a task's episodes (--task) in another folder")
    if (ENVIRONMENT_KEY in have) != (ENVIRONMENT_KEY in want):
        return (f"{root}'s frames show the objects' poses ({ENVIRONMENT_KEY}): record with --observe including "
                "environment, or use another folder" if ENVIRONMENT_KEY in have else
                f"{root}'s frames do not show the objects' poses ({ENVIRONMENT_KEY}): record with --observe "
                "without environment, or use another folder")
    differing = sorted(set(have) ^ set(want)) or sorted(
        key for key in have if (have[key]["dtype"], list(have[key]["shape"]), have[key].get("names"))
        != (want[key]["dtype"], list(want[key]["shape"]), want[key].get("names")))
    return (f"{root} has other features than this recorder writes (differing: {', '.join(differing)}); "
            f"it writes {', '.join(frame_features(want))}: use another folder")


def _frame_table(schema: pa.Schema, columns: dict[str, np.ndarray]) -> pa.Table:
    """An episode's frames as the data file's table: one (frames, ...) array per column."""
    arrays = []
    for field in schema:
        values = columns[field.name]
        if pa.types.is_fixed_size_list(field.type):
            arrays.append(pa.FixedSizeListArray.from_arrays(pa.array(values.reshape(-1), type=field.type.value_type),
                                                            field.type.list_size))
        else:
            arrays.append(pa.array(values.reshape(len(values)), type=field.type))
    return pa.Table.from_arrays(arrays, schema=schema)


def _concatenate(current: Path, episode: Path, output: Path) -> None:
    try:
        videos.concatenate([current, episode], output)
    except videos.av.FFmpegError as error:  # PyAV's own errors (a full disk among them)
        raise videos.VideoWriteError(videos.one_line(error)) from error


@dataclass(frozen=True)
class _SessionFile:
    """A file this writer session adds episodes to (LeRobot keeps its writer open on it)."""

    chunk_index: int
    file_index: int
    first_frame: int = 0  # data files: the dataset index of its first row
    to_timestamp: float = 0.0  # video files: where the next episode starts
    end: ParquetEnd | None = None  # data files: where the next episode's row group goes
    # Episode files: their rows, the file rewritten whole at each save. One row group per episode
    # would let it grow in place, but its ~90 statistics columns cost 11 kB of footer per row
    # group (the row itself: a few hundred bytes).
    rows: tuple[dict[str, Any], ...] = ()


class DatasetWriter:
    """Adds episodes to a LeRobot v3.0 dataset (creating it), one saved episode at a time.

    One writer per dataset: it holds the dataset folder's lock while it lives (close() or the
    process's end releases it). Saves are serialised; episodes may be recorded while one saves."""

    def __init__(self, root: Path, lock_fd: int, info: dict[str, Any], tasks: list[str],
                 rows: list[dict[str, Any]], stats: Stats | None, video_sizes: VideoSizes):
        self.root = root
        self._lock_fd: int | None = lock_fd
        self._info = info
        self.fps: int = int(info["fps"])
        self.video_sizes = dict(video_sizes)
        self.features: dict[str, dict[str, Any]] = info["features"]
        self._tasks = tasks
        self._stats = stats
        self.episodes: list[EpisodeSummary] = [summary(row, self.fps) for row in rows]
        self._last_row: dict[str, Any] | None = rows[-1] if rows else None
        self._data_file: _SessionFile | None = None
        self._video_files: dict[str, _SessionFile] = {}
        self._episodes_file: _SessionFile | None = None
        self._data_schema = data_schema(self.features)
        self._episode_schema = episode_row_schema(self.features)
        self._commit_lock = threading.Lock()
        self._work_lock = threading.Lock()
        self._work_count = 0
        self._live_episodes = 0  # with video, neither saved nor discarded: the work folder stays while any is
        # Set when a save left its journal or undo record: the files are between two states until
        # the next open completes or undoes it, so this writer saves nothing more.
        self._incomplete: str | None = None

    # -- opening -----------------------------------------------------------------------------
    @classmethod
    def open(cls, root: Path, fps: int, video_sizes: VideoSizes, *, environment_names: Sequence[str] = (),
             environment_state: bool = True, chunks_size: int = DEFAULT_CHUNK_SIZE, data_files_size_in_mb: float = DEFAULT_DATA_FILE_SIZE_IN_MB,
             video_files_size_in_mb: float = DEFAULT_VIDEO_FILE_SIZE_IN_MB) -> "DatasetWriter":
        """Open `root` to add episodes: creates the dataset if the folder is new or empty.

        video_sizes: each video feature's (width, height), e.g. {IMAGE_KEY: (320, 240)}; {} for a
        dataset without video. environment_names: a task's object_state names, for a dataset of a
        task's episodes (layout.recorder_features), with their environment state unless not
        `environment_state`. The size limits and chunks_size apply to a dataset created here
        (an existing one keeps its own)."""
        root = Path(root)
        if not isinstance(fps, int) or isinstance(fps, bool) or fps <= 0:
            raise DatasetError(f"fps {fps!r} is not a frame rate: use a whole number above 0, e.g. 30")
        for size in video_sizes.values():
            if len(size) != 2 or min(size) <= 0 or any(s % 2 for s in size):
                raise DatasetError(f"image size {size!r} cannot be stored as video: use even width and height above 0 "
                                   "(yuv420p halves them), e.g. (320, 240)")
        if root.exists() and not root.is_dir():
            raise DatasetError(f"{root} is a file: give a new or empty folder, or a LeRobot v3.0 dataset folder")
        try:
            root.mkdir(parents=True, exist_ok=True)
            lock_fd = lock_for_writing(root)
        except OSError as error:
            raise DatasetError(f"cannot open {root}: {one_line_os_error(error)}") from None
        try:
            want = recorder_features(video_sizes, tuple(environment_names), environment_state)
            return cls._open_locked(root, lock_fd, fps, video_sizes, want, chunks_size, data_files_size_in_mb,
                                    video_files_size_in_mb)
        except BaseException:
            os.close(lock_fd)
            raise

    @classmethod
    def _open_locked(cls, root: Path, lock_fd: int, fps: int, video_sizes: VideoSizes, want: dict[str, dict[str, Any]],
                     chunks_size: int, data_mb: float, video_mb: float) -> "DatasetWriter":
        try:
            if not (root / INFO_PATH).exists():
                if any(not is_ours(entry.name) for entry in root.iterdir()):
                    raise DatasetError(f"{root} is not empty and is not a LeRobot dataset (no {INFO_PATH}): "
                                       "give a new or empty folder, or a LeRobot v3.0 dataset folder")
                info: dict[str, Any] = {
                    "codebase_version": CODEBASE_VERSION, "robot_type": ROBOT_TYPE,
                    "total_episodes": 0, "total_frames": 0, "total_tasks": 0,
                    "chunks_size": chunks_size, "data_files_size_in_mb": data_mb, "video_files_size_in_mb": video_mb,
                    "fps": fps, "splits": {}, "data_path": DATA_PATH,
                    "video_path": VIDEO_PATH if video_sizes else None, "features": want,
                    UNITS_KEY: DEGREES,  # LeRobot's own datasets do not say (so101.dataset.units)
                }
                (root / "meta").mkdir(exist_ok=True)
                place_durably(root, INFO_PATH, info, [])
                fsync_path(root)
                return cls(root, lock_fd, info, [], [], None, video_sizes)
            info = load_info(root)
            recover(root)
            if int(info["fps"]) != fps:
                raise DatasetError(f"{root} is recorded at {info['fps']} fps, not {fps}: record at {info['fps']} fps, "
                                   "or use another folder")
            if not _same_features(info["features"], want):
                raise DatasetError(_feature_difference(root, info["features"], want, video_sizes))
            tasks = read_tasks(root) if (root / TASKS_PATH).exists() else []
            rows = read_episode_rows(root) if (root / EPISODES_DIR).is_dir() else []
            stats = (stats_from_json(json.loads((root / STATS_PATH).read_text(encoding="utf-8")))
                     if (root / STATS_PATH).exists() else None)
        except OSError as error:
            raise DatasetError(f"cannot open {root}: {one_line_os_error(error)}") from None
        except (pa.ArrowException, ValueError) as error:
            if isinstance(error, DatasetError):
                raise
            raise DatasetError(f"{root} cannot be read as a LeRobot v3.0 dataset: {error}") from None
        return cls(root, lock_fd, info, tasks, rows, stats, video_sizes)

    def close(self) -> None:
        """Release the dataset (the recorder's process ending does too)."""
        if self._lock_fd is not None:
            os.close(self._lock_fd)
            self._lock_fd = None

    def __enter__(self) -> "DatasetWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - at interpreter exit `os` may be gone; the exit releases the lock
            pass

    # -- episodes ----------------------------------------------------------------------------
    @property
    def tasks(self) -> list[str]:
        return list(self._tasks)

    @property
    def total_frames(self) -> int:
        return int(self._info["total_frames"])

    def start_episode(self, task: str) -> EpisodeRecorder:
        """A new episode of `task` (its text, e.g. "put the cube in the box")."""
        if self._lock_fd is None:
            raise DatasetError(f"the writer of {self.root} is closed: open it again")
        if not isinstance(task, str) or not task.strip():
            raise DatasetError("an episode needs a task text, e.g. 'put the cube in the box'")
        encoders: dict[str, videos.StreamingEncoder] = {}
        if self.video_sizes:
            with self._work_lock:
                try:
                    (self.root / WORK_DIR).mkdir(exist_ok=True)
                except OSError as error:
                    raise DatasetError(f"cannot record into {self.root}: {one_line_os_error(error)}") from None
                self._work_count += 1
                self._live_episodes += 1
                number = self._work_count
            for key, (width, height) in self.video_sizes.items():
                path = self.root / WORK_DIR / f"episode-{os.getpid()}-{number}-{key}.mp4"
                encoders[key] = videos.StreamingEncoder(path, self.fps, width, height, inspect=image_histogram)
        return EpisodeRecorder(self, task.strip(), frame_features(self.features), encoders)

    def episode_ended(self) -> None:
        """An episode with video was saved or dropped: the work folder goes when no other is recording."""
        with self._work_lock:
            self._live_episodes -= 1
            if self._live_episodes == 0:
                try:
                    (self.root / WORK_DIR).rmdir()
                except OSError:
                    pass  # already gone

    # -- a save ------------------------------------------------------------------------------
    def commit_episode(self, task: str, columns: dict[str, np.ndarray], encoded: dict[str, videos.EncodedVideo],
                       seed: int | None = None, scenario: dict[str, object] | None = None) -> EpisodeSummary:
        """Add an episode (EpisodeRecorder.save): its frame features' (frames, ...) columns, its
        finished videos, and a task's layout seed and its scenario as drawn (kept in info.json under SEEDS_KEY and
        SCENARIOS_KEY by episode index). All of it or nothing is in the dataset when this returns or raises."""
        with self._commit_lock:
            if self._lock_fd is None:
                raise DatasetError(f"the writer of {self.root} is closed: the episode is not saved")
            if self._incomplete is not None:
                raise DatasetError(f"the episode is not saved: an earlier save is still to be completed "
                                   f"({self._incomplete}); open {self.root} again")
            length = len(next(iter(columns.values())))
            episode_index = len(self.episodes)
            first_frame = self.total_frames
            tasks = list(self._tasks)
            if task not in tasks:
                tasks.append(task)

            frame_index = np.arange(length, dtype=np.int64)
            columns = {**columns,
                       "timestamp": (frame_index / self.fps).astype(np.float32),
                       "frame_index": frame_index,
                       "episode_index": np.full(length, episode_index, dtype=np.int64),
                       "index": np.arange(first_frame, first_frame + length, dtype=np.int64),
                       "task_index": np.full(length, tasks.index(task), dtype=np.int64)}
            # Statistics: LeRobot's timestamps are Python floats (float64) when it computes them.
            stats_input = {**columns, "timestamp": frame_index / self.fps}
            episode_stats: Stats = {key: image_stats(encoded[key].inspected) if key in encoded
                                    else vector_stats(stats_input[key]) for key in self.features}
            what = f"episode {episode_index}"
            try:
                plan = Plan()
                data_file = self._add_data(_frame_table(self._data_schema, columns), first_frame, plan)
                row: dict[str, Any] = {"episode_index": episode_index, "tasks": [task], "length": length,
                                       "data/chunk_index": data_file.chunk_index,
                                       "data/file_index": data_file.file_index,
                                       "dataset_from_index": first_frame, "dataset_to_index": first_frame + length}
                info = json.loads(json.dumps(self._info))
                video_files: dict[str, _SessionFile] = {}
                for key, episode_video in encoded.items():
                    video_files[key], from_s = self._add_video(key, episode_video, plan)
                    row.update({f"videos/{key}/chunk_index": video_files[key].chunk_index,
                                f"videos/{key}/file_index": video_files[key].file_index,
                                f"videos/{key}/from_timestamp": from_s,
                                f"videos/{key}/to_timestamp": video_files[key].to_timestamp})
                    if not info["features"][key].get("info"):
                        info["features"][key]["info"] = videos.video_info(episode_video.path)
                for key, feature_stats in episode_stats.items():
                    row.update({f"stats/{key}/{stat}": feature_stats[stat].tolist() for stat in STAT_KEYS})
                episodes_file = self._add_episode_row(row, length, plan)
            except OSError as error:
                raise not_saved(what, self.root, one_line_os_error(error)) from None
            if len(tasks) != len(self._tasks):
                plan.writes.append((TASKS_PATH, lambda path: pq.write_table(tasks_table(tasks), path)))
            new_stats = aggregate_stats([self._stats, episode_stats]) if self._stats is not None else episode_stats
            if seed is not None:
                info[SEEDS_KEY] = {**info.get(SEEDS_KEY, {}), str(episode_index): int(seed)}
            if scenario is not None:
                info[SCENARIOS_KEY] = {**info.get(SCENARIOS_KEY, {}), str(episode_index): scenario}
            info.update({"total_episodes": episode_index + 1, "total_frames": first_frame + length,
                         "total_tasks": len(tasks), "splits": {"train": f"0:{episode_index + 1}"}})
            plan.writes.append((INFO_PATH, lambda path: write_json(path, info)))
            plan.writes.append((STATS_PATH, lambda path: write_json(path, stats_to_json(new_stats))))

            try:
                commit(self.root, plan, what)
            except CommitIncomplete as error:
                self._incomplete = error.reason
                raise

            # Committed: the writer's view follows the files.
            self._info, self._tasks, self._stats = info, tasks, new_stats
            self._data_file, self._episodes_file = data_file, episodes_file
            self._video_files.update(video_files)
            self._last_row = row
            episode = EpisodeSummary(episode_index, length, (task,), length / self.fps)
            self.episodes = [*self.episodes, episode]  # a new list: readers in other threads see whole ones
            return episode

    # -- where an episode goes (LeRobot's _save_episode_data, _save_episode_video and
    # _save_episode_metadata rules) ----------------------------------------------------------
    def _new_file(self, template: str, prefix: str, current: _SessionFile | None) -> tuple[int, int]:
        """The next file of a kind after the session's current one: when resuming, the one after the
        last episode's (LeRobot moves on); never a file that exists (a file no episode row names,
        left by a crashed LeRobot session, is kept)."""
        chunks_size = int(self._info["chunks_size"])
        if current is not None:
            chunk, file = next_file(current.chunk_index, current.file_index, chunks_size)
        elif self._last_row is not None and f"{prefix}/chunk_index" in self._last_row:
            chunk, file = next_file(int(self._last_row[f"{prefix}/chunk_index"]),
                                    int(self._last_row[f"{prefix}/file_index"]), chunks_size)
        else:
            chunk, file = 0, 0
        while (self.root / template.format(chunk_index=chunk, file_index=file)).exists():
            chunk, file = next_file(chunk, file, chunks_size)
        return chunk, file

    def _data_fits(self, current: _SessionFile, first_frame: int, frames: int) -> bool:
        path = self.root / DATA_PATH.format(chunk_index=current.chunk_index, file_index=current.file_index)
        frames_in_file = first_frame - current.first_frame
        per_frame_mb = _size_mb(path) / frames_in_file if frames_in_file > 0 else 0.0
        return _size_mb(path) + per_frame_mb * frames < float(self._info["data_files_size_in_mb"])

    def _video_fits(self, current_path: Path, encoded: videos.EncodedVideo) -> bool:
        return _size_mb(current_path) + _size_mb(encoded.path) < float(self._info["video_files_size_in_mb"])

    def _episode_row_fits(self, current: _SessionFile, frames: int) -> bool:
        path = self.root / EPISODES_PATH.format(chunk_index=current.chunk_index, file_index=current.file_index)
        # LeRobot divides by the latest episode's index here, not by a frame count: its rule, kept.
        latest_index = int(current.rows[-1]["episode_index"])
        per_frame_mb = _size_mb(path) / latest_index if latest_index > 0 else 0.0
        return _size_mb(path) + per_frame_mb * frames < float(self._info["data_files_size_in_mb"])

    def _add_data(self, table: pa.Table, first_frame: int, plan: Plan) -> _SessionFile:
        """The data file the episode's rows go to: the session's, grown in place, or a new one."""
        current = self._data_file
        if current is not None and current.end is not None and self._data_fits(current, first_frame, table.num_rows):
            path = DATA_PATH.format(chunk_index=current.chunk_index, file_index=current.file_index)
            splice, end = parquet_append.appended(path, current.end, table)
            plan.splices.append(splice)
            return replace(current, end=end)
        chunk, file = self._new_file(DATA_PATH, "data", current)
        content, end = parquet_append.new_file(table)
        plan.writes.append((DATA_PATH.format(chunk_index=chunk, file_index=file), lambda path: path.write_bytes(content)))
        return _SessionFile(chunk, file, first_frame=first_frame, end=end)

    def _add_video(self, key: str, encoded: videos.EncodedVideo, plan: Plan) -> tuple[_SessionFile, float]:
        """The video file the episode's video of `key` goes to, and the episode's from_timestamp in it."""
        current = self._video_files.get(key)
        template = VIDEO_PATH.replace("{video_key}", key)
        if current is not None:
            current_path = self.root / template.format(chunk_index=current.chunk_index, file_index=current.file_index)
            if self._video_fits(current_path, encoded):
                episode_path = encoded.path
                plan.writes.append((str(current_path.relative_to(self.root)),
                                    lambda path: _concatenate(current_path, episode_path, path)))
                return replace(current, to_timestamp=current.to_timestamp + encoded.duration_s), current.to_timestamp
        chunk, file = self._new_file(template, f"videos/{key}", current)
        plan.moves.append((encoded.path, template.format(chunk_index=chunk, file_index=file)))
        return _SessionFile(chunk, file, to_timestamp=encoded.duration_s), 0.0

    def _add_episode_row(self, row: dict[str, Any], frames: int, plan: Plan) -> _SessionFile:
        """The meta/episodes file the row goes to, rewritten with it; the row gets its place."""
        current = self._episodes_file
        if current is not None and self._episode_row_fits(current, frames):
            chunk, file, rows = current.chunk_index, current.file_index, (*current.rows, row)
        else:
            chunk, file = self._new_file(EPISODES_PATH, "meta/episodes", current)
            rows = (row,)
        row.update({"meta/episodes/chunk_index": chunk, "meta/episodes/file_index": file})
        table = pa.Table.from_pylist(list(rows), schema=self._episode_schema)
        plan.writes.append((EPISODES_PATH.format(chunk_index=chunk, file_index=file),
                            lambda path: pq.write_table(table, path, compression="snappy", use_dictionary=True)))
        return _SessionFile(chunk, file, rows=rows)
