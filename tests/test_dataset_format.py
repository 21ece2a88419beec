"""The LeRobotDataset v3.0 files so101.dataset.writer writes, read back with plain pyarrow,
json and PyAV (not with the project's reader, so these checks do not share its mistakes): names,
types, indices, statistics, video; appending; refusals; a full disk and SIGKILL at any moment of
a save; and `so101 dataset`.
"""

from __future__ import annotations

import argparse
import errno
import hashlib
import json
import os
import random
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from types import ModuleType
from typing import Any, Callable

import av
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from so101.dataset import commit, video
from so101.dataset.episode import EpisodeRecorder
from so101.dataset.features import (
    ACTION_KEY, IMAGE_KEY, MOTOR_NAMES, ROBOT_TYPE, STATE_KEY, WRIST_IMAGE_KEY, video_keys_and_sizes,
)
from so101.dataset.layout import DatasetError
from so101.dataset.reader import Dataset
from so101.dataset.stats import QUANTILE_BINS
from so101.dataset.units import UNITS_KEY
from so101.dataset.writer import DatasetWriter
from tests.helpers.images import png_size

FPS = 30
SIZE = (128, 96)  # width, height: small, so that encoding takes milliseconds
VIDEO = {IMAGE_KEY: SIZE}  # DatasetWriter.open's video sizes
QUANTILES = {"q01": 0.01, "q10": 0.10, "q50": 0.50, "q90": 0.90, "q99": 0.99}
STATS = ("min", "max", "mean", "std", "count", *QUANTILES)
NUMERIC = ("action", "observation.state", "timestamp", "frame_index", "episode_index", "index", "task_index")
REPO = Path(__file__).resolve().parents[1]


# -- what the tests record -----------------------------------------------------------------------


def joints(seed: int, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Episode `seed`'s frame i: (state, action) float32[6]. action[0] starts at `seed`, so an
    episode read back says which one it is."""
    t = i / FPS
    action = np.array([seed + 2.0 * t, 40 * np.sin(t + seed), -30 + 5 * t, 20 * np.cos(2 * t), 90 * np.sin(0.5 * t),
                       50 + 40 * np.sin(3 * t + seed)], dtype=np.float32)
    return (action - np.float32(0.75)).astype(np.float32), action


def picture(seed: int, i: int, size: tuple[int, int] | None = None) -> np.ndarray:
    """A rendered-looking frame: soft gradients, a moving box and a disc with anti-aliased edges
    (a video codec keeps these, unlike noise or hard colour edges at a few dozen pixels)."""
    width, height = size or SIZE
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    image = np.empty((height, width, 3))
    image[..., 0] = 60 + 120 * x / width
    image[..., 1] = 80 + 100 * y / height
    image[..., 2] = 120 + 60 * np.sin((x + y) / 25 + seed)
    left = (5 + 2 * i) % (width - 16)
    inside = np.minimum(np.minimum(x - left, left + 16 - x), np.minimum(y - height / 3, height / 3 + 12 - y))
    box = np.clip(inside / 3 + 0.5, 0, 1)[..., None]  # a 3-pixel edge ramp
    image = image * (1 - box) + np.array([230, 200, 40]) * box
    radius = np.hypot(x - width * 0.7, y - height * 0.6 - 3 * np.sin(i / 4))
    disc = np.clip((height / 6 - radius) / 3 + 0.5, 0, 1)[..., None]
    image = image * (1 - disc) + np.array([30, 60, 200]) * disc
    return np.clip(image, 0, 255).astype(np.uint8)


def frame(seed: int, i: int, video: bool = True) -> dict[str, np.ndarray]:
    """Episode `seed`'s frame i as add_frame takes it: joints(), and picture() with video."""
    state, action = joints(seed, i)
    return {STATE_KEY: state, ACTION_KEY: action, **({IMAGE_KEY: picture(seed, i)} if video else {})}


def record_episodes(writer: DatasetWriter, episodes: list[tuple[str, int]], first_seed: int) -> list[int]:
    """Record and save (task, frames) episodes with seeds first_seed, first_seed+1, ...; their indices."""
    indices = []
    for n, (task, length) in enumerate(episodes):
        seed = first_seed + n
        episode = writer.start_episode(task)
        for i in range(length):
            episode.add_frame(frame(seed, i, video=bool(writer.video_sizes)))
        indices.append(episode.save().index)
    return indices


def record(root: Path, episodes: list[tuple[str, int]], first_seed: int = 0, video: bool = True,
           **limits: Any) -> None:
    """A writer session that records `episodes`; limits: DatasetWriter.open's file-size keywords."""
    with DatasetWriter.open(root, FPS, VIDEO if video else {}, **limits) as writer:
        record_episodes(writer, episodes, first_seed)


# -- reading the files without the project's reader ----------------------------------------------


def read_json(path: Path) -> dict:
    return json.loads(path.read_text(encoding="utf-8"))


def data_table(root: Path) -> pa.Table:
    """Every data file, in path order (as LeRobot concatenates them)."""
    return pa.concat_tables([pq.read_table(path) for path in sorted((root / "data").glob("*/*.parquet"))])


def episode_rows(root: Path) -> list[dict]:
    rows = []
    for path in sorted((root / "meta/episodes").glob("*/*.parquet")):
        rows += pq.read_table(path).to_pylist()
    return rows


def column(table: pa.Table, name: str) -> np.ndarray:
    values = table.column(name).combine_chunks()
    if pa.types.is_fixed_size_list(values.type):
        return values.flatten().to_numpy().reshape(len(values), values.type.list_size)
    return values.to_numpy(zero_copy_only=False)  # bools are bits in Arrow: copied out


def decode_episode(root: Path, row: dict) -> list[tuple[float, np.ndarray]]:
    """An episode's frames straight from its mp4 with PyAV: (seconds in the file, RGB) from its
    from_timestamp on, as many as its length."""
    info = read_json(root / "meta/info.json")
    path = root / info["video_path"].format(video_key=IMAGE_KEY, chunk_index=row[f"videos/{IMAGE_KEY}/chunk_index"],
                                            file_index=row[f"videos/{IMAGE_KEY}/file_index"])
    start = row[f"videos/{IMAGE_KEY}/from_timestamp"]
    with av.open(str(path)) as container:
        frames = [(float(frame.time), frame.to_ndarray(format="rgb24")) for frame in container.decode(video=0)
                  if frame.time is not None and frame.time >= start - 0.5 / FPS]
    return frames[:row["length"]]


def psnr_db(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))


def snapshot(root: Path) -> dict[str, str]:
    """Every file of the dataset (not the recorder's work folder) and a hash of its bytes."""
    return {str(path.relative_to(root)): hashlib.sha256(path.read_bytes()).hexdigest()
            for path in sorted(root.rglob("*")) if path.is_file() and commit.WORK_DIR not in path.parts}


