"""LeRobotDataset v3.0 on disk, read and written with pyarrow and PyAV only (no lerobot, torch, pandas).

The files are those LeRobot 0.4.x writes (lerobot/datasets/lerobot_dataset.py, utils.py,
compute_stats.py, video_utils.py; where its docs and its code differ, this follows the code):

    meta/info.json                         fps, features, totals, path templates, file-size limits
    meta/tasks.parquet                     task text (a pandas index) -> task_index
    meta/stats.json                        every feature's statistics over the dataset
    meta/episodes/chunk-000/file-000.parquet   one row per episode: frame range, tasks, where its
                                           data and video are, its statistics flattened
    data/chunk-000/file-000.parquet        one row per frame, one row group per episode
    videos/<key>/chunk-000/file-000.mp4    the episodes' pictures one after another

As in LeRobot, every writer session (DatasetWriter.open) starts new data, video and episode
files; within a session each episode is added to them until a file would pass its size limit
(info.json's data_files_size_in_mb, video_files_size_in_mb), and after chunks_size files the
next chunk folder starts.

Nothing is lost: the episode being recorded lives in memory and its video in DIR/.so101-work/;
saving writes every new or changed file beside its final name (NAME.so101-new), fsyncs them,
then writes a journal (meta/.so101-commit.json) naming the renames, then renames, then removes
the journal. Opening the dataset (reader or writer) finishes the renames of a journal it finds
and removes temporary and work files without one. A crash at any moment thus leaves every saved
episode readable, and the episode being saved either whole or absent.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.parquet as pq

from so101.dataset import video as videos
from so101.dataset.features import ACTION_KEY, IMAGE_KEY, MOTOR_NAMES, ROBOT_TYPE, STATE_KEY

CODEBASE_VERSION = "v3.0"
DEFAULT_CHUNK_SIZE = 1000  # files per chunk folder
DEFAULT_DATA_FILE_SIZE_IN_MB = 100
DEFAULT_VIDEO_FILE_SIZE_IN_MB = 200

INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
TASKS_PATH = "meta/tasks.parquet"
EPISODES_DIR = "meta/episodes"
CHUNK_FILE_PATTERN = "chunk-{chunk_index:03d}/file-{file_index:03d}"
EPISODES_PATH = EPISODES_DIR + "/" + CHUNK_FILE_PATTERN + ".parquet"
DATA_PATH = "data/" + CHUNK_FILE_PATTERN + ".parquet"
VIDEO_PATH = "videos/{video_key}/" + CHUNK_FILE_PATTERN + ".mp4"

DEFAULT_FEATURES: dict[str, dict[str, Any]] = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}

# compute_stats.py: RunningQuantileStats' quantiles and histogram bins.
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
QUANTILE_KEYS = tuple(f"q{int(q * 100):02d}" for q in QUANTILES)
QUANTILE_BINS = 5000
STAT_KEYS = ("min", "max", "mean", "std", "count") + QUANTILE_KEYS

# This writer's own files, never LeRobot's: LeRobot globs `*/*.parquet` and reads the paths in
# the episode rows, so it passes over all of them.
WORK_DIR = ".so101-work"
JOURNAL_PATH = "meta/.so101-commit.json"
TEMP_SUFFIX = ".so101-new"
# A reader that is recovering holds the dataset folder's lock for a moment: a writer waits this long.
LOCK_WAIT_S = 5.0

Float32Array = npt.NDArray[np.float32]
Image = npt.NDArray[np.uint8]
Stats = dict[str, dict[str, np.ndarray]]


class DatasetError(ValueError):
    """What is wrong with a dataset or a request, and what is accepted: str() is one line."""

    def __init__(self, message: str):
        super().__init__(" ".join(message.split()))


class _CommitIncomplete(DatasetError):
    """A save whose journal is whole but whose renames failed: the next open completes it."""


@dataclass(frozen=True)
class EpisodeSummary:
    index: int
    length: int  # frames
    tasks: tuple[str, ...]
    duration_s: float


def recorder_features(image_size: tuple[int, int] | None) -> dict[str, dict[str, Any]]:
    """The features a DatasetWriter writes, in LeRobot's order: ours, then LeRobot's defaults.

    image_size: (width, height) of the front camera's video, or None for no video."""
    features: dict[str, dict[str, Any]] = {
        ACTION_KEY: {"dtype": "float32", "shape": [len(MOTOR_NAMES)], "names": list(MOTOR_NAMES)},
        STATE_KEY: {"dtype": "float32", "shape": [len(MOTOR_NAMES)], "names": list(MOTOR_NAMES)},
    }
    if image_size is not None:
        width, height = image_size
        features[IMAGE_KEY] = {"dtype": "video", "shape": [height, width, 3], "names": ["height", "width", "channels"]}
    return {**features, **json.loads(json.dumps(DEFAULT_FEATURES))}


# -- statistics, as lerobot/datasets/compute_stats.py computes them ---------------------------------


def sample_indices(length: int) -> list[int]:
    """The frames of an episode whose pictures enter its image statistics (LeRobot's sample_indices)."""
    min_samples, max_samples, power = 100, 10_000, 0.75
    if length < min_samples:
        min_samples = length
    count = max(min_samples, min(int(length**power), max_samples))
    return [int(i) for i in np.round(np.linspace(0, length - 1, count)).astype(int)]


def _downsample(image: Image) -> Image:
    # auto_downsample_height_width: pictures 300 px or larger are thinned to about 150 px.
    height, width = image.shape[:2]
    if max(width, height) < 300:
        return image
    factor = int(width / 150) if width > height else int(height / 150)
    return image[::factor, ::factor]


_CHANNEL_OFFSETS = np.array([0, 256, 512], dtype=np.int32)


def image_histogram(image: Image) -> npt.NDArray[np.int64]:
    """How many pixels of each value (0-255) each channel has, after LeRobot's downsampling: (3, 256).

    Every image statistic LeRobot keeps (min, max, mean, std, its histogram quantiles) follows
    from these counts, so an episode keeps 3 kB per frame instead of its pictures."""
    pixels = _downsample(image).reshape(-1, 3).astype(np.int32) + _CHANNEL_OFFSETS
    return np.bincount(pixels.ravel(), minlength=768).reshape(3, 256).astype(np.int64)


