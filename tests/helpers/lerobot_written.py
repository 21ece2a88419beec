"""A LeRobotDataset v3.0 written the way LeRobot 0.4.x writes one, by code of its own.

This is a test fixture: it does not import the project's writer (so101.dataset.writer), so a
test that reads its output with the project's reader checks the reader against LeRobot's format,
not against the project's own idea of it. It needs only numpy, pyarrow and PyAV (no pandas, no
`datasets`, no torch). Read from LeRobot 0.4.0-0.4.4 (src/lerobot/datasets/, identical in what
follows) and checked against datasets that LeRobot 0.4.4 wrote itself (tests/data/lerobot_made/):

* Layout and names: utils.py `DEFAULT_DATA_PATH`, `DEFAULT_VIDEO_PATH`, `DEFAULT_EPISODES_PATH`,
  `DEFAULT_TASKS_PATH`, `INFO_PATH`, `STATS_PATH` (chunk-{:03d}/file-{:03d}); the next file after
  (chunk, file) is utils.py `update_chunk_file_indices` (file+1, or the next chunk's file 0 after
  `chunks_size` files). An episode is never split across files.
* meta/info.json: utils.py `create_empty_dataset_info` (its keys in its order), features =
  user features then `DEFAULT_FEATURES` (lerobot_dataset.py `LeRobotDatasetMetadata.create`), the
  feature order of lerobot_record.py (action, observation.state, observation.images.*);
  `LeRobotDatasetMetadata.save_episode` updates total_episodes/frames/tasks and splits
  {"train": "0:N"}; a video feature gets "info" from video_utils.py `get_video_info` of
  chunk-000/file-000.mp4 (`update_video_info`); `write_json` indents 4, ensure_ascii=False.
* data/*.parquet: lerobot_dataset.py `_save_episode_data`: one HF `datasets` table per episode
  (features from utils.py `get_hf_features_from_features`: 1-d vectors are fixed-size lists,
  shape (1,) are scalars, video keys are left out) appended as one row group to a
  `pq.ParquetWriter(compression="snappy", use_dictionary=True)`; the schema carries the
  "huggingface" metadata that `datasets`' ArrowWriter puts there ({"info": {"features": ...},
  "fingerprint": ...}, features as `datasets` 4.x serialises them: "List"/"Value").
  `add_frame` sets timestamp = frame_index / fps; `save_episode` sets index (global),
  episode_index and task_index.
* meta/episodes/*.parquet: `LeRobotDatasetMetadata.save_episode` / `_save_episode_metadata` /
  `_flush_metadata_buffer`: one row per episode, columns episode_index, tasks, length, then
  `_save_episode_data`'s data/chunk_index, data/file_index, dataset_from_index, dataset_to_index,
  then `_save_episode_video`'s videos/<key>/chunk_index, file_index, from_timestamp, to_timestamp,
  then utils.py `flatten_dict({"stats": ep_stats})`, then meta/episodes/chunk_index, file_index;
  rows buffered `metadata_buffer_size` (10) at a time into `pa.Table.from_pydict` (so numpy
  values become python lists: stats are list<double>/list<int64>, image stats 3-deep lists) and
  written as row groups by a ParquetWriter like the data's. No pandas or HF metadata here.
* Per-episode stats: compute_stats.py `compute_episode_stats`, `get_feature_stats`,
  `RunningQuantileStats` (min, max, mean, std, count, q01, q10, q50, q90, q99; quantiles from
  5000-bin histograms), images sampled by `sample_images`/`sample_indices` and reduced per
  channel to shape (3, 1, 1) scaled by 1/255. It is done with the same numpy operations on the
  same dtypes (float32 vectors, float64 timestamps before the float32 cast, int64 indices, uint8
  pixels, whose squares overflow in LeRobot too), so the values match LeRobot's.
* meta/stats.json: `save_episode` folds each episode in with compute_stats.py `aggregate_stats`
  ([dataset so far, episode]); utils.py `write_stats`/`serialize_dict`. (LeRobot's key order
  comes from a set, so it varies; here it is the features' order.)
* meta/tasks.parquet: `save_episode_tasks` + utils.py `write_tasks`: a pandas DataFrame
  {"task_index": int64} indexed by the task strings, `to_parquet` -> columns task_index,
  __index_level_0__ and the "pandas" schema metadata, reproduced here without pandas
  (as pandas 2.x with pyarrow writes it). Task indices in order of first appearance.
* videos/<key>/*.mp4: video_utils.py `encode_video_frames` (PyAV, libsvtav1, yuv420p, g=2,
  crf=30, preset=12, one temporary mp4 per episode), then lerobot_dataset.py
  `_save_episode_video`: the first episode of a file is moved there, later ones are appended
  with video_utils.py `concatenate_video_files` (ffconcat demuxer, stream copy, faststart);
  from_timestamp is the previous to_timestamp in that file (0.0 in a new file), to_timestamp
  adds `get_video_duration_in_s` of the episode's own mp4 (stream.duration * time_base).

LeRobot starts a new data/video/episodes file when a size limit in MB would be reached; here the
caller chooses by frames or episodes instead (frames_per_data_file, frames_per_video_file,
episodes_per_meta_file), so that tests can spread a few tiny episodes over several files and
chunks, as LeRobot does with big ones.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import tempfile
from collections.abc import Iterator
from fractions import Fraction
from pathlib import Path
from typing import Any

import av
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

CODEBASE_VERSION = "v3.0"
DEFAULT_CHUNK_SIZE = 1000
DEFAULT_DATA_FILE_SIZE_IN_MB = 100
DEFAULT_VIDEO_FILE_SIZE_IN_MB = 200  # 500 in LeRobot 0.4.0, 200 from 0.4.1 on
DEFAULT_METADATA_BUFFER_SIZE = 10
CHUNK_FILE_PATTERN = "chunk-{chunk_index:03d}/file-{file_index:03d}"
DATA_PATH = "data/" + CHUNK_FILE_PATTERN + ".parquet"
VIDEO_PATH = "videos/{video_key}/" + CHUNK_FILE_PATTERN + ".mp4"
EPISODES_PATH = "meta/episodes/" + CHUNK_FILE_PATTERN + ".parquet"
IMAGE_KEY = "observation.images.front"
MOTOR_NAMES = [f"{joint}.pos" for joint in ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")]
DEFAULT_FEATURES = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
QUANTILE_BINS = 5000
# LeRobot's default encoder and its options (video_utils.py `encode_video_frames`, `_get_codec_options`).
VCODEC = "libsvtav1"
CODEC_OPTIONS = {"libsvtav1": {"g": "2", "crf": "30", "preset": "12"}, "h264": {"g": "2", "crf": "30"}}


# -- stats: compute_stats.py ------------------------------------------------------------------


def _running_quantile_stats(batch: np.ndarray) -> dict[str, np.ndarray]:
    """`RunningQuantileStats().update(batch); get_statistics()` for one batch (rows = samples)."""
    batch = batch.reshape(-1, batch.shape[-1])
    count, width = batch.shape
    mean = np.mean(batch, axis=0)
    mean_of_squares = np.mean(batch**2, axis=0)
    low, high = np.min(batch, axis=0), np.max(batch, axis=0)
    edges = [np.linspace(low[i] - 1e-10, high[i] + 1e-10, QUANTILE_BINS + 1) for i in range(width)]
    # The running update of a first batch: adds (batch_mean - mean) * 1, i.e. zero, in mean's dtype.
    mean += (np.mean(batch, axis=0) - mean) * (count / count)
    mean_of_squares += (np.mean(batch**2, axis=0) - mean_of_squares) * (count / count)
    hists = [np.zeros(QUANTILE_BINS) + np.histogram(batch[:, i], bins=edges[i])[0] for i in range(width)]
    stats = {
        "min": low.copy(),
        "max": high.copy(),
        "mean": mean.copy(),
        "std": np.sqrt(np.maximum(0, mean_of_squares - mean**2)),
        "count": np.array([count]),
    }
    for q in QUANTILES:
        target = q * count
        values = []
        for hist, edge in zip(hists, edges):
            cumsum = np.cumsum(hist)
            idx = np.searchsorted(cumsum, target)
            if idx == 0:
                values.append(edge[0])
            elif idx >= len(cumsum):
                values.append(edge[-1])
            else:
                before = cumsum[idx - 1]
                in_bin = cumsum[idx] - before
                values.append(edge[idx] if in_bin == 0 else edge[idx] + (target - before) / in_bin * (edge[idx + 1] - edge[idx]))
        stats[f"q{int(q * 100):02d}"] = np.array(values)
    return stats


def _feature_stats(array: np.ndarray, image: bool) -> dict[str, np.ndarray]:
    """`get_feature_stats` as `compute_episode_stats` calls it: per channel for images (N,C,H,W),
    per dimension for (L, D) vectors, and shape-(1,) stats for (L,) scalars."""
    if image:
        n, channels = array.shape[0], array.shape[1]
        rows, sample_count = array.transpose(0, 2, 3, 1).reshape(-1, channels), n
    else:
        rows, sample_count = (array.reshape(-1, 1) if array.ndim == 1 else array), array.shape[0]
    if rows.shape[0] < 2:
        stats = {"min": np.min(rows, axis=0), "max": np.max(rows, axis=0), "mean": np.mean(rows, axis=0), "std": np.std(rows, axis=0)}
        stats["count"] = np.array([sample_count])
        for q in QUANTILES:
            stats[f"q{int(q * 100):02d}"] = stats["mean"].copy()
    else:
        stats = _running_quantile_stats(rows)
        stats["count"] = np.array([sample_count])
    if image:  # (C,) -> (1, C, 1, 1) -> / 255 -> (C, 1, 1)
        return {k: v if k == "count" else np.squeeze(v.reshape(1, -1, 1, 1) / 255.0, axis=0) for k, v in stats.items()}
    if array.ndim == 1:
        return {k: v if k == "count" else v.reshape(1) for k, v in stats.items()}
    return stats


def _sample_images(frames: np.ndarray) -> np.ndarray:
    """`sample_images`: up to 100 evenly spread frames (for short episodes, all) as (N, C, H, W)
    uint8, each downsampled by an integer step if its larger side is 300 or more."""
    length = len(frames)
    num = max(min(length, 100), min(int(length**0.75), 10_000))
    indices = np.round(np.linspace(0, length - 1, num)).astype(int).tolist()
    images = frames[indices].transpose(0, 3, 1, 2)
    height, width = images.shape[2:]
    if max(width, height) >= 300:
        step = int(width / 150) if width > height else int(height / 150)
        images = images[:, :, ::step, ::step]
    return np.ascontiguousarray(images)


def _aggregate(stats_list: list[dict[str, dict[str, np.ndarray]]]) -> dict[str, dict[str, np.ndarray]]:
    """compute_stats.py `aggregate_stats` (count-weighted means, variances and quantiles)."""
    keys = [key for stats in stats_list for key in stats]
    out: dict[str, dict[str, np.ndarray]] = {}
    for key in dict.fromkeys(keys):
        fts = [stats[key] for stats in stats_list if key in stats]
        means = np.stack([s["mean"] for s in fts])
        variances = np.stack([s["std"] ** 2 for s in fts])
        counts = np.stack([s["count"] for s in fts])
        total = counts.sum(axis=0)
        while counts.ndim < means.ndim:
            counts = np.expand_dims(counts, axis=-1)
        total_mean = (means * counts).sum(axis=0) / total
        total_var = ((variances + (means - total_mean) ** 2) * counts).sum(axis=0) / total
        agg = {
            "min": np.min(np.stack([s["min"] for s in fts]), axis=0),
            "max": np.max(np.stack([s["max"] for s in fts]), axis=0),
            "mean": total_mean,
            "std": np.sqrt(total_var),
            "count": total,
        }
        for q_key in [k for k in fts[0] if k.startswith("q") and k[1:].isdigit()]:
            if all(q_key in s for s in fts):
                agg[q_key] = (np.stack([s[q_key] for s in fts]) * counts).sum(axis=0) / total
        out[key] = agg
    return out


def _to_python(value: Any) -> Any:
    return value.tolist() if isinstance(value, np.ndarray) else value


# -- videos: video_utils.py -------------------------------------------------------------------


def video_codec() -> str:
    """LeRobot's default encoder if this PyAV has it, else h264 (LeRobot decodes either)."""
    for name in (VCODEC, "h264"):
        try:
            av.codec.Codec(name, "w")
            return name
        except Exception:  # noqa: BLE001 - PyAV raises several kinds for a missing codec
            continue
    raise RuntimeError("PyAV has neither libsvtav1 nor h264 to encode with")


