"""LeRobotDataset v3.0 on disk: its files, paths, schemas and metadata, read and written with
pyarrow only (no lerobot, torch, pandas).

The files are those LeRobot 0.4.x writes (lerobot/datasets/lerobot_dataset.py, utils.py,
compute_stats.py, video_utils.py; where its docs and its code differ, this follows the code):

    meta/info.json                         fps, features, totals, path templates, file-size limits
    meta/tasks.parquet                     task text (a pandas index) -> task_index
    meta/stats.json                        every feature's statistics over the dataset
    meta/episodes/chunk-000/file-000.parquet   one row per episode: frame range, tasks, where its
                                           data and videos are, its statistics flattened
    data/chunk-000/file-000.parquet        one row per frame, one row group per episode
    videos/<key>/chunk-000/file-000.mp4    each video feature's episodes one after another

As in LeRobot, every writer session (writer.DatasetWriter.open) starts new data, video and
episode files; within a session each episode is added to them until a file would pass its size
limit (info.json's data_files_size_in_mb, video_files_size_in_mb), and after chunks_size files
the next chunk folder starts. How a save stays whole through a crash: commit.py.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from so101.dataset.features import ACTION_KEY, ENVIRONMENT_KEY, MOTOR_NAMES, REWARD_KEY, STATE_KEY, SUCCESS_KEY
from so101.dataset.stats import STAT_KEYS

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


class DatasetError(ValueError):
    """What is wrong with a dataset or a request, and what is accepted: str() is one line."""

    def __init__(self, message: str):
        super().__init__(" ".join(message.split()))


@dataclass(frozen=True)
class EpisodeSummary:
    index: int
    length: int  # frames
    tasks: tuple[str, ...]
    duration_s: float


# In info.json, beside LeRobot's keys: {episode index: the seed its task's layout was made from}, for
# the episodes made from a seed (`so101 demos`, `so101 eval`'s runner); LeRobot ignores it.
SEEDS_KEY = "so101_episode_seeds"
# Each episode's scenario (so101.bodies.scenario: its physics, and with pictures their looks and where its
# cameras stood, as drawn), by episode index.
SCENARIOS_KEY = "so101_episode_scenarios"
# Where datasets written before SCENARIOS_KEY kept them: looks and physics by episode index, cameras a list.
OLD_LOOKS_KEY, OLD_CAMERAS_KEY, OLD_PHYSICS_KEY = "so101_episode_looks", "so101_episode_cameras", "so101_episode_physics"


def episode_scenario(info: Mapping[str, Any], episode: int) -> dict[str, Any]:
    """What info.json keeps of episode `episode`'s scenario ({} for none): "physics", "looks", "cameras", those
    it has; read from the keys of datasets written before SCENARIOS_KEY too."""
    kept = info.get(SCENARIOS_KEY, {}).get(str(episode))
    if kept is not None:
        return dict(kept)
    older: dict[str, Any] = {}
    for name, key in (("looks", OLD_LOOKS_KEY), ("physics", OLD_PHYSICS_KEY)):
        if str(episode) in info.get(key, {}):
            older[name] = info[key][str(episode)]
    cameras = info.get(OLD_CAMERAS_KEY, [])
    if episode < len(cameras) and cameras[episode] is not None:
        older["cameras"] = cameras[episode]
    return older


def recorder_features(video_sizes: Mapping[str, tuple[int, int]],
                      environment_names: Sequence[str] = (), environment_state: bool = True) -> dict[str, dict[str, Any]]:
    """The features a DatasetWriter writes, in LeRobot's order: ours, then LeRobot's defaults.

    video_sizes: each video feature's (width, height), e.g. {IMAGE_KEY: (320, 240)}; {} for none.
    environment_names: a task's object_state names (so101.tasks); with them, a frame also holds
    the environment state (unless not `environment_state`: a dataset for a policy that sees), the
    reward and success, as LeRobot's simulation datasets do."""
    features: dict[str, dict[str, Any]] = {
        ACTION_KEY: {"dtype": "float32", "shape": [len(MOTOR_NAMES)], "names": list(MOTOR_NAMES)},
        STATE_KEY: {"dtype": "float32", "shape": [len(MOTOR_NAMES)], "names": list(MOTOR_NAMES)},
    }
    if environment_names and environment_state:
        features[ENVIRONMENT_KEY] = {"dtype": "float32", "shape": [len(environment_names)],
                                     "names": list(environment_names)}
    for key, (width, height) in video_sizes.items():
        features[key] = {"dtype": "video", "shape": [height, width, 3], "names": ["height", "width", "channels"]}
    if environment_names:
        features[REWARD_KEY] = {"dtype": "float32", "shape": [1], "names": None}
        features[SUCCESS_KEY] = {"dtype": "bool", "shape": [1], "names": None}
    return {**features, **json.loads(json.dumps(DEFAULT_FEATURES))}


