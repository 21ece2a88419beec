"""LeRobot itself reads the datasets this project writes: a check to run by hand, in a venv that has
LeRobot 0.4.x (torch and all), never the project's own (the test suite does not run it).

    /tmp/lerobot-venv/bin/python tools/check_with_lerobot.py           # make a dataset with the project's writer, check it
    /tmp/lerobot-venv/bin/python tools/check_with_lerobot.py DIR ...   # check datasets that exist

With no DIR it runs the project's interpreter (--project-python, default .venv/bin/python beside
this folder) to record 3 episodes in 2 writer sessions with 320x240 video, as the recorder node
does. For each dataset, LeRobot's own code must:
  1. load it: LeRobotDataset("local/check", root=DIR), offline (HF_HUB_OFFLINE=1), decoding video with
     torchcodec (LeRobot's default) where it loads, else PyAV (torchcodec needs FFmpeg's shared libraries);
  2. give every item as the files hold it: each numeric column (a task's environment state, reward and
     success among them) equal to the data parquet's row,
     the task text, and the video frame at from_timestamp + timestamp (decoded by LeRobot, compared
     with PyAV's decoding of the same mp4);
  3. compute the same statistics: compute_episode_stats on each episode's columns against the
     episode rows' stats/*, aggregate_stats of those against meta/stats.json (pictures aside:
     LeRobot 0.4.x's image std overflows uint8, the project's does not);
  4. append to it: a copy resumed with LeRobotDataset + add_frame + save_episode + finalize, then
     loaded again with one more episode; then the project's writer appends another to that copy
     and the project's reader reads every episode of it, and LeRobot loads it once more.
Prints one line per check; exits 1 at the first failure.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")  # a complete local dataset needs no network; never fetch

import av  # noqa: E402
import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402

try:
    from lerobot.datasets.compute_stats import aggregate_stats, compute_episode_stats
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
except ImportError:
    sys.exit("check_with_lerobot: LeRobot is not importable here: run this with a venv that has lerobot 0.4.x "
             "(e.g. /tmp/lerobot-venv/bin/python), not the project's")

REPO = Path(__file__).resolve().parents[1]
VIDEO_KEY = "observation.images.front"
# The columns LeRobot fills in itself; a frame given to add_frame holds the others.
DEFAULT_KEYS = ("timestamp", "frame_index", "episode_index", "index", "task_index")


def video_backend() -> str:
    """LeRobot's default decoder, torchcodec, where it loads (it needs FFmpeg's shared libraries);
    PyAV, LeRobot's other one, where it does not."""
    try:
        import torchcodec.decoders  # noqa: F401
    except Exception:  # noqa: BLE001 - torchcodec raises RuntimeError, OSError or ImportError
        return "pyav"
    return "torchcodec"


BACKEND = video_backend()


def numeric_keys(features: dict) -> list[str]:
    return [key for key, feature in features.items() if feature["dtype"] not in ("video", "image", "string")]


def frame_for(features: dict, i: int) -> dict:
    """A frame for add_frame: every feature but LeRobot's own, filled with `i` (bools: i is odd)."""
    frame = {}
    for key, feature in features.items():
        if key in DEFAULT_KEYS:
            continue
        shape = tuple(feature["shape"])
        if feature["dtype"] == "video":
            frame[key] = np.full(shape, 128, dtype=np.uint8)
        else:
            frame[key] = np.full(shape, i % 2 == 1 if feature["dtype"] == "bool" else i, dtype=feature["dtype"])
    return frame