def _histogram_quantile(counts: np.ndarray, edges: np.ndarray, target: float) -> float:
    # RunningQuantileStats._compute_single_quantile: the bin where the count passes `target`,
    # interpolated linearly within it.
    cumulative = np.cumsum(counts)
    idx = int(np.searchsorted(cumulative, target))
    if idx == 0:
        return float(edges[0])
    if idx >= len(cumulative):
        return float(edges[-1])
    before = cumulative[idx - 1]
    in_bin = cumulative[idx] - before
    if in_bin == 0:
        return float(edges[idx])
    return float(edges[idx] + (target - before) / in_bin * (edges[idx + 1] - edges[idx]))


def _quantiles(column: np.ndarray, weights: np.ndarray | None = None) -> list[float]:
    """LeRobot's quantiles of one column: a 5000-bin histogram between its min and max.

    `column` keeps its dtype (float32 actions give float32 bin edges, as in LeRobot); `weights`
    counts each value's occurrences (the image histograms)."""
    if weights is None:
        low, high, total = column.min(), column.max(), len(column)
    else:
        present = column[weights > 0]
        low, high, total = present.min(), present.max(), int(weights.sum())
    edges = np.linspace(low - 1e-10, high + 1e-10, QUANTILE_BINS + 1)
    counts, _ = np.histogram(column, bins=edges, weights=weights)
    return [_histogram_quantile(counts, edges, q * total) for q in QUANTILES]


def vector_stats(values: np.ndarray) -> dict[str, np.ndarray]:
    """One numeric feature's statistics over an episode: values (frames,) or (frames, n).

    min and max keep the values' dtype (ints stay ints in the JSON); mean and std are exact
    (float64), where LeRobot's float32 running sums lose digits; quantiles are LeRobot's."""
    as_rows = values.reshape(len(values), -1)
    wide = as_rows.astype(np.float64)
    mean = wide.mean(axis=0)
    stats: dict[str, np.ndarray] = {
        "min": as_rows.min(axis=0),
        "max": as_rows.max(axis=0),
        "mean": mean,
        "std": wide.std(axis=0),
        "count": np.array([len(values)], dtype=np.int64),
    }
    if len(values) < 2:  # _compute_basic_stats: too few for a histogram, the mean stands in
        per_column = [list(mean) for _ in QUANTILES]
    else:
        by_column = [_quantiles(as_rows[:, i]) for i in range(as_rows.shape[1])]
        per_column = [[column[k] for column in by_column] for k in range(len(QUANTILES))]
    for key, column_values in zip(QUANTILE_KEYS, per_column):
        stats[key] = np.array(column_values, dtype=np.float64)
    return stats


def image_stats(histograms: list[np.ndarray]) -> dict[str, np.ndarray]:
    """An episode's picture statistics from its frames' histograms (image_histogram), as LeRobot
    computes them: over the pixels of sample_indices' frames, per channel, in [0, 1], shaped
    (3, 1, 1); count is the number of frames sampled.

    std is the true one: LeRobot 0.4.x squares uint8 pixels in uint8 (compute_stats.py
    RunningQuantileStats.update), which wraps around and leaves its image std 0 or near it."""
    chosen = sample_indices(len(histograms))
    counts = np.sum([histograms[i] for i in chosen], axis=0).astype(np.float64)  # (3, 256)
    levels = np.arange(256, dtype=np.float64)
    totals = counts.sum(axis=1)
    mean = (counts * levels).sum(axis=1) / totals
    variance = (counts * (levels - mean[:, None]) ** 2).sum(axis=1) / totals
    present = counts > 0
    stats: dict[str, np.ndarray] = {
        "min": np.array([levels[row].min() for row in present]),
        "max": np.array([levels[row].max() for row in present]),
        "mean": mean,
        "std": np.sqrt(variance),
        "count": np.array([len(chosen)], dtype=np.int64),
    }
    # np.arange(256) as integers, so the bin edges are float64 as for LeRobot's uint8 pixels.
    by_channel = [_quantiles(np.arange(256), counts[c]) for c in range(3)]
    for k, key in enumerate(QUANTILE_KEYS):
        stats[key] = np.array([by_channel[c][k] for c in range(3)])
    return {key: value if key == "count" else (value / 255.0).reshape(3, 1, 1) for key, value in stats.items()}


def aggregate_feature_stats(stats_list: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """LeRobot's aggregate_feature_stats: count-weighted means, pooled variance, quantiles weighted by count."""
    means = np.stack([s["mean"] for s in stats_list])
    variances = np.stack([s["std"] ** 2 for s in stats_list])
    counts = np.stack([s["count"] for s in stats_list])
    total_count = counts.sum(axis=0)
    while counts.ndim < means.ndim:
        counts = np.expand_dims(counts, axis=-1)
    total_mean = (means * counts).sum(axis=0) / total_count
    delta_means = means - total_mean
    total_variance = ((variances + delta_means**2) * counts).sum(axis=0) / total_count
    aggregated = {
        "min": np.min(np.stack([s["min"] for s in stats_list]), axis=0),
        "max": np.max(np.stack([s["max"] for s in stats_list]), axis=0),
        "mean": total_mean,
        "std": np.sqrt(total_variance),
        "count": total_count,
    }
    for key in QUANTILE_KEYS:
        if all(key in s for s in stats_list):
            aggregated[key] = (np.stack([s[key] for s in stats_list]) * counts).sum(axis=0) / total_count
    return aggregated


def aggregate_stats(stats_list: list[Stats]) -> Stats:
    """LeRobot's aggregate_stats: per feature, over every stats dict that has it."""
    keys = [key for stats in stats_list for key in stats]
    return {key: aggregate_feature_stats([stats[key] for stats in stats_list if key in stats])
            for key in dict.fromkeys(keys)}


def stats_to_json(stats: Stats) -> dict[str, dict[str, Any]]:
    return {key: {name: value.tolist() for name, value in feature.items()} for key, feature in stats.items()}


def stats_from_json(data: dict[str, dict[str, Any]]) -> Stats:
    return {key: {name: np.array(value) for name, value in feature.items()} for key, feature in data.items()}


# -- file helpers ---------------------------------------------------------------------------------


def _one_line_os_error(error: OSError) -> str:
    where = f" ({error.filename})" if error.filename else ""
    return f"{error.strerror or error}{where}"


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_json(path: Path, data: Any) -> None:
    """json.dump as LeRobot's write_json: indent 4, UTF-8 as is (the caller fsyncs)."""
    with open(path, "w", encoding="utf-8") as file:
        json.dump(data, file, indent=4, ensure_ascii=False)


@contextmanager
def _flock(path: Path, operation: int) -> Iterator[None]:
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, operation)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def _try_lock(path: Path) -> int | None:
    """An exclusive lock on a folder, held until the returned descriptor is closed; None if held elsewhere."""
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as error:
        os.close(fd)
        if error.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
            return None
        raise
    return fd