def lerobot_quantile_bounds(values: np.ndarray, q: float) -> tuple[float, float]:
    """Where LeRobot's histogram quantile (5000 bins between min and max) may land for data whose
    exact q-quantile lies between two neighbouring samples: within a bin of them."""
    bin_width = (values.max() - values.min()) / QUANTILE_BINS + 2e-10
    low = np.quantile(values, q, method="lower")
    high = np.quantile(values, q, method="higher")
    return float(low - bin_width), float(high + bin_width)


# -- one dataset, read by several tests ----------------------------------------------------------

EPISODES = [("pick the cube", 40), ("place the cube", 25), ("pick the cube", 33)]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("recorded") / "demos"
    record(root, EPISODES)
    return root


@pytest.fixture(scope="module")
def recorded_without_video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("recorded") / "demos"
    record(root, EPISODES, video=False)
    return root


def test_the_files_are_lerobots(recorded: Path) -> None:
    files = sorted(str(p.relative_to(recorded)) for p in recorded.rglob("*") if p.is_file())
    assert files == ["data/chunk-000/file-000.parquet", "meta/episodes/chunk-000/file-000.parquet",
                     "meta/info.json", "meta/stats.json", "meta/tasks.parquet",
                     f"videos/{IMAGE_KEY}/chunk-000/file-000.mp4"]
    info = read_json(recorded / "meta/info.json")
    assert list(info) == ["codebase_version", "robot_type", "total_episodes", "total_frames", "total_tasks",
                          "chunks_size", "data_files_size_in_mb", "video_files_size_in_mb", "fps", "splits",
                          "data_path", "video_path", "features", UNITS_KEY]
    assert info[UNITS_KEY] == "degrees"  # ours, beside LeRobot's keys: its own datasets do not say
    assert (info["codebase_version"], info["robot_type"], info["fps"]) == ("v3.0", ROBOT_TYPE, FPS)
    assert (info["total_episodes"], info["total_frames"], info["total_tasks"]) == (3, 98, 2)
    assert (info["chunks_size"], info["data_files_size_in_mb"], info["video_files_size_in_mb"]) == (1000, 100, 200)
    assert info["splits"] == {"train": "0:3"}
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert info["video_path"] == "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    features = info["features"]
    assert list(features) == ["action", "observation.state", IMAGE_KEY, *NUMERIC[2:]]
    for key in ("action", "observation.state"):
        assert features[key] == {"dtype": "float32", "shape": [6], "names": list(MOTOR_NAMES)}
    assert features[IMAGE_KEY] == {
        "dtype": "video", "shape": [SIZE[1], SIZE[0], 3], "names": ["height", "width", "channels"],
        "info": {"video.height": SIZE[1], "video.width": SIZE[0], "video.codec": "av1", "video.pix_fmt": "yuv420p",
                 "video.is_depth_map": False, "video.fps": FPS, "video.channels": 3, "has_audio": False}}
    assert features["timestamp"] == {"dtype": "float32", "shape": [1], "names": None}
    for key in NUMERIC[3:]:
        assert features[key] == {"dtype": "int64", "shape": [1], "names": None}
    # LeRobot's write_json: indent 4.
    assert (recorded / "meta/info.json").read_text(encoding="utf-8").startswith('{\n    "codebase_version": "v3.0"')


def test_data_columns_and_types(recorded: Path) -> None:
    path = recorded / "data/chunk-000/file-000.parquet"
    schema = pq.read_schema(path)
    assert schema.names == list(NUMERIC)
    assert schema.field("action").type == pa.list_(pa.float32(), 6)
    assert schema.field("observation.state").type == pa.list_(pa.float32(), 6)
    assert schema.field("timestamp").type == pa.float32()
    for name in NUMERIC[3:]:
        assert schema.field(name).type == pa.int64()
    hf = json.loads(schema.metadata[b"huggingface"])["info"]["features"]
    assert hf["action"] == {"feature": {"dtype": "float32", "_type": "Value"}, "length": 6, "_type": "List"}
    assert hf["index"] == {"dtype": "int64", "_type": "Value"}
    metadata = pq.read_metadata(path)
    assert metadata.num_row_groups == len(EPISODES)  # one per episode, as LeRobot's ParquetWriter
    assert metadata.row_group(0).column(0).compression == "SNAPPY"


def test_tasks_are_a_pandas_index(recorded: Path) -> None:
    table = pq.read_table(recorded / "meta/tasks.parquet")
    assert table.schema.names == ["task_index", "__index_level_0__"]
    assert table.schema.field("__index_level_0__").type == pa.string()
    assert table.to_pylist() == [{"task_index": 0, "__index_level_0__": "pick the cube"},
                                 {"task_index": 1, "__index_level_0__": "place the cube"}]
    pandas_meta = json.loads(table.schema.metadata[b"pandas"])
    assert pandas_meta["index_columns"] == ["__index_level_0__"]


def test_indices_timestamps_and_values(recorded: Path) -> None:
    table = data_table(recorded)
    lengths = [length for _, length in EPISODES]
    total = sum(lengths)
    assert np.array_equal(column(table, "index"), np.arange(total))
    frame_index = column(table, "frame_index")
    assert np.array_equal(frame_index, np.concatenate([np.arange(n) for n in lengths]))
    assert np.array_equal(column(table, "episode_index"), np.repeat(np.arange(len(lengths)), lengths))
    assert np.array_equal(column(table, "task_index"), np.repeat([0, 1, 0], lengths))
    assert np.allclose(column(table, "timestamp"), frame_index / FPS, atol=1e-6, rtol=0)
    given = [joints(seed, i) for seed, n in enumerate(lengths) for i in range(n)]
    assert np.array_equal(column(table, "observation.state"), np.array([state for state, _ in given]))
    assert np.array_equal(column(table, "action"), np.array([action for _, action in given]))


def test_episode_rows_tile_the_data(recorded: Path) -> None:
    rows = episode_rows(recorded)
    assert [row["episode_index"] for row in rows] == [0, 1, 2]
    assert [row["tasks"] for row in rows] == [["pick the cube"], ["place the cube"], ["pick the cube"]]
    assert [row["length"] for row in rows] == [n for _, n in EPISODES]
    ends = np.cumsum([0] + [n for _, n in EPISODES])
    assert [(row["dataset_from_index"], row["dataset_to_index"]) for row in rows] == list(zip(ends[:-1], ends[1:]))
    starts = [row[f"videos/{IMAGE_KEY}/from_timestamp"] for row in rows]
    assert starts == pytest.approx([0.0, 40 / FPS, 65 / FPS], abs=1e-9)
    assert [row[f"videos/{IMAGE_KEY}/to_timestamp"] for row in rows] == pytest.approx(
        [40 / FPS, 65 / FPS, 98 / FPS], abs=1e-9)
    for row in rows:
        assert (row["data/chunk_index"], row["data/file_index"]) == (0, 0)
        assert (row["meta/episodes/chunk_index"], row["meta/episodes/file_index"]) == (0, 0)
    names = pq.read_schema(recorded / "meta/episodes/chunk-000/file-000.parquet").names
    stats_columns = [f"stats/{key}/{stat}" for key in ["action", "observation.state", IMAGE_KEY, *NUMERIC[2:]]
                     for stat in STATS]
    assert names == ["episode_index", "tasks", "length", "data/chunk_index", "data/file_index",
                     "dataset_from_index", "dataset_to_index",
                     f"videos/{IMAGE_KEY}/chunk_index", f"videos/{IMAGE_KEY}/file_index",
                     f"videos/{IMAGE_KEY}/from_timestamp", f"videos/{IMAGE_KEY}/to_timestamp",
                     *stats_columns, "meta/episodes/chunk_index", "meta/episodes/file_index"]