MAKE = """
import sys
import numpy as np
from pathlib import Path
from so101.dataset.writer import DatasetWriter
root = Path(sys.argv[1])
W, H = 320, 240
def picture(seed, i):
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    img = np.stack([60 + 120 * x / W, 80 + 100 * y / H, 120 + 60 * np.sin((x + y) / 40 + seed)], axis=-1)
    left = 20 + (3 * i) % 200
    box = np.clip(np.minimum(np.minimum(x - left, left + 60 - x), np.minimum(y - 80, 140 - y)) / 3 + 0.5, 0, 1)
    img = img * (1 - box[..., None]) + np.array([230, 200, 40]) * box[..., None]
    return np.clip(img, 0, 255).astype(np.uint8)
for session, episodes in enumerate([[("pick the cube", 45), ("place the cube", 30)], [("pick the cube", 38)]]):
    with DatasetWriter.open(root, 30, {"observation.images.front": (W, H)}) as writer:
        for n, (task, length) in enumerate(episodes):
            seed = 10 * session + n
            episode = writer.start_episode(task)
            for i in range(length):
                t = i / 30
                action = np.array([seed + t, 40 * np.sin(t), -30 + 5 * t, 20 * np.cos(2 * t), 90 * np.sin(t / 2),
                                   50 + 40 * np.sin(3 * t)], dtype=np.float32)
                episode.add_frame({"observation.state": action - np.float32(0.5), "action": action,
                                   "observation.images.front": picture(seed, i)})
            episode.save()
"""


def fail(message: str) -> None:
    print(f"FAIL {message}")
    sys.exit(1)


def ok(message: str) -> None:
    print(f"ok   {message}")


def read_data(root: Path) -> dict[str, np.ndarray]:
    tables = [pq.read_table(path) for path in sorted((root / "data").glob("*/*.parquet"))]
    columns: dict[str, np.ndarray] = {}
    for name in tables[0].column_names:
        parts = [table.column(name).combine_chunks() for table in tables]
        if pa.types.is_fixed_size_list(parts[0].type):
            columns[name] = np.concatenate([p.flatten().to_numpy().reshape(len(p), p.type.list_size) for p in parts])
        else:
            columns[name] = np.concatenate([p.to_numpy(zero_copy_only=False) for p in parts])
    return columns


def episode_rows(root: Path) -> list[dict]:
    rows: list[dict] = []
    for path in sorted((root / "meta/episodes").glob("*/*.parquet")):
        rows += pq.read_table(path).to_pylist()
    return rows


class PyAVFrames:
    """Frames of one mp4 by time, decoded once in order (items come in order)."""

    def __init__(self, path: Path):
        self.path = path
        self._open()

    def _open(self) -> None:
        self._container = av.open(str(self.path))
        self._half_frame_s = 0.5 / float(self._container.streams.video[0].average_rate)
        self._frames = self._container.decode(video=0)
        self._current = next(self._frames)

    def at(self, seconds: float) -> np.ndarray:
        if self._current.time > seconds + self._half_frame_s:  # asked for an earlier frame: start again
            self._container.close()
            self._open()
        while self._current.time < seconds - self._half_frame_s:
            self._current = next(self._frames)
        if abs(self._current.time - seconds) > self._half_frame_s:
            raise LookupError(f"no frame at {seconds} s in {self.path}")
        return self._current.to_ndarray(format="rgb24")