def frame_features(features: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """The features a frame is given (add_frame's keys): all but those the writer fills in."""
    return {key: feature for key, feature in features.items() if key not in DEFAULT_FEATURES}


def video_keys(features: dict[str, dict[str, Any]]) -> list[str]:
    return [key for key, feature in features.items() if feature.get("dtype") == "video"]


def write_json(path: Path, data: Any) -> None:
    """json.dump as LeRobot's write_json: indent 4, UTF-8 as is (the caller fsyncs)."""
    with open(path, "w", encoding="utf-8") as file:
        json.dump(data, file, indent=4, ensure_ascii=False)


def load_info(root: Path) -> dict[str, Any]:
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
                           f"(`so101 dataset {root} --convert` runs LeRobot's own converter on it)")
    return info


def read_tasks(root: Path) -> list[str]:
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


def tasks_table(tasks: list[str]) -> pa.Table:
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


def read_episode_rows(root: Path) -> list[dict[str, Any]]:
    """Every episode's row of meta/episodes (without its statistics), by episode_index."""
    rows: list[dict[str, Any]] = []
    for path in sorted((root / EPISODES_DIR).glob("*/*.parquet")):
        schema = pq.read_schema(path)
        columns = [name for name in schema.names if not name.startswith("stats/")]
        rows.extend(pq.read_table(path, columns=columns).to_pylist())
    return sorted(rows, key=lambda row: int(row["episode_index"]))


def summary(row: dict[str, Any], fps: int) -> EpisodeSummary:
    length = int(row["length"])
    return EpisodeSummary(int(row["episode_index"]), length, tuple(str(t) for t in row.get("tasks") or ()),
                          length / fps)


def describe(episodes: list[EpisodeSummary]) -> str:
    if not episodes:
        return "it has no episodes"
    indices = [e.index for e in episodes]
    if indices == list(range(indices[0], indices[-1] + 1)):
        return f"it has episodes {indices[0]}-{indices[-1]}" if len(indices) > 1 else f"it has episode {indices[0]}"
    return "it has episodes " + ", ".join(str(i) for i in indices)


def next_file(chunk_index: int, file_index: int, chunks_size: int) -> tuple[int, int]:
    """LeRobot's update_chunk_file_indices: the next file, in the next chunk after chunks_size files."""
    if file_index == chunks_size - 1:
        return chunk_index + 1, 0
    return chunk_index, file_index + 1


def data_schema(features: dict[str, dict[str, Any]]) -> pa.Schema:
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


def episode_row_schema(features: dict[str, dict[str, Any]]) -> pa.Schema:
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
        is_bool = feature["dtype"] == "bool"
        for stat in STAT_KEYS:
            if stat == "count":
                fields.append((f"stats/{key}/{stat}", pa.list_(pa.int64())))
            elif is_image:
                fields.append((f"stats/{key}/{stat}", pa.list_(pa.list_(pa.list_(pa.float64())))))
            elif is_int and stat in ("min", "max"):
                fields.append((f"stats/{key}/{stat}", pa.list_(pa.int64())))
            elif is_bool and stat in ("min", "max"):  # numpy's min and max of bools are bools
                fields.append((f"stats/{key}/{stat}", pa.list_(pa.bool_())))
            else:
                fields.append((f"stats/{key}/{stat}", pa.list_(pa.float64())))
    fields += [("meta/episodes/chunk_index", pa.int64()), ("meta/episodes/file_index", pa.int64())]
    return pa.schema(fields)