def _encode_episode_video(frames: np.ndarray, path: Path, fps: int, vcodec: str) -> None:
    """`encode_video_frames`: RGB frames -> mp4 with the codec options LeRobot uses."""
    from so101.dataset.video import _no_realtime_threads, scheduling_policy

    height, width = frames.shape[1:3]
    # Not LeRobot's, and nothing in the file changes: SVT-AV1 (as root) runs its threads at SCHED_FIFO
    # priority 99, which starved the tests running beside this one (the emulated arm, real-time
    # dataflows) for as long as it encoded. Its threads go back to this one's policy once they exist.
    policy = scheduling_policy()
    with av.open(str(path), "w") as output:
        stream = output.add_stream(vcodec, fps, options=dict(CODEC_OPTIONS.get(vcodec, {"g": "2"})))
        stream.pix_fmt = "yuv420p"
        stream.width, stream.height = width, height
        for index, frame in enumerate(frames):
            for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")):
                output.mux(packet)
            if index == 0:
                _no_realtime_threads(policy)
        for packet in stream.encode():
            output.mux(packet)
        _no_realtime_threads(policy)


def _concatenate_videos(inputs: list[Path], output_path: Path) -> None:
    """`concatenate_video_files`: the ffconcat demuxer, packets copied, moov atom first."""
    with tempfile.TemporaryDirectory() as tmp:
        listing = Path(tmp) / "list.ffconcat"
        listing.write_text("ffconcat version 1.0\n" + "".join(f"file '{p.resolve()}'\n" for p in inputs))
        joined = Path(tmp) / "joined.mp4"
        with av.open(str(listing), "r", format="concat", options={"safe": "0"}) as src, av.open(
            str(joined), "w", options={"movflags": "faststart"}
        ) as dst:
            streams = {}
            for stream in src.streams:
                if stream.type in ("video", "audio", "subtitle"):
                    streams[stream.index] = dst.add_stream_from_template(template=stream, opaque=True)
                    streams[stream.index].time_base = stream.time_base
            for packet in src.demux():
                if packet.stream.index not in streams or packet.dts is None:
                    continue
                packet.stream = streams[packet.stream.index]
                dst.mux(packet)
        shutil.move(str(joined), str(output_path))