def check_items(root: Path) -> None:
    dataset = LeRobotDataset("local/check", root=root, video_backend=BACKEND)
    info = json.loads((root / "meta/info.json").read_text())
    data = read_data(root)
    rows = episode_rows(root)
    tasks = pq.read_table(root / "meta/tasks.parquet").column("__index_level_0__").to_pylist()
    if len(dataset) != info["total_frames"] or dataset.num_episodes != info["total_episodes"]:
        fail(f"{root}: LeRobot sees {len(dataset)} frames / {dataset.num_episodes} episodes, info.json says "
             f"{info['total_frames']} / {info['total_episodes']}")
    ok(f"{root}: LeRobotDataset loads it: {dataset.num_episodes} episodes, {len(dataset)} frames, "
       f"video keys {dataset.meta.video_keys}")
    worst_pixel = 0.0
    decoders: dict[Path, PyAVFrames] = {}
    for i in range(len(dataset)):
        item = dataset[i]
        for key in numeric_keys(info["features"]):
            if not np.array_equal(item[key].numpy(), data[key][i]):
                fail(f"item {i} {key}: LeRobot gives {item[key].numpy()}, the parquet has {data[key][i]}")
        if item["task"] != tasks[int(data["task_index"][i])]:
            fail(f"item {i}: task {item['task']!r}, tasks.parquet says {tasks[int(data['task_index'][i])]!r}")
        for key in dataset.meta.video_keys:
            row = rows[int(data["episode_index"][i])]
            path = root / info["video_path"].format(video_key=key, chunk_index=row[f"videos/{key}/chunk_index"],
                                                    file_index=row[f"videos/{key}/file_index"])
            decoder = decoders.setdefault(path, PyAVFrames(path))
            expected = decoder.at(row[f"videos/{key}/from_timestamp"] + float(data["timestamp"][i]))
            got = (item[key].numpy().transpose(1, 2, 0) * 255).round()
            worst_pixel = max(worst_pixel, float(np.abs(got - expected).mean()))
    if worst_pixel > 2.0:
        fail(f"LeRobot's video frames differ from PyAV's decoding by {worst_pixel:.2f} levels on average")
    video = (f", video frames (LeRobot's decoding vs PyAV's: at most {worst_pixel:.2f} levels mean difference)"
             if dataset.meta.video_keys else " (no video)")
    ok(f"all {len(dataset)} items equal the files: numeric columns exactly ({', '.join(numeric_keys(info['features']))}), "
       f"task texts{video} (LeRobot's video backend: {BACKEND})")


def same_stat(stat: str, ours: np.ndarray, theirs: np.ndarray, stats: dict) -> bool:
    """The project's stats are float64; LeRobot's mean and std of float32 data are float32 running
    sums, std = sqrt(E[x²] - E[x]²). A float32 sum of n values can be off by n × 2⁻²⁴ of the sum of
    their sizes, so that (at least 1e-5, which 211 frames of a held gripper needed) bounds both: the
    mean's error against the largest value's size (a joint swinging ±70° about a mean of 1.7° over
    230 frames had LeRobot's mean 2.6e-5 from the exact one), the variance's against E[x²]."""
    ours, theirs = np.asarray(ours, dtype=np.float64), np.asarray(theirs, dtype=np.float64)
    mean = np.asarray(stats["mean"], dtype=np.float64)
    relative = max(1e-5, float(np.max(stats["count"])) * 2.0**-24)
    if stat == "std":
        bound = relative * (mean**2 + ours**2) + 1e-12
        return bool(np.all(np.abs(ours**2 - theirs**2) <= bound))
    if stat == "mean":
        size = np.maximum(np.abs(np.asarray(stats["min"], dtype=np.float64)), np.abs(np.asarray(stats["max"], dtype=np.float64)))
        return bool(np.all(np.abs(ours - theirs) <= relative * size + 1e-6))
    return bool(np.allclose(ours, theirs, rtol=1e-5, atol=1e-6))  # float32 sums again


def check_stats(root: Path) -> None:
    info = json.loads((root / "meta/info.json").read_text())
    features = {key: {**ft, "shape": tuple(ft["shape"])} for key, ft in info["features"].items() if ft["dtype"] != "video"}
    data = read_data(root)
    episode_stats = []
    for row in episode_rows(root):
        part = slice(row["dataset_from_index"], row["dataset_to_index"])
        buffer = {key: data[key][part] for key in features}
        # LeRobot's add_frame keeps timestamps as Python floats (frame_index / fps) until it saves.
        buffer["timestamp"] = data["frame_index"][part] / info["fps"]
        theirs = compute_episode_stats(buffer, features)
        for key, stats in theirs.items():
            for stat, value in stats.items():
                ours = np.array(row[f"stats/{key}/{stat}"])
                if not same_stat(stat, ours, value, stats):
                    fail(f"episode {row['episode_index']} {key} {stat}: ours {ours}, LeRobot's {value}")
        episode_stats.append(theirs)
    aggregated = aggregate_stats(episode_stats)
    ours = json.loads((root / "meta/stats.json").read_text())
    for key, stats in aggregated.items():
        for stat, value in stats.items():
            if not same_stat(stat, np.array(ours[key][stat]), value, stats):
                fail(f"stats.json {key} {stat}: ours {ours[key][stat]}, LeRobot's {value}")
    ok(f"per-episode stats and stats.json equal LeRobot's compute_episode_stats / aggregate_stats "
       f"({len(features)} numeric features, {len(episode_stats)} episodes)")