def check_numeric_stats(stats: dict, values: np.ndarray) -> None:
    """stats (as stored: lists) against numpy's over `values` (frames,) or (frames, n)."""
    rows = values.reshape(len(values), -1).astype(np.float64)
    assert stats["count"] == [len(values)]
    assert np.array_equal(stats["min"], rows.min(axis=0))
    assert np.array_equal(stats["max"], rows.max(axis=0))
    assert np.allclose(stats["mean"], rows.mean(axis=0), rtol=1e-12, atol=1e-12)
    assert np.allclose(stats["std"], rows.std(axis=0), rtol=1e-9, atol=1e-12)
    for key, q in QUANTILES.items():
        for value, data in zip(stats[key], rows.T):
            low, high = lerobot_quantile_bounds(data, q)
            assert low <= value <= high, (key, value, low, high)


def test_episode_stats_are_numpys(recorded: Path) -> None:
    table = data_table(recorded)
    for row in episode_rows(recorded):
        part = table.slice(row["dataset_from_index"], row["length"])
        for key in NUMERIC:
            stats = {stat: row[f"stats/{key}/{stat}"] for stat in STATS}
            values = column(part, key)
            check_numeric_stats(stats, values if key != "timestamp" else column(part, "frame_index") / FPS)
        # Pictures: every frame of an episode under 100 frames, per channel, in [0, 1], shaped (3, 1, 1).
        pixels = np.stack([picture(row["episode_index"], i) for i in range(row["length"])]).reshape(-1, 3) / 255.0
        image = {stat: np.array(row[f"stats/{IMAGE_KEY}/{stat}"]) for stat in STATS}
        assert image["count"].tolist() == [row["length"]]
        for stat in ("min", "max", "mean", "std"):
            assert image[stat].shape == (3, 1, 1)
            assert np.allclose(image[stat].ravel(), getattr(pixels, stat)(axis=0), rtol=1e-9, atol=1e-12), stat
        for key, q in QUANTILES.items():
            for channel in range(3):
                low, high = lerobot_quantile_bounds(pixels[:, channel], q)
                assert low <= image[key].ravel()[channel] <= high


def test_stats_json_aggregates_the_episodes(recorded: Path) -> None:
    stats = read_json(recorded / "meta/stats.json")
    table = data_table(recorded)
    rows = episode_rows(recorded)
    assert set(stats) == {"action", "observation.state", IMAGE_KEY, *NUMERIC[2:]}
    for key in NUMERIC:
        values = (column(table, "frame_index") / FPS if key == "timestamp" else column(table, key))
        values = values.reshape(len(values), -1).astype(np.float64)
        assert stats[key]["count"] == [len(values)]
        assert np.array_equal(stats[key]["min"], values.min(axis=0))
        assert np.array_equal(stats[key]["max"], values.max(axis=0))
        assert np.allclose(stats[key]["mean"], values.mean(axis=0), rtol=1e-9, atol=1e-12)
        assert np.allclose(stats[key]["std"], values.std(axis=0), rtol=1e-9, atol=1e-12)
        # LeRobot's aggregate_stats: quantiles are the count-weighted mean of the episodes'.
        counts = np.array([row[f"stats/{key}/count"][0] for row in rows], dtype=np.float64)
        for q in QUANTILES:
            per_episode = np.array([row[f"stats/{key}/{q}"] for row in rows])
            assert np.allclose(stats[key][q], (per_episode * counts[:, None]).sum(axis=0) / counts.sum(), rtol=1e-12)
    pixels = np.stack([picture(seed, i) for seed, (_, n) in enumerate(EPISODES) for i in range(n)])
    pixels = pixels.reshape(-1, 3) / 255.0
    assert stats[IMAGE_KEY]["count"] == [98]
    for stat in ("min", "max", "mean", "std"):
        assert np.allclose(np.ravel(stats[IMAGE_KEY][stat]), getattr(pixels, stat)(axis=0), rtol=1e-9), stat


def test_video_frames_are_the_pictures_at_their_timestamps(recorded: Path) -> None:
    for row in episode_rows(recorded):
        frames = decode_episode(recorded, row)
        assert len(frames) == row["length"]
        start = row[f"videos/{IMAGE_KEY}/from_timestamp"]
        for i, (seconds, rgb) in enumerate(frames):
            assert seconds == pytest.approx(start + i / FPS, abs=1e-4)  # LeRobot's tolerance_s
            assert rgb.shape == (SIZE[1], SIZE[0], 3)
            assert psnr_db(rgb, picture(row["episode_index"], i)) >= 30.0
    with av.open(str(recorded / f"videos/{IMAGE_KEY}/chunk-000/file-000.mp4")) as container:
        stream = container.streams.video[0]
        assert (stream.codec_context.name, stream.pix_fmt, stream.frames) in {
            ("libdav1d", "yuv420p", 98), ("av1", "yuv420p", 98)}
        keyframes = [packet.is_keyframe for packet in container.demux(stream) if packet.size]
        assert keyframes[:4] == [True, False, True, False]  # g=2, as LeRobot encodes


def test_without_video(recorded_without_video: Path) -> None:
    info = read_json(recorded_without_video / "meta/info.json")
    assert info["video_path"] is None
    assert IMAGE_KEY not in info["features"]
    assert not (recorded_without_video / "videos").exists()
    assert IMAGE_KEY not in read_json(recorded_without_video / "meta/stats.json")
    names = pq.read_schema(recorded_without_video / "meta/episodes/chunk-000/file-000.parquet").names
    assert not [name for name in names if name.startswith("videos/")]
    assert pq.read_schema(recorded_without_video / "data/chunk-000/file-000.parquet").names == list(NUMERIC)