def _video_duration_s(path: Path) -> float:
    """`get_video_duration_in_s`."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        if stream.duration is not None:
            return float(stream.duration * stream.time_base)
        return float(Fraction(container.duration, av.time_base))


def _video_info(path: Path) -> dict[str, Any]:
    """`get_video_info` (+ `get_audio_info` for a file without sound)."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        pix_fmt = stream.pix_fmt
        info = {
            "video.height": stream.height,
            "video.width": stream.width,
            "video.codec": stream.codec.canonical_name,
            "video.pix_fmt": pix_fmt,
            "video.is_depth_map": False,
            "video.fps": int(stream.base_rate),
            "video.channels": 1 if "gray" in pix_fmt else 4 if ("rgba" in pix_fmt or "yuva" in pix_fmt) else 3,
        }
        info["has_audio"] = bool(container.streams.audio)
    return info


# -- the files' fixed parts ---------------------------------------------------------------------


def _features(with_video: bool, height: int, width: int) -> dict[str, dict]:
    features: dict[str, dict] = {
        "action": {"dtype": "float32", "shape": [6], "names": list(MOTOR_NAMES)},
        "observation.state": {"dtype": "float32", "shape": [6], "names": list(MOTOR_NAMES)},
    }
    if with_video:
        features[IMAGE_KEY] = {"dtype": "video", "shape": [height, width, 3], "names": ["height", "width", "channels"]}
    return {**features, **json.loads(json.dumps(DEFAULT_FEATURES))}