PROJECT_APPENDS = """
import sys
import numpy as np
from pathlib import Path
from so101.dataset.reader import Dataset
from so101.dataset.writer import DatasetWriter
root = Path(sys.argv[1])
dataset = Dataset.open(root)
sizes = {key: (f["shape"][1], f["shape"][0]) for key, f in dataset.features.items() if f["dtype"] == "video"}
environment = dataset.features.get("observation.environment_state", {}).get("names") or ()
own = ("timestamp", "frame_index", "episode_index", "index", "task_index")
with DatasetWriter.open(root, dataset.fps, sizes, environment_names=environment) as writer:
    episode = writer.start_episode("appended by so101")
    for i in range(9):
        episode.add_frame({key: np.full(f["shape"], 90 if f["dtype"] == "video" else i,
                                        dtype="uint8" if f["dtype"] == "video" else f["dtype"])
                           for key, f in dataset.features.items() if key not in own})
    episode.save()
dataset = Dataset.open(root)
for e in dataset.episodes:
    assert len(dataset.episode_frames(e.index)["index"]) == e.length
    for key in dataset.video_keys:
        assert len(list(dataset.episode_images(e.index, key))) == e.length
print(len(dataset.episodes))
"""


def check_append(root: Path, project_python: Path) -> None:
    with tempfile.TemporaryDirectory() as scratch:
        copy = Path(scratch) / "copy"
        shutil.copytree(root, copy)
        dataset = LeRobotDataset("local/check", root=copy, video_backend=BACKEND)
        before = dataset.num_episodes
        for i in range(12):
            dataset.add_frame({**frame_for(dataset.features, i), "task": "appended by LeRobot"})
        dataset.save_episode()
        dataset.finalize()
        again = LeRobotDataset("local/check", root=copy, video_backend=BACKEND)
        if again.num_episodes != before + 1:
            fail(f"after LeRobot appended an episode it sees {again.num_episodes} episodes, not {before + 1}")
        for i in range(len(again)):
            again[i]
        ok(f"LeRobot appends to it (episode {before}, in its next files) and reads all {len(again)} items back")
        if not project_python.exists():
            print(f"skip the project's writer after LeRobot's: no {project_python}")
            return
        done = subprocess.run([str(project_python), "-c", PROJECT_APPENDS, str(copy)], cwd=REPO, check=True,
                              capture_output=True, text=True)
        if done.stdout.split()[-1] != str(before + 2):
            fail(f"the project's reader sees {done.stdout.split()[-1]} episodes after its append, not {before + 2}")
        final = LeRobotDataset("local/check", root=copy, video_backend=BACKEND)
        for i in range(len(final)):
            final[i]
        if final.num_episodes != before + 2:
            fail(f"LeRobot sees {final.num_episodes} episodes after the project's append, not {before + 2}")
        ok(f"then the project's writer appends episode {before + 1}, its reader reads all {before + 2} episodes "
           f"and LeRobot all {len(final)} items")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("roots", nargs="*", type=Path, metavar="DIR", help="datasets to check (default: make one)")
    parser.add_argument("--project-python", type=Path, default=REPO / ".venv/bin/python",
                        help="the project's interpreter, to make a dataset (default .venv/bin/python)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        roots = args.roots
        if not roots:
            made = Path(scratch) / "made-by-so101"
            subprocess.run([str(args.project_python), "-c", MAKE, str(made)], check=True, cwd=REPO)
            print(f"made {made} with so101.dataset.writer ({args.project_python})")
            roots = [made]
        for root in roots:
            check_items(root)
            check_stats(root)
            check_append(root, args.project_python)
    return 0


if __name__ == "__main__":
    sys.exit(main())