def test_two_cameras_each_get_their_video(tmp_path: Path) -> None:
    root = tmp_path / "demos"
    wrist, wrist_size = "observation.images.wrist", (64, 48)
    with DatasetWriter.open(root, FPS, {IMAGE_KEY: SIZE, wrist: wrist_size}) as writer:
        for seed, length in [(0, 8), (1, 6)]:
            episode = writer.start_episode("pick")
            for i in range(length):
                episode.add_frame({**frame(seed, i), wrist: picture(seed + 10, i, wrist_size)})
            episode.save()
    info = read_json(root / "meta/info.json")
    assert list(info["features"]) == ["action", "observation.state", IMAGE_KEY, wrist, *NUMERIC[2:]]
    assert info["features"][wrist]["shape"] == [48, 64, 3]
    assert (info["features"][wrist]["info"]["video.width"], info["features"][IMAGE_KEY]["info"]["video.width"]) == (
        64, 128)
    assert {IMAGE_KEY, wrist} <= set(read_json(root / "meta/stats.json"))
    rows = episode_rows(root)
    for key in (IMAGE_KEY, wrist):
        assert (root / f"videos/{key}/chunk-000/file-000.mp4").is_file()
        assert [row[f"videos/{key}/from_timestamp"] for row in rows] == pytest.approx([0, 8 / FPS])
        assert [row[f"stats/{key}/count"] for row in rows] == [[8], [6]]
    dataset = Dataset.open(root)
    assert dataset.video_keys == [IMAGE_KEY, wrist]
    for episode_index, length in [(0, 8), (1, 6)]:
        fronts = list(dataset.episode_images(episode_index, IMAGE_KEY))
        wrists = list(dataset.episode_images(episode_index, wrist))
        assert len(fronts) == len(wrists) == length
        assert min(psnr_db(rgb, picture(episode_index, i)) for i, rgb in enumerate(fronts)) >= 30.0
        assert min(psnr_db(rgb, picture(episode_index + 10, i, wrist_size)) for i, rgb in enumerate(wrists)) >= 30.0
    with pytest.raises(DatasetError, match="has video \\(observation.images.wrist\\): record with its image size"):
        DatasetWriter.open(root, FPS, VIDEO)


# -- the reader -------------------------------------------------------------------------------------


def test_reader_gives_back_what_was_recorded(recorded: Path) -> None:
    dataset = Dataset.open(recorded)
    assert (dataset.fps, dataset.robot_type, dataset.total_frames) == (FPS, ROBOT_TYPE, 98)
    assert dataset.tasks == ["pick the cube", "place the cube"]
    assert dataset.video_keys == [IMAGE_KEY]
    assert [(e.index, e.length, e.tasks) for e in dataset.episodes] == [
        (0, 40, ("pick the cube",)), (1, 25, ("place the cube",)), (2, 33, ("pick the cube",))]
    assert dataset.episodes[1].duration_s == pytest.approx(25 / FPS)
    frames = dataset.episode_frames(1)
    assert frames["action"].dtype == np.float32 and frames["action"].shape == (25, 6)
    assert np.array_equal(frames["action"], np.array([joints(1, i)[1] for i in range(25)]))
    assert np.array_equal(frames["index"], np.arange(40, 65))
    pictures = list(dataset.episode_images(2, IMAGE_KEY))
    assert len(pictures) == 33
    assert min(psnr_db(rgb, picture(2, i)) for i, rgb in enumerate(pictures)) >= 30.0


@pytest.mark.parametrize("ask", ["frames", "images", "key"])
def test_reader_says_which_episodes_exist(recorded: Path, ask: str) -> None:
    dataset = Dataset.open(recorded)
    with pytest.raises(DatasetError) as caught:
        if ask == "frames":
            dataset.episode_frames(3)
        elif ask == "images":
            list(dataset.episode_images(7, IMAGE_KEY))
        else:
            list(dataset.episode_images(0, "observation.images.wrist"))
    message = str(caught.value)
    assert "\n" not in message
    assert ("episodes 0-2" in message) if ask != "key" else (IMAGE_KEY in message)


# -- appending, files and chunks --------------------------------------------------------------------


def test_a_second_session_continues_in_new_files(tmp_path: Path) -> None:
    root = tmp_path / "demos"
    record(root, [("pick", 10), ("place", 12)])
    with DatasetWriter.open(root, FPS, VIDEO) as writer:
        assert [e.index for e in writer.episodes] == [0, 1]
        # Saved in the background while the next episode records, as the recorder node does.
        first = writer.start_episode("place")
        for i in range(9):
            first.add_frame(frame(2, i))
        saving = threading.Thread(target=first.save)
        saving.start()
        second = writer.start_episode("stack")
        for i in range(11):
            second.add_frame(frame(3, i))
        saving.join()
        assert second.save().index == 3
        assert [e.index for e in writer.episodes] == [0, 1, 2, 3]
    table = data_table(root)
    assert np.array_equal(column(table, "index"), np.arange(42))
    assert np.array_equal(column(table, "episode_index"), np.repeat([0, 1, 2, 3], [10, 12, 9, 11]))
    assert np.array_equal(column(table, "task_index"), np.repeat([0, 1, 1, 2], [10, 12, 9, 11]))
    assert pq.read_table(root / "meta/tasks.parquet").column("__index_level_0__").to_pylist() == [
        "pick", "place", "stack"]
    rows = episode_rows(root)
    # LeRobot moves on to the next file when it resumes: data, video and episode rows alike.
    assert [(r["data/file_index"], r[f"videos/{IMAGE_KEY}/file_index"], r["meta/episodes/file_index"])
            for r in rows] == [(0, 0, 0), (0, 0, 0), (1, 1, 1), (1, 1, 1)]
    assert [r[f"videos/{IMAGE_KEY}/from_timestamp"] for r in rows] == pytest.approx([0, 10 / FPS, 0, 9 / FPS])
    info = read_json(root / "meta/info.json")
    assert (info["total_episodes"], info["total_frames"], info["total_tasks"], info["splits"]) == (
        4, 42, 3, {"train": "0:4"})
    for row in rows:
        frames = decode_episode(root, row)
        assert len(frames) == row["length"]
        assert psnr_db(frames[-1][1], picture(row["episode_index"], row["length"] - 1)) >= 30.0


def test_size_limits_start_new_files_and_chunks(tmp_path: Path) -> None:
    root = tmp_path / "demos"
    # Limits under one episode's size, 2 files a chunk: every episode gets its own files.
    record(root, [("pick", 8), ("pick", 6), ("place", 7)], chunks_size=2, data_files_size_in_mb=1e-6,
           video_files_size_in_mb=1e-6)
    rows = episode_rows(root)
    where = [(r["data/chunk_index"], r["data/file_index"]) for r in rows]
    assert where == [(0, 0), (0, 1), (1, 0)]
    assert [(r[f"videos/{IMAGE_KEY}/chunk_index"], r[f"videos/{IMAGE_KEY}/file_index"]) for r in rows] == where
    assert [(r["meta/episodes/chunk_index"], r["meta/episodes/file_index"]) for r in rows] == where
    assert all(r[f"videos/{IMAGE_KEY}/from_timestamp"] == 0.0 for r in rows)
    assert sorted(str(p.relative_to(root / "data")) for p in (root / "data").rglob("*.parquet")) == [
        "chunk-000/file-000.parquet", "chunk-000/file-001.parquet", "chunk-001/file-000.parquet"]
    assert np.array_equal(column(data_table(root), "index"), np.arange(21))
    dataset = Dataset.open(root)
    for row in rows:
        assert len(dataset.episode_frames(row["episode_index"])["index"]) == row["length"]
        assert len(list(dataset.episode_images(row["episode_index"], IMAGE_KEY))) == row["length"]