def _roll_forward(root: Path, renames: list[tuple[str, str]]) -> None:
    """Do the journal's renames that are not done yet (a temp that is gone was renamed)."""
    folders: set[Path] = set()
    for source, target in renames:
        if (root / source).exists():
            os.replace(root / source, root / target)
            folders.update({(root / source).parent, (root / target).parent})
    for folder in folders:
        if folder.exists():
            _fsync_path(folder)
    (root / JOURNAL_PATH).unlink(missing_ok=True)
    _fsync_path(root / "meta")


def _recover(root: Path) -> None:
    """Complete an interrupted commit (its journal exists: every temp was written and fsynced),
    then remove what an interrupted commit or recording left (temps without a journal, work files).

    The caller holds the dataset folder's lock: no writer is alive."""
    journal = root / JOURNAL_PATH
    if journal.exists():
        try:
            renames = [(str(a), str(b)) for a, b in json.loads(journal.read_text(encoding="utf-8"))["renames"]]
        except (ValueError, KeyError, TypeError):
            renames = []  # cannot happen (the journal is renamed into place whole); drop it
        with _flock(root / "meta", fcntl.LOCK_EX):
            _roll_forward(root, renames)
    for folder in ("meta", "data", "videos"):
        if (root / folder).is_dir():
            for temp in (root / folder).rglob("*" + TEMP_SUFFIX):
                temp.unlink(missing_ok=True)
    work = root / WORK_DIR
    if work.is_dir():
        for stale in work.iterdir():
            stale.unlink(missing_ok=True)
        work.rmdir()


@contextmanager
def _consistent_view(root: Path) -> Iterator[None]:
    """Recover if no writer is alive, then hold the metadata still (no commit renames) while reading."""
    fd = _try_lock(root)
    if fd is not None:
        try:
            _recover(root)
        finally:
            os.close(fd)
    with _flock(root / "meta", fcntl.LOCK_SH):
        yield


def _is_ours(name: str) -> bool:
    return name == WORK_DIR or name.endswith(TEMP_SUFFIX)


def _read_tasks(root: Path) -> list[str]:
    """Task texts by task_index. LeRobot writes them as a pandas index (a column named by the
    parquet's pandas metadata, `__index_level_0__` or `task`) beside `task_index`."""
    table = pq.read_table(root / TASKS_PATH)
    pandas_meta = json.loads((table.schema.metadata or {}).get(b"pandas", b"{}"))
    index_columns = [name for name in pandas_meta.get("index_columns", []) if isinstance(name, str)]
    text_columns = index_columns or [name for name in table.column_names if name != "task_index"]
    if "task_index" not in table.column_names or not text_columns:
        raise DatasetError(f"{root / TASKS_PATH} has no task_index and task text columns")
    texts = table.column(text_columns[0]).to_pylist()
    indices = table.column("task_index").to_pylist()
    tasks = [""] * (max(indices) + 1 if indices else 0)
    for index, text in zip(indices, texts):
        tasks[index] = str(text)
    return tasks


def _tasks_table(tasks: list[str]) -> pa.Table:
    """tasks.parquet as pandas' DataFrame.to_parquet writes LeRobot's task table (index = text),
    so that LeRobot's pd.read_parquet gets the texts back as the index."""
    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [{"name": None, "field_name": None, "pandas_type": "unicode", "numpy_type": "object",
                            "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64",
             "metadata": None},
            {"name": None, "field_name": "__index_level_0__", "pandas_type": "unicode", "numpy_type": "object",
             "metadata": None},
        ],
        "attributes": {},
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.3.3",
    }
    schema = pa.schema([("task_index", pa.int64()), ("__index_level_0__", pa.string())],
                       metadata={b"pandas": json.dumps(pandas_meta).encode()})
    return pa.table({"task_index": list(range(len(tasks))), "__index_level_0__": tasks}, schema=schema)


def _read_episode_rows(root: Path) -> list[dict[str, Any]]:
    """Every episode's row of meta/episodes (without its statistics), by episode_index."""
    rows: list[dict[str, Any]] = []
    for path in sorted((root / EPISODES_DIR).glob("*/*.parquet")):
        schema = pq.read_schema(path)
        columns = [name for name in schema.names if not name.startswith("stats/")]
        rows.extend(pq.read_table(path, columns=columns).to_pylist())
    return sorted(rows, key=lambda row: int(row["episode_index"]))