def _hf_schema(features: dict[str, dict], fingerprint: str) -> pa.Schema:
    """The data files' arrow schema and its "huggingface" metadata (`get_hf_features_from_features`)."""
    fields, hf = [], {}
    for key, ft in features.items():
        if ft["dtype"] == "video":
            continue
        value_type = pa.float32() if ft["dtype"] == "float32" else pa.int64()
        if ft["shape"] == [1]:
            fields.append(pa.field(key, value_type))
            hf[key] = {"dtype": ft["dtype"], "_type": "Value"}
        else:
            fields.append(pa.field(key, pa.list_(value_type, ft["shape"][0])))
            hf[key] = {"feature": {"dtype": ft["dtype"], "_type": "Value"}, "length": ft["shape"][0], "_type": "List"}
    metadata = {"huggingface": json.dumps({"info": {"features": hf}, "fingerprint": fingerprint})}
    return pa.schema(fields, metadata=metadata)


def _write_tasks(path: Path, tasks: list[str]) -> None:
    """`write_tasks`: what `pd.DataFrame({"task_index": ...}, index=tasks).to_parquet(path)` writes."""
    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [{"name": None, "field_name": None, "pandas_type": "unicode", "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": None},
            {"name": None, "field_name": "__index_level_0__", "pandas_type": "unicode", "numpy_type": "object", "metadata": None},
        ],
        "attributes": {},
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.3.3",
    }
    schema = pa.schema([("task_index", pa.int64()), ("__index_level_0__", pa.string())], metadata={"pandas": json.dumps(pandas_meta)})
    table = pa.table({"task_index": list(range(len(tasks))), "__index_level_0__": tasks}, schema=schema)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, path, compression="snappy")