def test_a_new_file_never_replaces_one(tmp_path: Path) -> None:
    root = tmp_path / "demos"
    record(root, [("pick", 5)])
    # Left by a session that crashed before its episode row was written: no row names these files.
    orphans = [root / "data/chunk-000/file-001.parquet", root / f"videos/{IMAGE_KEY}/chunk-000/file-001.mp4"]
    for orphan in orphans:
        orphan.write_bytes(b"someone's bytes")
    record(root, [("place", 6)], first_seed=1)
    assert all(orphan.read_bytes() == b"someone's bytes" for orphan in orphans)
    row = episode_rows(root)[1]
    assert (row["data/file_index"], row[f"videos/{IMAGE_KEY}/file_index"], row["meta/episodes/file_index"]) == (2, 2, 1)
    assert len(list(Dataset.open(root).episode_images(1, IMAGE_KEY))) == 6


# -- refusals ----------------------------------------------------------------------------------------


def _not_a_dataset(root: Path) -> None:
    root.mkdir()
    (root / "notes.txt").write_text("my notes")


def _a_file(root: Path) -> None:
    root.write_text("not a folder")


def _older_lerobot(root: Path) -> None:
    (root / "meta").mkdir(parents=True)
    (root / "meta/info.json").write_text(json.dumps({"codebase_version": "v2.1", "fps": 30, "features": {}}))


@pytest.mark.parametrize(("prepare", "fps", "video_sizes", "expected"), [
    (_not_a_dataset, FPS, VIDEO, "is not empty and is not a LeRobot dataset"),
    (_a_file, FPS, VIDEO, "is a file"),
    (_older_lerobot, FPS, VIDEO, "LeRobot v2.1 dataset: this reads and writes v3.0"),
    ("video", 15, VIDEO, "is recorded at 30 fps, not 15: record at 30 fps"),
    ("video", FPS, {}, "has video (observation.images.front): record with its image size"),
    ("video", FPS, {IMAGE_KEY: (320, 240)}, "video is 128x96, not 320x240: record at 128x96"),
    ("no video", FPS, VIDEO, "has no video (observation.images.front): record without an image size"),
    (None, FPS, {IMAGE_KEY: (63, 48)}, "use even width and height"),
    (None, 0, VIDEO, "use a whole number above 0"),
], ids=["not-a-dataset", "a-file", "v2.1", "other-fps", "video-vs-none", "other-size", "none-vs-video",
        "odd-size", "zero-fps"])
def test_refusals_are_one_line(tmp_path: Path, prepare: object, fps: int, video_sizes: dict[str, tuple[int, int]],
                               expected: str) -> None:
    root = tmp_path / "demos"
    if callable(prepare):
        prepare(root)
    elif prepare is not None:
        record(root, [("pick", 3)], video=prepare == "video")
    before = snapshot(root) if root.is_dir() else None
    with pytest.raises(DatasetError) as caught:
        DatasetWriter.open(root, fps, video_sizes)
    message = str(caught.value)
    assert "\n" not in message and expected in message
    if before is not None:
        assert snapshot(root) == before


def test_a_second_writer_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(commit, "LOCK_WAIT_S", 0.2)
    with DatasetWriter.open(tmp_path / "demos", FPS, VIDEO):
        with pytest.raises(DatasetError, match="another recorder is writing to"):
            DatasetWriter.open(tmp_path / "demos", FPS, VIDEO)


@pytest.mark.parametrize(("misuse", "expected"), [
    ("short state", "observation.state has shape (5,) float32: it must be 6 values"),
    ("no picture", "the frame has no 'observation.images.front'"),
    ("other picture", "it must be (96, 128, 3) uint8"),
    ("no frames", "an episode of 0 frames is not saved"),
    ("no task", "an episode needs a task text"),
])
def test_recorder_misuse_is_one_line(tmp_path: Path, misuse: str, expected: str) -> None:
    with DatasetWriter.open(tmp_path / "demos", FPS, VIDEO) as writer:
        with pytest.raises(DatasetError) as caught:
            if misuse == "no task":
                writer.start_episode("  ")
            episode = writer.start_episode("pick")
            state, action = joints(0, 0)
            if misuse == "short state":
                episode.add_frame({STATE_KEY: state[:5], ACTION_KEY: action, IMAGE_KEY: picture(0, 0)})
            elif misuse == "no picture":
                episode.add_frame({STATE_KEY: state, ACTION_KEY: action})
            elif misuse == "other picture":
                episode.add_frame({STATE_KEY: state, ACTION_KEY: action, IMAGE_KEY: picture(0, 0, (32, 24))})
            else:
                episode.save()
        assert "\n" not in str(caught.value) and expected in str(caught.value)


@pytest.mark.parametrize(("change", "expected"), [
    ({ACTION_KEY: None}, "the frame has no 'action': a frame holds action, observation.state, observation.images.front"),
    ({"observation.images.wrist": picture(0, 0)},
     "the frame has 'observation.images.wrist', which is not a feature of this dataset"),
    ({STATE_KEY: np.zeros((6, 1), np.float32)}, "observation.state has shape (6, 1) float32: it must be 6 values "
                                                "(shoulder_pan.pos, shoulder_lift.pos"),
    ({ACTION_KEY: np.array(["up"] * 6)}, "action has shape (6,) <U2: it must be 6 values"),
    ({IMAGE_KEY: picture(0, 0) / 255.0}, "observation.images.front has shape (96, 128, 3) float64: "
                                         "it must be (96, 128, 3) uint8 (RGB)"),
], ids=["missing", "extra", "shape", "dtype", "picture-dtype"])
def test_a_frame_is_checked_against_the_features(tmp_path: Path, change: dict, expected: str) -> None:
    with DatasetWriter.open(tmp_path / "demos", FPS, VIDEO) as writer:
        episode = writer.start_episode("pick")
        wrong = {key: value for key, value in {**frame(0, 0), **change}.items() if value is not None}
        with pytest.raises(DatasetError) as caught:
            episode.add_frame(wrong)
        assert "\n" not in str(caught.value) and expected in str(caught.value)
        assert episode.frames == 0  # nothing of a refused frame is kept: its picture neither
        episode.add_frame(frame(0, 0))
        assert episode.save().length == 1
    assert len(list(Dataset.open(tmp_path / "demos").episode_images(0, IMAGE_KEY))) == 1