def _load_info(root: Path) -> dict[str, Any]:
    info_path = root / INFO_PATH
    if not root.exists():
        raise DatasetError(f"{root} does not exist: give the folder of a LeRobot v3.0 dataset")
    if not root.is_dir():
        raise DatasetError(f"{root} is a file, not a dataset folder: give the folder of a LeRobot v3.0 dataset")
    if not info_path.is_file():
        raise DatasetError(f"{root} is not a LeRobot dataset (no {INFO_PATH}): give the folder of a LeRobot v3.0 dataset")
    try:
        info = json.loads(info_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise DatasetError(f"{info_path} cannot be read as JSON ({error}): it must be LeRobot's info.json") from None
    if not isinstance(info, dict) or not isinstance(info.get("features"), dict) or "fps" not in info:
        raise DatasetError(f"{info_path} has no fps or features: it is not LeRobot's info.json")
    version = str(info.get("codebase_version", "?"))
    if not version.startswith("v3."):
        raise DatasetError(f"{root} is a LeRobot {version} dataset: this reads and writes v3.0 "
                           "(LeRobot converts older ones with lerobot.datasets.v30.convert_dataset_v21_to_v30)")
    return info


def _summary(row: dict[str, Any], fps: int) -> EpisodeSummary:
    length = int(row["length"])
    return EpisodeSummary(int(row["episode_index"]), length, tuple(str(t) for t in row.get("tasks") or ()),
                          length / fps)


def _column_to_numpy(column: Any, feature: dict[str, Any]) -> np.ndarray:
    dtype = np.dtype(feature["dtype"])
    shape = tuple(feature["shape"])
    chunked = column.combine_chunks() if hasattr(column, "combine_chunks") else column
    if pa.types.is_fixed_size_list(chunked.type) or pa.types.is_list(chunked.type) or pa.types.is_large_list(chunked.type):
        flat = chunked.flatten().to_numpy(zero_copy_only=False)
        return np.asarray(flat, dtype=dtype).reshape(len(chunked), *shape)
    values = np.asarray(chunked.to_numpy(zero_copy_only=False), dtype=dtype)
    return values if shape in ((1,), ()) else values.reshape(len(chunked), *shape)


def _describe(episodes: list[EpisodeSummary]) -> str:
    if not episodes:
        return "it has no episodes"
    indices = [e.index for e in episodes]
    if indices == list(range(indices[0], indices[-1] + 1)):
        return f"it has episodes {indices[0]}-{indices[-1]}" if len(indices) > 1 else f"it has episode {indices[0]}"
    return "it has episodes " + ", ".join(str(i) for i in indices)


# -- the reader -----------------------------------------------------------------------------------


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
        self.episodes = [_summary(row, self.fps) for row in rows]
        self.video_keys = [key for key, feature in self.features.items() if feature.get("dtype") == "video"]

    @classmethod
    def open(cls, root: Path) -> "Dataset":
        root = Path(root)
        _load_info(root)  # a clear refusal before anything is touched
        try:
            with _consistent_view(root):
                info = _load_info(root)
                tasks = _read_tasks(root) if (root / TASKS_PATH).exists() else []
                rows = _read_episode_rows(root) if (root / EPISODES_DIR).is_dir() else []
        except (OSError, pa.ArrowException) as error:
            raise DatasetError(f"{root} cannot be read: {error}") from None
        return cls(root, info, tasks, rows)

    def _row(self, index: int) -> dict[str, Any]:
        if index not in self._rows:
            raise DatasetError(f"{self.root} has no episode {index}: {_describe(self.episodes)}")
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


# -- the writer -----------------------------------------------------------------------------------


def _next_file(chunk_index: int, file_index: int, chunks_size: int) -> tuple[int, int]:
    """LeRobot's update_chunk_file_indices: the next file, in the next chunk after chunks_size files."""
    if file_index == chunks_size - 1:
        return chunk_index + 1, 0
    return chunk_index, file_index + 1


def _size_mb(path: Path) -> float:
    return path.stat().st_size / (1024**2)


def _data_schema(features: dict[str, dict[str, Any]]) -> pa.Schema:
    """The frame table's schema, with the `huggingface` metadata LeRobot's datasets library writes."""
    fields = []
    hf_features: dict[str, Any] = {}
    for key, feature in features.items():
        if feature["dtype"] in ("video", "image"):
            continue
        value_type = pa.from_numpy_dtype(np.dtype(feature["dtype"]))
        if list(feature["shape"]) == [1]:
            fields.append(pa.field(key, value_type))
            hf_features[key] = {"dtype": feature["dtype"], "_type": "Value"}
        else:
            fields.append(pa.field(key, pa.list_(value_type, int(feature["shape"][0]))))
            hf_features[key] = {"feature": {"dtype": feature["dtype"], "_type": "Value"},
                                "length": int(feature["shape"][0]), "_type": "List"}
    return pa.schema(fields, metadata={b"huggingface": json.dumps({"info": {"features": hf_features}}).encode()})


def _episode_row_schema(features: dict[str, dict[str, Any]]) -> pa.Schema:
    """meta/episodes' columns and types as LeRobot writes them (pa.Table.from_pydict of its row dict)."""
    fields = [("episode_index", pa.int64()), ("tasks", pa.list_(pa.string())), ("length", pa.int64()),
              ("data/chunk_index", pa.int64()), ("data/file_index", pa.int64()),
              ("dataset_from_index", pa.int64()), ("dataset_to_index", pa.int64())]
    for key, feature in features.items():
        if feature["dtype"] == "video":
            fields += [(f"videos/{key}/chunk_index", pa.int64()), (f"videos/{key}/file_index", pa.int64()),
                       (f"videos/{key}/from_timestamp", pa.float64()), (f"videos/{key}/to_timestamp", pa.float64())]
    for key, feature in features.items():
        is_image = feature["dtype"] in ("video", "image")
        is_int = not is_image and np.issubdtype(np.dtype(feature["dtype"]), np.integer)
        for stat in STAT_KEYS:
            if stat == "count":
                fields.append((f"stats/{key}/{stat}", pa.list_(pa.int64())))
            elif is_image:
                fields.append((f"stats/{key}/{stat}", pa.list_(pa.list_(pa.list_(pa.float64())))))
            elif is_int and stat in ("min", "max"):
                fields.append((f"stats/{key}/{stat}", pa.list_(pa.int64())))
            else:
                fields.append((f"stats/{key}/{stat}", pa.list_(pa.float64())))
    fields += [("meta/episodes/chunk_index", pa.int64()), ("meta/episodes/file_index", pa.int64())]
    return pa.schema(fields)


def _same_features(have: dict[str, dict[str, Any]], want: dict[str, dict[str, Any]]) -> bool:
    def comparable(features: dict[str, dict[str, Any]]) -> dict[str, tuple[str, list[int], Any]]:
        return {key: (f["dtype"], list(f["shape"]), f.get("names")) for key, f in features.items()}
    return comparable(have) == comparable(want)


def _feature_difference(root: Path, have: dict[str, dict[str, Any]], want: dict[str, dict[str, Any]],
                        image_size: tuple[int, int] | None) -> str:
    """Why an existing dataset's features are not this recorder's, in one line."""
    have_video = {key for key, f in have.items() if f.get("dtype") == "video"}
    if image_size is None and have_video:
        return f"{root} has video ({', '.join(sorted(have_video))}): record with its image size, or use another folder"
    if image_size is not None and IMAGE_KEY not in have:
        return (f"{root} has no video ({IMAGE_KEY}): record without an image size (no video), "
                "or use another folder")
    if image_size is not None and IMAGE_KEY in have and list(have[IMAGE_KEY]["shape"]) != list(want[IMAGE_KEY]["shape"]):
        height, width = have[IMAGE_KEY]["shape"][:2]
        return (f"{root}'s video is {width}x{height}, not {image_size[0]}x{image_size[1]}: record at "
                f"{width}x{height}, or use another folder")
    differing = sorted(set(have) ^ set(want)) or sorted(
        key for key in have if (have[key]["dtype"], list(have[key]["shape"]), have[key].get("names"))
        != (want[key]["dtype"], list(want[key]["shape"]), want[key].get("names")))
    return (f"{root} has other features than this recorder writes (differing: {', '.join(differing)}); "
            f"it writes {', '.join(k for k in want if k not in DEFAULT_FEATURES)}: use another folder")


@dataclass
class _SessionFile:
    """A file this writer session appends episodes to (LeRobot keeps its writer open on it)."""

    chunk_index: int
    file_index: int
    first_frame: int = 0  # data files: the dataset index of its first row
    to_timestamp: float = 0.0  # video files: where the next episode starts
    tables: tuple[pa.Table, ...] = ()  # data files: one table per episode (one row group each)
    rows: tuple[dict[str, Any], ...] = ()  # episode files: their rows


@dataclass
class _Plan:
    """A commit's files: new contents written beside their final names, and files moved in whole."""

    writes: list[tuple[str, Callable[[Path], None]]]
    moves: list[tuple[Path, str]]


class DatasetWriter:
    """Adds episodes to a LeRobot v3.0 dataset (creating it), one saved episode at a time.

    One writer per dataset: it holds the dataset folder's lock while it lives (close() or the
    process's end releases it). Saves are serialised; episodes may be recorded while one saves."""

    def __init__(self, root: Path, lock_fd: int, info: dict[str, Any], tasks: list[str],
                 rows: list[dict[str, Any]], stats: Stats | None, image_size: tuple[int, int] | None):
        self.root = root
        self._lock_fd: int | None = lock_fd
        self._info = info
        self.fps: int = int(info["fps"])
        self.image_size = image_size
        self.features: dict[str, dict[str, Any]] = info["features"]
        self._tasks = tasks
        self._stats = stats
        self.episodes: list[EpisodeSummary] = [_summary(row, self.fps) for row in rows]
        self._last_row: dict[str, Any] | None = rows[-1] if rows else None
        self._data_file: _SessionFile | None = None
        self._video_file: _SessionFile | None = None
        self._episodes_file: _SessionFile | None = None
        self._data_schema = _data_schema(self.features)
        self._episode_schema = _episode_row_schema(self.features)
        self._commit_lock = threading.Lock()
        self._work_lock = threading.Lock()
        self._work_count = 0
        self._live_episodes = 0  # started, neither saved nor discarded: the work folder stays while any is
        # Set when a save's renames failed after its journal: the files are between two states until
        # the next open completes them, so this writer saves nothing more.
        self._incomplete: str | None = None

    # -- opening -----------------------------------------------------------------------------
    @classmethod
    def open(cls, root: Path, fps: int, image_size: tuple[int, int] | None, *,
             chunks_size: int = DEFAULT_CHUNK_SIZE, data_files_size_in_mb: float = DEFAULT_DATA_FILE_SIZE_IN_MB,
             video_files_size_in_mb: float = DEFAULT_VIDEO_FILE_SIZE_IN_MB) -> "DatasetWriter":
        """Open `root` to add episodes: creates the dataset if the folder is new or empty.

        image_size: (width, height) of the video, or None for a dataset without video. The size
        limits and chunks_size apply to a dataset created here (an existing one keeps its own)."""
        root = Path(root)
        if not isinstance(fps, int) or isinstance(fps, bool) or fps <= 0:
            raise DatasetError(f"fps {fps!r} is not a frame rate: use a whole number above 0, e.g. 30")
        if image_size is not None and (len(image_size) != 2 or min(image_size) <= 0 or any(s % 2 for s in image_size)):
            raise DatasetError(f"image size {image_size!r} cannot be stored as video: use even width and height above 0 "
                               "(yuv420p halves them), e.g. (320, 240)")
        if root.exists() and not root.is_dir():
            raise DatasetError(f"{root} is a file: give a new or empty folder, or a LeRobot v3.0 dataset folder")
        try:
            root.mkdir(parents=True, exist_ok=True)
            lock_fd = cls._lock(root)
        except OSError as error:
            raise DatasetError(f"cannot open {root}: {_one_line_os_error(error)}") from None
        try:
            return cls._open_locked(root, lock_fd, fps, image_size, chunks_size, data_files_size_in_mb,
                                    video_files_size_in_mb)
        except BaseException:
            os.close(lock_fd)
            raise

    @staticmethod
    def _lock(root: Path) -> int:
        deadline = time.monotonic() + LOCK_WAIT_S
        while True:
            fd = _try_lock(root)
            if fd is not None:
                return fd
            if time.monotonic() > deadline:
                raise DatasetError(f"another recorder is writing to {root}: stop it first, or use another folder")
            time.sleep(0.05)

    @classmethod
    def _open_locked(cls, root: Path, lock_fd: int, fps: int, image_size: tuple[int, int] | None,
                     chunks_size: int, data_mb: float, video_mb: float) -> "DatasetWriter":
        want = recorder_features(image_size)
        try:
            if not (root / INFO_PATH).exists():
                if any(not _is_ours(entry.name) for entry in root.iterdir()):
                    raise DatasetError(f"{root} is not empty and is not a LeRobot dataset (no {INFO_PATH}): "
                                       "give a new or empty folder, or a LeRobot v3.0 dataset folder")
                info: dict[str, Any] = {
                    "codebase_version": CODEBASE_VERSION, "robot_type": ROBOT_TYPE,
                    "total_episodes": 0, "total_frames": 0, "total_tasks": 0,
                    "chunks_size": chunks_size, "data_files_size_in_mb": data_mb, "video_files_size_in_mb": video_mb,
                    "fps": fps, "splits": {}, "data_path": DATA_PATH,
                    "video_path": VIDEO_PATH if image_size is not None else None, "features": want,
                }
                (root / "meta").mkdir(exist_ok=True)
                temp = root / (INFO_PATH + TEMP_SUFFIX)
                _write_json(temp, info)
                _fsync_path(temp)
                os.replace(temp, root / INFO_PATH)
                _fsync_path(root / "meta")
                _fsync_path(root)
                return cls(root, lock_fd, info, [], [], None, image_size)
            info = _load_info(root)
            _recover(root)
            if int(info["fps"]) != fps:
                raise DatasetError(f"{root} is recorded at {info['fps']} fps, not {fps}: record at {info['fps']} fps, "
                                   "or use another folder")
            if not _same_features(info["features"], want):
                raise DatasetError(_feature_difference(root, info["features"], want, image_size))
            tasks = _read_tasks(root) if (root / TASKS_PATH).exists() else []
            rows = _read_episode_rows(root) if (root / EPISODES_DIR).is_dir() else []
            stats = (stats_from_json(json.loads((root / STATS_PATH).read_text(encoding="utf-8")))
                     if (root / STATS_PATH).exists() else None)
        except OSError as error:
            raise DatasetError(f"cannot open {root}: {_one_line_os_error(error)}") from None
        except (pa.ArrowException, ValueError) as error:
            if isinstance(error, DatasetError):
                raise
            raise DatasetError(f"{root} cannot be read as a LeRobot v3.0 dataset: {error}") from None
        return cls(root, lock_fd, info, tasks, rows, stats, image_size)

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

    def start_episode(self, task: str) -> "EpisodeRecorder":
        """A new episode of `task` (its text, e.g. "put the cube in the box")."""
        if self._lock_fd is None:
            raise DatasetError(f"the writer of {self.root} is closed: open it again")
        if not isinstance(task, str) or not task.strip():
            raise DatasetError("an episode needs a task text, e.g. 'put the cube in the box'")
        encoder = None
        if self.image_size is not None:
            with self._work_lock:
                try:
                    (self.root / WORK_DIR).mkdir(exist_ok=True)
                except OSError as error:
                    raise DatasetError(f"cannot record into {self.root}: {_one_line_os_error(error)}") from None
                self._work_count += 1
                self._live_episodes += 1
                name = f"episode-{os.getpid()}-{self._work_count}.mp4"
            width, height = self.image_size
            encoder = videos.StreamingEncoder(self.root / WORK_DIR / name, self.fps, width, height,
                                              inspect=image_histogram)
        return EpisodeRecorder(self, task.strip(), encoder)

    def _episode_ended(self) -> None:
        """An episode with video was saved or dropped: the work folder goes when no other is recording."""
        with self._work_lock:
            self._live_episodes -= 1
            if self._live_episodes == 0:
                try:
                    (self.root / WORK_DIR).rmdir()
                except OSError:
                    pass  # already gone

    # -- a commit ----------------------------------------------------------------------------
    def _commit(self, task: str, states: Float32Array, actions: Float32Array,
                encoded: videos.EncodedVideo | None) -> EpisodeSummary:
        with self._commit_lock:
            if self._lock_fd is None:
                raise DatasetError(f"the writer of {self.root} is closed: the episode is not saved")
            if self._incomplete is not None:
                raise DatasetError(f"the episode is not saved: an earlier save is still to be completed "
                                   f"({self._incomplete}); open {self.root} again")
            length = len(states)
            episode_index = len(self.episodes)
            first_frame = self.total_frames
            tasks = list(self._tasks)
            if task not in tasks:
                tasks.append(task)
            task_index = tasks.index(task)

            frame_index = np.arange(length, dtype=np.int64)
            columns: dict[str, np.ndarray] = {
                ACTION_KEY: actions, STATE_KEY: states,
                "timestamp": (frame_index / self.fps).astype(np.float32),
                "frame_index": frame_index,
                "episode_index": np.full(length, episode_index, dtype=np.int64),
                "index": np.arange(first_frame, first_frame + length, dtype=np.int64),
                "task_index": np.full(length, task_index, dtype=np.int64),
            }
            table = pa.table({key: (pa.FixedSizeListArray.from_arrays(pa.array(values.ravel()), values.shape[1])
                                    if values.ndim == 2 else pa.array(values))
                              for key, values in columns.items()}, schema=self._data_schema)

            # Statistics: LeRobot's timestamps are Python floats (float64) when it computes them.
            stats_input = {**columns, "timestamp": frame_index / self.fps}
            episode_stats: Stats = {}
            for key, feature in self.features.items():
                if feature["dtype"] == "video":
                    assert encoded is not None
                    episode_stats[key] = image_stats(encoded.inspected)
                elif key in stats_input:
                    episode_stats[key] = vector_stats(stats_input[key])
            new_stats = aggregate_stats([self._stats, episode_stats]) if self._stats is not None else episode_stats

            plan = _Plan([], [])
            chunks_size = int(self._info["chunks_size"])
            row: dict[str, Any] = {"episode_index": episode_index, "tasks": [task], "length": length}

            data_file = self._place_data(length, chunks_size, table)
            row.update({"data/chunk_index": data_file.chunk_index, "data/file_index": data_file.file_index,
                        "dataset_from_index": first_frame, "dataset_to_index": first_frame + length})
            data_tables = data_file.tables
            schema = self._data_schema
            plan.writes.append((DATA_PATH.format(chunk_index=data_file.chunk_index, file_index=data_file.file_index),
                                lambda path: _write_tables(path, schema, data_tables)))

            video_file: _SessionFile | None = None
            info = json.loads(json.dumps(self._info))
            if encoded is not None:
                video_file, from_s = self._place_video(encoded, chunks_size, plan)
                row.update({f"videos/{IMAGE_KEY}/chunk_index": video_file.chunk_index,
                            f"videos/{IMAGE_KEY}/file_index": video_file.file_index,
                            f"videos/{IMAGE_KEY}/from_timestamp": from_s,
                            f"videos/{IMAGE_KEY}/to_timestamp": video_file.to_timestamp})
                if episode_index == 0 and not info["features"][IMAGE_KEY].get("info"):
                    info["features"][IMAGE_KEY]["info"] = videos.video_info(encoded.path)

            for key, feature_stats in episode_stats.items():
                for stat in STAT_KEYS:
                    row[f"stats/{key}/{stat}"] = feature_stats[stat].tolist()
            episodes_file = self._place_episode_row(row, length, chunks_size)
            episode_rows = episodes_file.rows
            episode_schema = self._episode_schema
            plan.writes.append((EPISODES_PATH.format(chunk_index=episodes_file.chunk_index,
                                                     file_index=episodes_file.file_index),
                                lambda path: pq.write_table(pa.Table.from_pylist(list(episode_rows), schema=episode_schema),
                                                            path, compression="snappy", use_dictionary=True)))
            if len(tasks) != len(self._tasks):
                plan.writes.append((TASKS_PATH, lambda path: pq.write_table(_tasks_table(tasks), path)))

            info["total_episodes"] = episode_index + 1
            info["total_frames"] = first_frame + length
            info["total_tasks"] = len(tasks)
            info["splits"] = {"train": f"0:{episode_index + 1}"}
            plan.writes.append((INFO_PATH, lambda path: _write_json(path, info)))
            plan.writes.append((STATS_PATH, lambda path: _write_json(path, stats_to_json(new_stats))))

            self._apply(plan, episode_index)

            # Committed: the writer's view follows the files.
            self._info, self._tasks, self._stats = info, tasks, new_stats
            self._data_file, self._episodes_file = data_file, episodes_file
            if video_file is not None:
                self._video_file = video_file
            self._last_row = row
            summary = EpisodeSummary(episode_index, length, (task,), length / self.fps)
            self.episodes = [*self.episodes, summary]  # a new list: readers in other threads see whole ones
            return summary

    def _unused(self, template: str, chunk: int, file: int, chunks_size: int) -> tuple[int, int]:
        """(chunk, file) or the first file after it that does not exist: a new file never replaces one
        (a file no episode row names, left by a crashed LeRobot session, is kept)."""
        while (self.root / template.format(chunk_index=chunk, file_index=file)).exists():
            chunk, file = _next_file(chunk, file, chunks_size)
        return chunk, file

    def _place_data(self, length: int, chunks_size: int, table: pa.Table) -> _SessionFile:
        """The data file the episode goes to, with its tables (LeRobot's _save_episode_data rules)."""
        current = self._data_file
        first_frame = self.total_frames
        if current is not None:
            path = self.root / DATA_PATH.format(chunk_index=current.chunk_index, file_index=current.file_index)
            size_mb = _size_mb(path)
            frames_in_file = first_frame - current.first_frame
            per_frame_mb = size_mb / frames_in_file if frames_in_file > 0 else 0.0
            if size_mb + per_frame_mb * length < float(self._info["data_files_size_in_mb"]):
                return _SessionFile(current.chunk_index, current.file_index, current.first_frame,
                                    tables=(*current.tables, table))
            chunk, file = _next_file(current.chunk_index, current.file_index, chunks_size)
        elif self._last_row is not None:  # resuming: LeRobot moves on to the next file
            chunk, file = _next_file(int(self._last_row["data/chunk_index"]), int(self._last_row["data/file_index"]),
                                     chunks_size)
        else:
            chunk, file = 0, 0
        chunk, file = self._unused(DATA_PATH, chunk, file, chunks_size)
        return _SessionFile(chunk, file, first_frame, tables=(table,))

    def _place_video(self, encoded: videos.EncodedVideo, chunks_size: int,
                     plan: _Plan) -> tuple[_SessionFile, float]:
        """Where the episode's video goes (LeRobot's _save_episode_video rules); adds the file to the
        plan and returns the file and the episode's from_timestamp in it."""
        current = self._video_file
        key = f"videos/{IMAGE_KEY}"
        if current is not None:
            current_path = self.root / VIDEO_PATH.format(video_key=IMAGE_KEY, chunk_index=current.chunk_index,
                                                          file_index=current.file_index)
            if _size_mb(current_path) + _size_mb(encoded.path) < float(self._info["video_files_size_in_mb"]):
                from_s = current.to_timestamp
                episode_path = encoded.path
                plan.writes.append((str(current_path.relative_to(self.root)),
                                    lambda path: _concatenate(current_path, episode_path, path)))
                return _SessionFile(current.chunk_index, current.file_index,
                                    to_timestamp=from_s + encoded.duration_s), from_s
            chunk, file = _next_file(current.chunk_index, current.file_index, chunks_size)
        elif self._last_row is not None and f"{key}/chunk_index" in self._last_row:
            chunk, file = _next_file(int(self._last_row[f"{key}/chunk_index"]),
                                     int(self._last_row[f"{key}/file_index"]), chunks_size)
        else:
            chunk, file = 0, 0
        chunk, file = self._unused(VIDEO_PATH.replace("{video_key}", IMAGE_KEY), chunk, file, chunks_size)
        plan.moves.append((encoded.path, VIDEO_PATH.format(video_key=IMAGE_KEY, chunk_index=chunk, file_index=file)))
        return _SessionFile(chunk, file, to_timestamp=encoded.duration_s), 0.0

    def _place_episode_row(self, row: dict[str, Any], length: int, chunks_size: int) -> _SessionFile:
        """The meta/episodes file the row goes to (LeRobot's _save_episode_metadata rules)."""
        current = self._episodes_file
        if current is not None:
            path = self.root / EPISODES_PATH.format(chunk_index=current.chunk_index, file_index=current.file_index)
            size_mb = _size_mb(path)
            # LeRobot divides by the latest episode's index here, not by a frame count: its rule, kept.
            latest_index = int(current.rows[-1]["episode_index"])
            per_frame_mb = size_mb / latest_index if latest_index > 0 else 0.0
            if size_mb + per_frame_mb * length < float(self._info["data_files_size_in_mb"]):
                row.update({"meta/episodes/chunk_index": current.chunk_index,
                            "meta/episodes/file_index": current.file_index})
                return _SessionFile(current.chunk_index, current.file_index, rows=(*current.rows, row))
            chunk, file = _next_file(current.chunk_index, current.file_index, chunks_size)
        elif self._last_row is not None:
            chunk, file = _next_file(int(self._last_row["meta/episodes/chunk_index"]),
                                     int(self._last_row["meta/episodes/file_index"]), chunks_size)
        else:
            chunk, file = 0, 0
        chunk, file = self._unused(EPISODES_PATH, chunk, file, chunks_size)
        row.update({"meta/episodes/chunk_index": chunk, "meta/episodes/file_index": file})
        return _SessionFile(chunk, file, rows=(row,))

    def _apply(self, plan: _Plan, episode_index: int) -> None:
        """Write the plan's files beside their final names, fsync, journal, rename (see the module's doc)."""
        temps: list[Path] = []
        created: list[Path] = []
        journal = self.root / JOURNAL_PATH
        journal_temp = self.root / (JOURNAL_PATH + TEMP_SUFFIX)
        renames: list[tuple[str, str]] = []
        try:
            for final, write in plan.writes:
                final_path = self.root / final
                created += _make_folders(final_path.parent)
                temp = final_path.with_name(final_path.name + TEMP_SUFFIX)
                temps.append(temp)
                write(temp)
                _fsync_path(temp)
                renames.append((str(temp.relative_to(self.root)), final))
            for source, final in plan.moves:
                created += _make_folders((self.root / final).parent)
                _fsync_path(source)
                renames.append((str(source.relative_to(self.root)), final))
            for folder in {(self.root / name).parent for name, _ in renames} | {p.parent for p in created}:
                _fsync_path(folder)
            temps.append(journal_temp)
            _write_json(journal_temp, {"renames": renames})
            _fsync_path(journal_temp)
            os.replace(journal_temp, journal)
            _fsync_path(journal.parent)
        except BaseException as error:
            # Not committed: remove every trace, the dataset stays exactly as it was.
            journal.unlink(missing_ok=True)
            for temp in temps:
                temp.unlink(missing_ok=True)
            for folder in reversed(created):
                try:
                    folder.rmdir()
                except OSError:
                    pass
            if not isinstance(error, (OSError, videos.VideoWriteError)):
                raise
            reason = _one_line_os_error(error) if isinstance(error, OSError) else str(error)
            raise DatasetError(f"episode {episode_index} is not saved: {reason}; "
                               f"the dataset in {self.root} is as it was") from None
        try:
            with _flock(self.root / "meta", fcntl.LOCK_EX):
                _roll_forward(self.root, renames)
        except OSError as error:
            # The journal is whole: the next open completes these renames.
            self._incomplete = _one_line_os_error(error)
            raise _CommitIncomplete(f"episode {episode_index} is saved but not yet in place ({self._incomplete}): "
                                    f"it is completed when {self.root} is next opened") from None


def _make_folders(folder: Path) -> list[Path]:
    """mkdir -p, returning the folders it made (outermost first)."""
    missing: list[Path] = []
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    for path in reversed(missing):
        path.mkdir()
    return list(reversed(missing))


def _write_tables(path: Path, schema: pa.Schema, tables: tuple[pa.Table, ...]) -> None:
    # One row group per episode, as LeRobot's ParquetWriter.write_table per episode makes it.
    with pq.ParquetWriter(path, schema=schema, compression="snappy", use_dictionary=True) as writer:
        for table in tables:
            writer.write_table(table)


def _concatenate(current: Path, episode: Path, output: Path) -> None:
    try:
        videos.concatenate([current, episode], output)
    except videos.av.FFmpegError as error:  # PyAV's own errors (a full disk among them)
        raise videos.VideoWriteError(videos.one_line(error)) from error


class EpisodeRecorder:
    """One episode being recorded: its rows in memory, its video encoding as frames come."""

    def __init__(self, writer: DatasetWriter, task: str, encoder: videos.StreamingEncoder | None):
        self._writer = writer
        self.task = task
        self._encoder = encoder
        self._states: list[Float32Array] = []
        self._actions: list[Float32Array] = []
        self._encoded: videos.EncodedVideo | None = None
        self._saved: EpisodeSummary | None = None
        self._discarded = False
        self._lock = threading.Lock()
        self._size = (len(MOTOR_NAMES),)
        self.frames = 0  # frames added so far


    def add_frame(self, state: np.ndarray, action: np.ndarray, image: np.ndarray | None = None) -> None:
        """One frame: state and action float32[6] in LeRobot's units (features.to_lerobot), and the
        picture (height, width, 3) uint8 when the dataset has video."""
        if self._saved is not None or self._discarded:
            raise DatasetError("this episode is already " + ("saved" if self._saved else "discarded")
                               + ": start a new one to add frames")
        state_row = self._vector(state, "state")
        action_row = self._vector(action, "action")
        if self._encoder is not None:
            if image is None:
                raise DatasetError("this dataset has video: every frame needs its picture")
            if image.dtype != np.uint8 or image.shape != (self._encoder.height, self._encoder.width, 3):
                raise DatasetError(f"a picture of shape {image.shape} {image.dtype} cannot be stored: this dataset's "
                                   f"video takes ({self._encoder.height}, {self._encoder.width}, 3) uint8 (RGB)")
            self._encoder.add(image)
        elif image is not None:
            raise DatasetError("this dataset has no video: give no picture (open it with an image size for video)")
        self._states.append(state_row)
        self._actions.append(action_row)
        self.frames += 1

    def _vector(self, values: np.ndarray, what: str) -> Float32Array:
        row = np.asarray(values, dtype=np.float32)
        if row.shape != self._size:
            raise DatasetError(f"the {what} has shape {row.shape}: it must be {len(MOTOR_NAMES)} values "
                               f"({', '.join(MOTOR_NAMES)})")
        return np.array(row, copy=True)

    def save(self) -> EpisodeSummary:
        """Commit the episode to the dataset: may take seconds (the video is joined to the file's);
        safe in a background thread. A failure (a full disk...) leaves the dataset as it was."""
        with self._lock:
            if self._saved is not None:
                return self._saved
            if self._discarded:
                raise DatasetError("this episode was discarded: it cannot be saved")
            if not self._states:
                raise DatasetError("an episode of 0 frames is not saved: add frames first, or discard it")
            if self._encoder is not None and self._encoded is None:
                try:
                    self._encoded = self._encoder.finish()
                except videos.VideoWriteError as error:
                    self._discard_video()
                    self._discarded = True
                    raise DatasetError(f"the episode's video could not be written ({error}): the episode is not "
                                       "saved") from None
                if self._encoded.frames != len(self._states):
                    raise DatasetError(f"the episode's video has {self._encoded.frames} frames for "
                                       f"{len(self._states)} rows: the episode is not saved")
            try:
                self._saved = self._writer._commit(self.task, np.stack(self._states), np.stack(self._actions),
                                                   self._encoded)
            except _CommitIncomplete:
                # Its video may still be in the work folder, named by the journal: keep it for the next open.
                self._discarded = True
                raise
            if self._encoded is not None:
                self._encoded.path.unlink(missing_ok=True)  # joined into the dataset's file, or moved there
                self._writer._episode_ended()
            self._states, self._actions = [], []  # the rows are in the dataset now
            return self._saved

    def discard(self) -> None:
        """Drop the episode: nothing of it stays on disk."""
        with self._lock:
            if self._saved is not None or self._discarded:
                return
            self._discarded = True
            self._discard_video()
            self._states, self._actions = [], []

    def _discard_video(self) -> None:
        if self._encoded is not None:
            self._encoded.path.unlink(missing_ok=True)
        elif self._encoder is not None:
            self._encoder.cancel()
        if self._encoder is not None:
            self._writer._episode_ended()