def _write_json(data: dict, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as f:
        json.dump(data, f, indent=4, ensure_ascii=False)


class _Files:
    """Which chunk/file the next episode goes to: `update_chunk_file_indices` after a limit."""

    def __init__(self, chunks_size: int, limit: int | None):
        self.chunks_size, self.limit = chunks_size, limit
        self.chunk, self.file, self.used = 0, 0, 0
        self.started = False

    def place(self, amount: int) -> tuple[int, int, bool]:
        """(chunk, file, is_new_file) for the next episode, which adds `amount` to its file."""
        new = not self.started
        if self.started and self.limit is not None and self.used + amount > self.limit:
            self.chunk, self.file = (self.chunk + 1, 0) if self.file == self.chunks_size - 1 else (self.chunk, self.file + 1)
            self.used, new = 0, True
        self.started = True
        self.used += amount
        return self.chunk, self.file, new


# -- the writer -------------------------------------------------------------------------------------


def structured_frames(length: int, seed: int = 0, width: int = 64, height: int = 48) -> np.ndarray:
    """(length, height, width, 3) uint8 pictures a video codec keeps well (about 40 dB PSNR with
    LeRobot's settings) yet tells apart frame by frame (neighbours differ, about 20 dB): a smooth
    colour gradient, and a bright square with soft edges that moves 6 px right and 3 px down a
    frame, from a start that depends on the seed."""
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    frames = np.empty((length, height, width, 3), dtype=np.uint8)
    side = max(8, min(width, height) // 3)
    blue = np.full_like(xx, 70.0 + 12 * (seed % 5))
    base = np.stack([30 + 130 * xx / max(1, width - 1), 30 + 130 * yy / max(1, height - 1), blue], axis=-1)
    for i in range(length):
        cx = side / 2 + (6 * i + 7 * seed) % max(1, width - side)
        cy = side / 2 + (3 * i + 5 * seed) % max(1, height - side)
        distance = np.maximum(np.abs(xx - cx), np.abs(yy - cy))
        weight = np.clip((side / 2 - distance) / 3 + 0.5, 0, 1)
        frames[i] = (base + 100 * weight[..., None]).round().clip(0, 255).astype(np.uint8)
    return frames


def write_lerobot_dataset(
    root: Path,
    episodes: list[dict],
    fps: int = 30,
    with_video: bool = False,
    frames_per_data_file: int | None = None,
    image_size: tuple[int, int] = (64, 48),
    *,
    frames_per_video_file: int | None = None,
    episodes_per_meta_file: int | None = None,
    chunks_size: int = DEFAULT_CHUNK_SIZE,
    robot_type: str | None = "so101_follower",
    vcodec: str | None = None,
    metadata_buffer_size: int = DEFAULT_METADATA_BUFFER_SIZE,
    data_files_size_in_mb: float = DEFAULT_DATA_FILE_SIZE_IN_MB,
    video_files_size_in_mb: float = DEFAULT_VIDEO_FILE_SIZE_IN_MB,
) -> None:
    """Write `episodes` to `root` (which must not exist yet) as LeRobot 0.4.x would record them.

    Each episode: {"task": str (or "frame_tasks": one str per frame, as LeRobot allows),
    "action": (L, 6) float32, "observation.state": (L, 6) float32, and, with video, optionally
    "images": (L, H, W, 3) uint8 (else `structured_frames` of image_size = (width, height))}.

    A data file takes episodes until the next would bring it past frames_per_data_file frames
    (None: no limit, as with LeRobot's 100 MB for small datasets); likewise
    frames_per_video_file (default: frames_per_data_file) for the mp4 files and
    episodes_per_meta_file for meta/episodes/, whose rows are written metadata_buffer_size at a
    time (row groups). After chunks_size files a new chunk begins. data_files_size_in_mb and
    video_files_size_in_mb are only recorded in info.json. vcodec: None for LeRobot's
    libsvtav1 (h264 where this PyAV lacks it).
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=False)
    width, height = image_size
    if with_video:
        given = [ep["images"] for ep in episodes if "images" in ep]
        if given:
            height, width = given[0].shape[1:3]
    features = _features(with_video, height, width)
    codec = (vcodec or video_codec()) if with_video else None
    frames_per_video_file = frames_per_data_file if frames_per_video_file is None else frames_per_video_file

    info: dict[str, Any] = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": robot_type,
        "total_episodes": 0,
        "total_frames": 0,
        "total_tasks": 0,
        "chunks_size": chunks_size,
        "data_files_size_in_mb": data_files_size_in_mb,
        "video_files_size_in_mb": video_files_size_in_mb,
        "fps": fps,
        "splits": {},
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH if with_video else None,
        "features": features,
    }
    _write_json(info, root / "meta/info.json")

    tasks: list[str] = []
    dataset_stats: dict | None = None
    data_files, video_files = _Files(chunks_size, frames_per_data_file), _Files(chunks_size, frames_per_video_file)
    meta_files = _Files(chunks_size, episodes_per_meta_file)
    data_writer: pq.ParquetWriter | None = None
    meta_writer: pq.ParquetWriter | None = None
    meta_buffer: list[dict] = []
    video_to_timestamp = 0.0
    total_frames = 0

    def flush_meta() -> None:
        nonlocal meta_writer
        if not meta_buffer:
            return
        table = pa.Table.from_pydict({key: [row[key] for row in meta_buffer] for key in meta_buffer[0]})
        if meta_writer is None:
            path = root / EPISODES_PATH.format(chunk_index=meta_buffer[0]["meta/episodes/chunk_index"], file_index=meta_buffer[0]["meta/episodes/file_index"])
            path.parent.mkdir(parents=True, exist_ok=True)
            meta_writer = pq.ParquetWriter(path, schema=table.schema, compression="snappy", use_dictionary=True)
        meta_writer.write_table(table)
        meta_buffer.clear()

    with tempfile.TemporaryDirectory() as scratch:
        for episode_index, episode in enumerate(episodes):
            action = np.asarray(episode["action"], dtype=np.float32)
            state = np.asarray(episode["observation.state"], dtype=np.float32)
            length = len(action)
            if state.shape != action.shape or action.shape[1:] != (6,) or length < 1:
                raise ValueError(f"episode {episode_index}: action and observation.state must both be (L>=1, 6)")
            # One task per frame, as `add_frame` takes them; the episode's tasks are `list(set(...))`
            # in LeRobot (an order that varies between runs), here in order of first appearance.
            frame_tasks = list(episode["frame_tasks"]) if "frame_tasks" in episode else [episode["task"]] * length
            if len(frame_tasks) != length:
                raise ValueError(f"episode {episode_index}: {len(frame_tasks)} frame_tasks for {length} frames")
            episode_tasks = list(dict.fromkeys(frame_tasks))
            new_tasks = [task for task in episode_tasks if task not in tasks]
            if new_tasks:  # `save_episode_tasks` rewrites tasks.parquet when there are new tasks
                tasks.extend(new_tasks)
                _write_tasks(root / "meta/tasks.parquet", tasks)

            # The episode buffer as `add_frame` + `save_episode` leave it (before the HF cast).
            buffer: dict[str, np.ndarray] = {"action": action, "observation.state": state}
            frames = None
            if with_video:
                frames = np.asarray(episode["images"], dtype=np.uint8) if "images" in episode else structured_frames(length, episode_index, width, height)
                if frames.shape != (length, height, width, 3):
                    raise ValueError(f"episode {episode_index}: images must be ({length}, {height}, {width}, 3), not {frames.shape}")
            buffer["timestamp"] = np.stack([i / fps for i in range(length)])
            buffer["frame_index"] = np.stack(list(range(length)))
            buffer["episode_index"] = np.full((length,), episode_index)
            buffer["index"] = np.arange(total_frames, total_frames + length)
            buffer["task_index"] = np.array([tasks.index(task) for task in frame_tasks])

            ep_stats: dict[str, dict[str, np.ndarray]] = {}
            for key in features:
                if key == IMAGE_KEY:
                    ep_stats[key] = _feature_stats(_sample_images(frames), image=True)
                else:
                    ep_stats[key] = _feature_stats(buffer[key], image=False)

            # data/: one row group per episode.
            chunk, file, new = data_files.place(length)
            if new and data_writer is not None:
                data_writer.close()
                data_writer = None
            path = root / DATA_PATH.format(chunk_index=chunk, file_index=file)
            if data_writer is None:
                fingerprint = hashlib.sha256(f"{path.relative_to(root)}".encode()).hexdigest()[:16]
                schema = _hf_schema(features, fingerprint)
                path.parent.mkdir(parents=True, exist_ok=True)
                data_writer = pq.ParquetWriter(path, schema=schema, compression="snappy", use_dictionary=True)
            columns = {key: buffer[key] for key in data_writer.schema.names}
            data_writer.write_table(
                pa.table(
                    {
                        key: (
                            pa.FixedSizeListArray.from_arrays(pa.array(v.reshape(-1).astype(np.float32)), v.shape[1])
                            if v.ndim == 2
                            else pa.array(v.astype(np.float32 if key == "timestamp" else np.int64))
                        )
                        for key, v in columns.items()
                    },
                    schema=data_writer.schema,
                )
            )
            row: dict[str, Any] = {
                "episode_index": episode_index,
                "tasks": episode_tasks,
                "length": length,
                "data/chunk_index": chunk,
                "data/file_index": file,
                "dataset_from_index": total_frames,
                "dataset_to_index": total_frames + length,
            }

            # videos/: encode the episode alone, then start a file with it or append it.
            if with_video:
                ep_path = Path(scratch) / f"{IMAGE_KEY}_{episode_index:03d}.mp4"
                _encode_episode_video(frames, ep_path, fps, codec)
                duration = _video_duration_s(ep_path)
                v_chunk, v_file, v_new = video_files.place(length)
                v_path = root / VIDEO_PATH.format(video_key=IMAGE_KEY, chunk_index=v_chunk, file_index=v_file)
                if v_new:
                    video_to_timestamp = 0.0
                    v_path.parent.mkdir(parents=True, exist_ok=True)
                    shutil.move(str(ep_path), str(v_path))
                else:
                    _concatenate_videos([v_path, ep_path], v_path)
                    ep_path.unlink()
                row[f"videos/{IMAGE_KEY}/chunk_index"] = v_chunk
                row[f"videos/{IMAGE_KEY}/file_index"] = v_file
                row[f"videos/{IMAGE_KEY}/from_timestamp"] = video_to_timestamp
                row[f"videos/{IMAGE_KEY}/to_timestamp"] = video_to_timestamp + duration
                video_to_timestamp = video_to_timestamp + duration
                if episode_index == 0:
                    features[IMAGE_KEY]["info"] = _video_info(v_path)

            for feature_key, feature_stats in ep_stats.items():
                for stat_key, value in feature_stats.items():
                    row[f"stats/{feature_key}/{stat_key}"] = _to_python(value)

            # meta/episodes/: buffered rows, a new file when the caller's limit is reached.
            m_chunk, m_file, m_new = meta_files.place(1)
            if m_new:  # the rows still buffered belong to the file before
                flush_meta()
                if meta_writer is not None:
                    meta_writer.close()
                    meta_writer = None
            row["meta/episodes/chunk_index"] = m_chunk
            row["meta/episodes/file_index"] = m_file
            meta_buffer.append(row)
            if len(meta_buffer) >= metadata_buffer_size:
                flush_meta()

            total_frames += length
            info["total_episodes"] = episode_index + 1
            info["total_frames"] = total_frames
            info["total_tasks"] = len(tasks)
            info["splits"] = {"train": f"0:{info['total_episodes']}"}
            _write_json(info, root / "meta/info.json")
            dataset_stats = ep_stats if dataset_stats is None else _aggregate([dataset_stats, ep_stats])
            _write_json({k: {s: _to_python(v) for s, v in st.items()} for k, st in dataset_stats.items()}, root / "meta/stats.json")

    # `finalize`: close the writers (the parquet footers are written then).
    if data_writer is not None:
        data_writer.close()
    flush_meta()
    if meta_writer is not None:
        meta_writer.close()


# -- reading back, for tests ---------------------------------------------------------------------


def dataset_files(root: Path) -> list[str]:
    """The dataset's files (meta/, data/, videos/), relative and sorted."""
    root = Path(root)
    return sorted(str(p.relative_to(root)) for part in ("meta", "data", "videos") for p in (root / part).rglob("*") if p.is_file())


def parquet_columns(path: Path) -> list[tuple[str, str]]:
    """(name, arrow type) of each column of a parquet file."""
    return [(field.name, str(field.type)) for field in pq.read_schema(path)]


def decode_frames(path: Path) -> Iterator[np.ndarray]:
    """Every frame of an mp4 as (H, W, 3) uint8 RGB, in order."""
    with av.open(str(path)) as container:
        for frame in container.decode(video=0):
            yield frame.to_ndarray(format="rgb24")


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """Peak signal-to-noise ratio of two uint8 pictures, in dB (inf when equal)."""
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def write_v21_dataset(root: Path, episodes: list[dict], fps: int) -> None:
    """A LeRobot v2.1 dataset without video, laid out as LeRobot 0.3 wrote one (one parquet file per episode,
    meta/*.jsonl): `episodes` as make_episodes' (task, action, observation.state). For the converter's test."""
    features = {key: {"dtype": "float32", "shape": [6], "names": MOTOR_NAMES} for key in ("action", "observation.state")}
    features.update(json.loads(json.dumps(DEFAULT_FEATURES)))
    tasks = list(dict.fromkeys(episode["task"] for episode in episodes))
    (root / "meta").mkdir(parents=True)
    (root / "data/chunk-000").mkdir(parents=True)
    index, episode_lines, stats_lines = 0, [], []
    for number, episode in enumerate(episodes):
        length = len(episode["action"])
        frames = np.arange(length)
        columns = {"action": episode["action"], "observation.state": episode["observation.state"],
                   "timestamp": (frames / fps).astype(np.float32), "frame_index": frames,
                   "episode_index": np.full(length, number), "index": index + frames,
                   "task_index": np.full(length, tasks.index(episode["task"]))}
        table = pa.table({key: pa.array(list(values), type=pa.list_(pa.float32())) if values.ndim == 2 else pa.array(values)
                          for key, values in columns.items()})
        pq.write_table(table, root / f"data/chunk-000/episode_{number:06d}.parquet")
        episode_lines.append({"episode_index": number, "tasks": [episode["task"]], "length": length})
        stats_lines.append({"episode_index": number, "stats": {
            key: {"min": np.atleast_1d(values.min(0)).tolist(), "max": np.atleast_1d(values.max(0)).tolist(),
                  "mean": np.atleast_1d(values.mean(0)).tolist(), "std": np.atleast_1d(values.std(0)).tolist(),
                  "count": [length]}
            for key, values in columns.items()}})
        index += length
    info = {"codebase_version": "v2.1", "robot_type": "so101_follower", "total_episodes": len(episodes),
            "total_frames": index, "total_tasks": len(tasks), "total_videos": 0, "total_chunks": 1, "chunks_size": 1000,
            "fps": fps, "splits": {"train": f"0:{len(episodes)}"},
            "data_path": "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet", "video_path": None,
            "features": features}
    (root / "meta/info.json").write_text(json.dumps(info, indent=4))
    for name, lines in (("episodes", episode_lines), ("episodes_stats", stats_lines),
                        ("tasks", [{"task_index": i, "task": task} for i, task in enumerate(tasks)])):
        (root / f"meta/{name}.jsonl").write_text("".join(json.dumps(line) + "\n" for line in lines))