def test_discard_leaves_nothing(tmp_path: Path) -> None:
    root = tmp_path / "demos"
    record(root, [("pick", 5)])
    before = snapshot(root)
    with DatasetWriter.open(root, FPS, VIDEO) as writer:
        episode = writer.start_episode("place")
        for i in range(7):
            episode.add_frame(frame(1, i))
        episode.discard()
        assert writer.episodes[-1].index == 0
    assert snapshot(root) == before
    assert not (root / commit.WORK_DIR).exists()


# -- a full disk and interrupted commits --------------------------------------------------------------


@pytest.fixture(scope="module")
def one_episode(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("base") / "demos"
    record(root, [("pick", 12)])
    return root


def copy_of(base: Path, into: Path) -> Path:
    import shutil

    shutil.copytree(base, into / "demos")
    return into / "demos"


def recording(writer: DatasetWriter, seed: int = 1, frames: int = 10) -> EpisodeRecorder:
    episode = writer.start_episode("place")
    for i in range(frames):
        episode.add_frame(frame(seed, i))
    return episode


def commit_calls(base: Path, into: Path, monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, str]]:
    """The fsync and replace calls, in order, of the save the full-disk test breaks: a session's
    second episode, joined onto the session's video file."""
    root = copy_of(base, into)
    calls: list[tuple[str, str]] = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd: int) -> None:
        calls.append(("fsync", ""))
        real_fsync(fd)

    def replace(source: str, target: str) -> None:
        calls.append(("replace", str(target)))
        real_replace(source, target)

    with DatasetWriter.open(root, FPS, VIDEO) as writer:
        record_episodes(writer, [("pick", 6)], first_seed=5)
        episode = recording(writer)
        monkeypatch.setattr(os, "fsync", fsync)
        monkeypatch.setattr(os, "replace", replace)
        episode.save()
    monkeypatch.undo()
    return calls


def fsyncs_until_journal(calls: list[tuple[str, str]]) -> int:
    """How many fsyncs a save makes up to and with its journal's folder: a failure in any of them
    must leave the dataset as it was."""
    journal_at = next(i for i, (kind, target) in enumerate(calls) if kind == "replace" and
                      target.endswith(commit.JOURNAL_PATH))
    return sum(1 for kind, _ in calls[:journal_at] if kind == "fsync") + 1


