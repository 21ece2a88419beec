"""The reader: a LeRobot v3.0 dataset's episodes, numbers and pictures (the files: layout.py)."""

from __future__ import annotations

import fcntl
import json
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from so101.dataset import video as videos
from so101.dataset.commit import consistent_view, flock
from so101.dataset.features import ACTION_KEY, STATE_KEY, from_lerobot
from so101.dataset.layout import (DATA_PATH, EPISODES_DIR, STATS_PATH, TASKS_PATH, DatasetError, describe, load_info,
                                  read_episode_rows, read_tasks, summary, video_keys)
from so101.dataset.units import JointUnits, joint_units
from so101.feetech.calibration import CalibrationError, load_calibration
from so101.dataset.video import Image


def _column_to_numpy(column: Any, feature: dict[str, Any]) -> np.ndarray:
    dtype = np.dtype(feature["dtype"])
    shape = tuple(feature["shape"])
    chunked = column.combine_chunks() if hasattr(column, "combine_chunks") else column
    if pa.types.is_fixed_size_list(chunked.type) or pa.types.is_list(chunked.type) or pa.types.is_large_list(chunked.type):
        flat = chunked.flatten().to_numpy(zero_copy_only=False)
        return np.asarray(flat, dtype=dtype).reshape(len(chunked), *shape)
    values = np.asarray(chunked.to_numpy(zero_copy_only=False), dtype=dtype)
    return values if shape in ((1,), ()) else values.reshape(len(chunked), *shape)


class Dataset:
    """A LeRobot v3.0 dataset read from its folder: any number of episodes, files and chunks, with
    or without video, ours or LeRobot's own."""

    def __init__(self, root: Path, info: dict[str, Any], tasks: list[str], rows: list[dict[str, Any]]):
        self.root = root
        self.info = info
        self.fps: int = int(info["fps"])
        self.robot_type: str | None = info.get("robot_type")
        self.features: dict[str, dict[str, Any]] = info["features"]
        self.total_frames: int = int(info.get("total_frames", sum(int(r["length"]) for r in rows)))
        self.tasks = tasks
        self._rows = {int(row["episode_index"]): row for row in rows}
        self.episodes = [summary(row, self.fps) for row in rows]
        self.video_keys = video_keys(self.features)

    @classmethod
    def open(cls, root: Path) -> "Dataset":
        root = Path(root)
        load_info(root)  # a clear refusal before anything is touched
        try:
            with consistent_view(root):
                info = load_info(root)
                tasks = read_tasks(root) if (root / TASKS_PATH).exists() else []
                rows = read_episode_rows(root) if (root / EPISODES_DIR).is_dir() else []
        except (OSError, pa.ArrowException) as error:
            raise DatasetError(f"{root} cannot be read: {error}") from None
        return cls(root, info, tasks, rows)

    def _row(self, index: int) -> dict[str, Any]:
        if index not in self._rows:
            raise DatasetError(f"{self.root} has no episode {index}: {describe(self.episodes)}")
        return self._rows[index]

    def episode_frames(self, index: int) -> dict[str, np.ndarray]:
        """The episode's numeric columns, one entry per frame: "action" (L, 6) float32,
        "observation.state" (L, 6), "timestamp" (L,), "frame_index", "episode_index", "index",
        "task_index" (L,) int64, and any other numeric feature a LeRobot dataset has."""
        row = self._row(index)
        path = self.root / self.info.get("data_path", DATA_PATH).format(
            chunk_index=int(row["data/chunk_index"]), file_index=int(row["data/file_index"]))
        wanted = {key: feature for key, feature in self.features.items()
                  if feature.get("dtype") not in ("video", "image", "string")}
        try:
            with flock(self.root / "meta", fcntl.LOCK_SH):  # a writer grows the file in place: never half way
                present = set(pq.read_schema(path).names)
                columns = [key for key in wanted if key in present]
                table = pq.read_table(path, columns=columns, filters=[("episode_index", "=", index)])
        except (OSError, pa.ArrowException) as error:
            raise DatasetError(f"episode {index}'s data cannot be read from {path}: {error}") from None
        if table.num_rows != int(row["length"]):  # a data file that does not hold what the metadata says
            raise DatasetError(f"episode {index} has {int(row['length'])} frames in its metadata but {table.num_rows} "
                               f"rows in {path}: the dataset's files disagree")
        frames = {key: _column_to_numpy(table.column(key), wanted[key]) for key in columns}
        if "frame_index" in frames and np.any(np.diff(frames["frame_index"]) < 0):
            order = np.argsort(frames["frame_index"], kind="stable")
            frames = {key: values[order] for key, values in frames.items()}
        return frames

    def joint_units(self, said: str | None = None, calibration_file: Path | None = None,
                    episode: int | None = None) -> JointUnits:
        """How this dataset's joints read as degrees (so101.dataset.units.joint_units): its meta, `said`
        (--units) with the recording follower's `calibration_file`, or its values: its statistics'
        extremes, else episode `episode`'s frames. DatasetError in one line."""
        try:
            calibration = None if calibration_file is None else load_calibration(calibration_file)
        except CalibrationError as error:
            raise DatasetError(str(error)) from None
        extremes = self._joint_extremes()
        if extremes is None:
            first = self.episodes[0].index if self.episodes else 0
            frames = self.episode_frames(first if episode is None else episode)
            extremes = np.concatenate([frames[key] for key in (ACTION_KEY, STATE_KEY) if key in frames] or [np.zeros((0, 6))])
        try:
            return joint_units(self.info, extremes, said, calibration, str(calibration_file or ""))
        except DatasetError as error:
            raise type(error)(f"{self.root}: {error}") from None

    def episode_joints_deg(self, index: int, units: JointUnits) -> dict[str, np.ndarray]:
        """Episode `index`'s action and observation.state (those it has) in this project's degrees, (L, 6)."""
        frames = self.episode_frames(index)
        return {key: from_lerobot(units.as_degrees(frames[key])) for key in (ACTION_KEY, STATE_KEY) if key in frames}

    def _joint_extremes(self) -> np.ndarray | None:
        try:
            stats = json.loads((self.root / STATS_PATH).read_text(encoding="utf-8"))
            return np.array([stats[key][end] for key in (ACTION_KEY, STATE_KEY) if key in stats for end in ("min", "max")],
                            dtype=np.float64).reshape(-1, 6)
        except (OSError, ValueError, KeyError, TypeError):
            return None

    def episode_images(self, index: int, key: str) -> Iterator[Image]:
        """The episode's pictures of video feature `key`, decoded, (H, W, 3) uint8, in frame order."""
        row = self._row(index)
        if key not in self.video_keys:
            accepted = ", ".join(self.video_keys) if self.video_keys else "none: this dataset has no video"
            raise DatasetError(f"{key!r} is not a video feature of {self.root} (video features: {accepted})")
        path = self.root / str(self.info["video_path"]).format(
            video_key=key, chunk_index=int(row[f"videos/{key}/chunk_index"]),
            file_index=int(row[f"videos/{key}/file_index"]))
        start_s = float(row[f"videos/{key}/from_timestamp"])
        end_s = start_s + int(row["length"]) / self.fps
        return videos.decode(path, start_s, end_s, self.fps)