def test_a_full_disk_at_any_write_leaves_the_dataset_as_it_was(one_episode: Path, tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    calls = commit_calls(one_episode, tmp_path / "spy", monkeypatch)
    last = fsyncs_until_journal(calls)
    assert last >= 8  # data, video, episodes, info, stats, the moved or joined video, folders, journal
    failures: list[tuple[str, int]] = [("fsync", k) for k in range(1, last + 1)]
    failures += [("parquet", 1), ("parquet", 2), ("concatenate", 1), ("json", 1), ("json", 3)]
    real: dict[str, Callable[..., Any]] = {"fsync": os.fsync, "parquet": pq.ParquetWriter.write_table,
                                           "json": json.dump, "concatenate": video.concatenate}
    for number, (where, k) in enumerate(failures):
        root = copy_of(one_episode, tmp_path / f"run{number}")
        with DatasetWriter.open(root, FPS, VIDEO) as writer:
            record_episodes(writer, [("pick", 6)], first_seed=5)  # this session's video file to join onto
            before = snapshot(root)
            episode = recording(writer)
            count = [0]

            def failing(*args: object, _where: str = where, _k: int = k, **kwargs: object) -> object:
                count[0] += 1
                if count[0] == _k:
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                return real[_where](*args, **kwargs)

            target = {"fsync": (os, "fsync"), "parquet": (pq.ParquetWriter, "write_table"),
                      "json": (json, "dump"), "concatenate": (video, "concatenate")}[where]
            monkeypatch.setattr(*target, failing)
            with pytest.raises(DatasetError) as caught:
                episode.save()
            monkeypatch.undo()
            message = str(caught.value)
            assert "\n" not in message and "No space left on device" in message, (where, k, message)
            assert "is not saved" in message
            assert snapshot(root) == before, (where, k)
            assert [e.index for e in writer.episodes] == [0, 1]
            assert [e.index for e in Dataset.open(root).episodes] == [0, 1]
            # The disk has room again: the same episode saves.
            assert episode.save().index == 2
        dataset = Dataset.open(root)
        assert [e.length for e in dataset.episodes] == [12, 6, 10]
        assert np.array_equal(dataset.episode_frames(2)["action"], np.array([joints(1, i)[1] for i in range(10)]))
        assert len(list(dataset.episode_images(2, IMAGE_KEY))) == 10
        assert np.array_equal(column(data_table(root), "index"), np.arange(28))


def test_renames_cut_short_are_completed_on_open(one_episode: Path, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    root = copy_of(one_episode, tmp_path)
    real_replace = os.replace
    renamed: list[str] = []

    def replace_twice(source: str, target: str) -> None:
        if len(renamed) == 3:  # the journal and two files are in place, then the disk fails
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        renamed.append(str(target))
        real_replace(source, target)

    with DatasetWriter.open(root, FPS, VIDEO) as writer:
        episode = recording(writer)
        monkeypatch.setattr(os, "replace", replace_twice)
        with pytest.raises(DatasetError, match="is saved but not yet in place") as caught:
            episode.save()
        monkeypatch.undo()
        episode.discard()  # keeps the video the journal still names
        # The files are between two states until the next open: this writer saves nothing more.
        with pytest.raises(DatasetError, match="an earlier save is still to be completed"):
            recording(writer, seed=2).save()
    assert "\n" not in str(caught.value)
    assert (root / commit.JOURNAL_PATH).exists()
    dataset = Dataset.open(root)  # completes the renames
    assert not (root / commit.JOURNAL_PATH).exists()
    assert [e.length for e in dataset.episodes] == [12, 10]
    assert np.array_equal(dataset.episode_frames(1)["action"], np.array([joints(1, i)[1] for i in range(10)]))
    assert read_json(root / "meta/info.json")["total_frames"] == 22
    assert len(list(dataset.episode_images(1, IMAGE_KEY))) == 10
    assert not list(root.rglob("*" + commit.TEMP_SUFFIX))


def test_leftovers_without_a_journal_are_removed_on_open(one_episode: Path, tmp_path: Path) -> None:
    root = copy_of(one_episode, tmp_path)
    before = snapshot(root)
    (root / ("data/chunk-000/file-000.parquet" + commit.TEMP_SUFFIX)).write_bytes(b"half a file")
    (root / ("meta/info.json" + commit.TEMP_SUFFIX)).write_text("{")
    (root / commit.WORK_DIR).mkdir()
    (root / commit.WORK_DIR / "episode-1-1.mp4").write_bytes(b"\x00" * 100)
    assert [e.index for e in Dataset.open(root).episodes] == [0]
    assert snapshot(root) == before
    assert not (root / commit.WORK_DIR).exists()


# -- SIGKILL -------------------------------------------------------------------------------------------

# Recorded in a fresh interpreter, as the recorder node does, and killed after a random delay.
CHILD = textwrap.dedent("""
    import random, sys, time
    sys.path[:0] = [{repo!r}, {tests!r}]
    from test_dataset_format import FPS, VIDEO, frame
    from so101.dataset.writer import DatasetWriter

    root, seed = sys.argv[1], int(sys.argv[2])
    rng = random.Random(seed)
    writer = DatasetWriter.open(root, FPS, VIDEO)
    print("ready", flush=True)
    while True:
        episode = writer.start_episode("pick" if seed % 2 else "place")
        pause_s = rng.choice([0.0, 0.0, 0.0, 0.01])  # some episodes recorded slowly: killed mid-episode
        for i in range(rng.randint(3, 30)):
            episode.add_frame(frame(seed, i))
            time.sleep(pause_s)
        summary = episode.save()
        print("saved", summary.index, seed, flush=True)
        seed += 1
""")


def save_and_die_at(root: Path, step: int) -> int:
    """In a forked child: record an episode and save it, SIGKILLed at the step-th fsync or rename of
    the save (never, for 0). Returns the child's exit status: the steps made when it was not killed."""
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        try:
            writer = DatasetWriter.open(root, FPS, VIDEO)
            episode = recording(writer, seed=1000 + step, frames=10)
            calls = [0]

            def dying(real: Callable[..., Any]) -> Callable[..., Any]:
                def call(*args: Any) -> Any:
                    calls[0] += 1
                    if calls[0] == step:
                        os.kill(os.getpid(), signal.SIGKILL)
                    return real(*args)
                return call

            os.fsync, os.replace = dying(os.fsync), dying(os.replace)
            episode.save()
            os._exit(min(calls[0], 250))
        except BaseException:  # noqa: BLE001
            os._exit(255)
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        assert os.WTERMSIG(status) == signal.SIGKILL
        return -1
    assert os.WEXITSTATUS(status) != 255
    return os.WEXITSTATUS(status)


def run_child(root: Path, first_seed: int, kill_after_s: float) -> list[str]:
    """The lines "saved INDEX SEED" the child printed before it was killed, kill_after_s after it
    had opened the dataset."""
    code = CHILD.format(repo=str(REPO), tests=str(REPO / "tests"))
    child = subprocess.Popen([sys.executable, "-c", code, str(root), str(first_seed)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    assert child.stdout is not None
    assert child.stdout.readline() == "ready\n"
    time.sleep(kill_after_s)
    child.send_signal(signal.SIGKILL)
    out, err = child.communicate(timeout=60)
    assert child.returncode == -signal.SIGKILL, err
    return out.splitlines()


def check_whole(root: Path) -> Dataset:
    """The dataset after a crash: it opens, nothing of ours is left, every episode reads whole, and
    the files agree with each other."""
    dataset = Dataset.open(root)
    assert not (root / commit.JOURNAL_PATH).exists()
    assert not list(root.rglob("*" + commit.TEMP_SUFFIX))
    assert not (root / commit.WORK_DIR).exists()
    info = read_json(root / "meta/info.json")
    rows = episode_rows(root)
    assert info["total_episodes"] == len(rows) == len(dataset.episodes)
    if not rows:  # killed before its first save returned: a dataset with no episodes yet
        assert info["total_frames"] == 0 and not list(root.glob("data/*/*.parquet"))
        return dataset
    table = data_table(root)
    assert info["total_frames"] == table.num_rows == sum(row["length"] for row in rows)
    assert np.array_equal(column(table, "index"), np.arange(table.num_rows))
    for row in rows:
        frames = dataset.episode_frames(row["episode_index"])
        seed = int(round(float(frames["action"][0, 0])))  # joints() starts action[0] at the seed
        assert np.array_equal(frames["action"], np.array([joints(seed, i)[1] for i in range(row["length"])]))
        pictures = list(dataset.episode_images(row["episode_index"], IMAGE_KEY))
        assert len(pictures) == row["length"]
        assert psnr_db(pictures[-1], picture(seed, row["length"] - 1)) >= 30.0
    return dataset


@pytest.mark.slow
def test_sigkill_at_every_step_of_a_save(one_episode: Path, tmp_path: Path) -> None:
    steps = save_and_die_at(copy_of(one_episode, tmp_path / "spy"), 0)  # the fsyncs and renames of one save
    assert steps >= 12
    outcomes = set()
    for step in range(1, steps + 1):
        root = copy_of(one_episode, tmp_path / f"step{step}")
        assert save_and_die_at(root, step) == -1  # killed before save returned
        dataset = check_whole(root)
        # Killed before the journal was whole: the episode is dropped; after: it is completed.
        outcomes.add(len(dataset.episodes))
        assert len(dataset.episodes) in (1, 2)
    assert outcomes == {1, 2}
    # And recording goes on after a crash.
    with DatasetWriter.open(root, FPS, VIDEO) as writer:
        record_episodes(writer, [("pick", 4)], first_seed=7)
    check_whole(root)


@pytest.mark.slow
def test_sigkill_at_random_moments_loses_no_saved_episode(tmp_path: Path) -> None:
    root = tmp_path / "demos"
    rng = random.Random(101)
    saved: dict[int, int] = {}  # episode index -> seed, of every save that returned
    for attempt in range(6):
        lines = run_child(root, 1000 * (attempt + 1), kill_after_s=rng.uniform(0.05, 0.6))
        saved.update({int(index): int(seed) for _, index, seed in (line.split() for line in lines)})
        dataset = check_whole(root)
        indices = [e.index for e in dataset.episodes]
        assert set(saved) <= set(indices)
        assert len(indices) <= len(saved) + attempt + 1  # at most the one being saved, completed, per kill
        for index, seed in saved.items():
            assert float(dataset.episode_frames(index)["action"][0, 0]) == pytest.approx(seed)
    assert len(saved) >= 5


# -- so101 dataset -------------------------------------------------------------------------------------


def test_cli_summary(recorded: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from so101.cli import dataset as dataset_cli

    args = _parse(dataset_cli, [str(recorded)])
    assert dataset_cli.run(args) == 0
    out = capsys.readouterr().out
    assert f"{recorded}: LeRobot v3.0 dataset, robot {ROBOT_TYPE}, 30 fps" in out
    assert "3 episodes:" in out
    assert "        1      25      0.8 s  place the cube" in out
    assert "total: 98 frames, 3.3 s at 30 fps" in out
    assert "    0: pick the cube\n    1: place the cube" in out
    assert "  action                    float32  (6,)" in out
    assert "  observation.images.front  video    (96, 128, 3)  av1 128x96" in out
    assert "  task_index                int64    (1,)" in out


def _parse(module: ModuleType, argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="so101 dataset")
    module.add_arguments(parser, "dataset")
    return parser.parse_args(argv)


def test_cli_plot(recorded: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from so101.cli import dataset as dataset_cli

    out = tmp_path / "plots" / "episode-2.png"
    assert dataset_cli.run(_parse(dataset_cli, [str(recorded), "--plot", "2", "--out", str(out)])) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    assert png_size(out.read_bytes()) == (1200, 800)


@pytest.mark.parametrize(("argv", "expected"), [
    (["{missing}"], "does not exist"),
    (["{not_dataset}"], "is not a LeRobot dataset (no meta/info.json)"),
    (["{recorded}", "--plot", "3"], "has no episode 3: it has episodes 0-2"),
], ids=["missing", "not-a-dataset", "no-such-episode"])
def test_cli_errors_are_one_line(recorded: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                 argv: list[str], expected: str) -> None:
    from so101.cli import dataset as dataset_cli

    (tmp_path / "notes").mkdir()
    names = {"missing": tmp_path / "nothing", "not_dataset": tmp_path / "notes", "recorded": recorded}
    args = _parse(dataset_cli, [part.format(**names) for part in argv])
    assert dataset_cli.run(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("so101 dataset: ") and expected in err


def test_a_tasks_episodes_carry_the_environment_state_reward_and_success(tmp_path: Path) -> None:
    from so101.dataset.features import ENVIRONMENT_KEY, REWARD_KEY, SUCCESS_KEY
    from so101.tasks import CUBE_TO_BOX

    names = CUBE_TO_BOX.object_state_names
    root = tmp_path / "task"
    with DatasetWriter.open(root, FPS, {}, environment_names=names) as writer:
        episode = writer.start_episode("put the cube in the box")
        for i in range(40):
            done = i >= 30
            episode.add_frame({**frame(0, i, video=False), ENVIRONMENT_KEY: np.full(len(names), i, np.float32),
                               REWARD_KEY: np.array([float(done)], np.float32), SUCCESS_KEY: np.array([done])})
        episode.save()
    features = read_json(root / "meta/info.json")["features"]
    assert list(features)[:5] == [ACTION_KEY, STATE_KEY, ENVIRONMENT_KEY, REWARD_KEY, SUCCESS_KEY]
    assert features[ENVIRONMENT_KEY] == {"dtype": "float32", "shape": [10], "names": list(names)}
    assert features[REWARD_KEY] == {"dtype": "float32", "shape": [1], "names": None}
    assert features[SUCCESS_KEY] == {"dtype": "bool", "shape": [1], "names": None}
    table = data_table(root)
    assert table.schema.field(SUCCESS_KEY).type == pa.bool_() and table.schema.field(REWARD_KEY).type == pa.float32()
    assert column(table, SUCCESS_KEY).tolist() == [False] * 30 + [True] * 10
    assert column(table, ENVIRONMENT_KEY)[39].tolist() == [39.0] * 10
    row = episode_rows(root)[0]
    assert row[f"stats/{SUCCESS_KEY}/min"] == [False] and row[f"stats/{SUCCESS_KEY}/max"] == [True]
    assert row[f"stats/{SUCCESS_KEY}/mean"] == [0.25] and row[f"stats/{REWARD_KEY}/max"] == [1.0]
    stats = read_json(root / "meta/stats.json")
    assert stats[SUCCESS_KEY]["min"] == [False] and stats[ENVIRONMENT_KEY]["max"] == [39.0] * 10
    read_back = Dataset.open(root).episode_frames(0)
    assert read_back[SUCCESS_KEY].ravel().tolist() == [False] * 30 + [True] * 10
    assert read_back[ENVIRONMENT_KEY].shape == (40, 10)
    # A task's dataset takes only a task's episodes, and the other way round: one line each.
    with pytest.raises(DatasetError, match=r"holds a task's episodes .*: record them with --task$"):
        DatasetWriter.open(root, FPS, {})
    plain = tmp_path / "plain"
    record(plain, [("pick", 3)], video=False)
    with pytest.raises(DatasetError, match=r"holds episodes without a task: record a task's episodes \(--task\) in another folder$"):
        DatasetWriter.open(plain, FPS, {}, environment_names=names)
    # What the frames observe is the folder's too: one that shows the objects' poses takes no episode
    # without them, and the other way round.
    with pytest.raises(DatasetError, match=r"show the objects' poses \(observation.environment_state\): record with "
                                           r"--observe including environment, or use another folder$"):
        DatasetWriter.open(root, FPS, {}, environment_names=names, environment_state=False)


@pytest.mark.parametrize("text, task, video, problem", [
    ("state,environment,front,wrist", True, True, None),
    ("state,front,wrist", True, True, None),
    ("state, front", False, True, None),
    ("state,environment", False, False, "environment is a task's objects: it goes with --task"),
    ("state,wrist", False, True, "the wrist camera is drawn for a task's episodes: wrist goes with --task"),
    ("state,front", True, False, "front and wrist are the cameras, and there are none here (--no-video)"),
])
def test_what_the_frames_observe_reads_back_as_written_and_asks_for_no_more_than_the_body_has(text, task, video, problem):
    from so101.observe import observed_for, parse_observed

    observed = parse_observed(text)
    assert str(observed) == text.replace(" ", "") and parse_observed(str(observed)) == observed
    assert observed.problem(task, video) == problem
    assert observed_for(task, video).problem(task, video) is None  # all that the body has: the default
    if problem is None and video:
        assert list(video_keys_and_sizes((96, 72), task, observed)) == [
            key for key, shown in ((IMAGE_KEY, observed.front), (WRIST_IMAGE_KEY, observed.wrist)) if shown]


def test_a_dataset_that_leaves_the_objects_poses_out_keeps_reward_and_success(tmp_path: Path) -> None:
    """`--observe state,front,wrist`: a task's episodes without observation.environment_state, for a
    policy that sees; its reward and success stay (they are not observations)."""
    from so101.dataset.features import ENVIRONMENT_KEY, REWARD_KEY, SUCCESS_KEY
    from so101.tasks import CUBE_TO_BOX

    names = CUBE_TO_BOX.object_state_names
    root = tmp_path / "seen"
    with DatasetWriter.open(root, FPS, {}, environment_names=names, environment_state=False) as writer:
        episode = writer.start_episode("put the cube in the box")
        with pytest.raises(DatasetError, match="not a feature of this dataset"):
            episode.add_frame({**frame(0, 0, video=False), ENVIRONMENT_KEY: np.zeros(len(names), np.float32),
                               REWARD_KEY: np.array([0.0], np.float32), SUCCESS_KEY: np.array([False])})
        for i in range(5):
            episode.add_frame({**frame(0, i, video=False), REWARD_KEY: np.array([0.0], np.float32),
                               SUCCESS_KEY: np.array([False])})
        episode.save()
    assert list(read_json(root / "meta/info.json")["features"])[:4] == [ACTION_KEY, STATE_KEY, REWARD_KEY, SUCCESS_KEY]
    with pytest.raises(DatasetError, match=r"do not show the objects' poses .*: record with --observe without "
                                           r"environment, or use another folder$"):
        DatasetWriter.open(root, FPS, {}, environment_names=names)
