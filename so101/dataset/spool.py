"""A spool: finished episodes kept whole in a folder, each ready for DatasetWriter.commit_episode.

What a worker of `so101 demos --workers K` writes instead of a dataset: K workers cannot append to
one dataset in seed order, so each keeps its episodes here, and the command adds them to the
dataset in seed order (`pop`). An episode is what the writer's own save takes (its frame columns,
its finished videos and their pictures' histograms), so the merged dataset is the one a single
run writes, byte for byte. Each episode is a folder `episode-NNNNNN` made whole under another name
and renamed: a worker killed mid-save leaves no half episode.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from so101.dataset import video as videos
from so101.dataset.commit import WORK_DIR, CommitIncomplete
from so101.dataset.episode import EpisodeRecorder
from so101.dataset.layout import DatasetError, EpisodeSummary, frame_features, recorder_features
from so101.dataset.stats import image_histogram

if TYPE_CHECKING:
    from so101.dataset.writer import DatasetWriter

PREFIX = "episode-"
COLUMNS_FILE = "columns.npz"
META_FILE = "episode.json"


def _histograms_file(key: str) -> str:
    return f"{key}.histograms.npy"


class EpisodeSpool:
    """Episodes saved into `folder` in the order they are saved (EpisodeRecorder.save), one folder each."""

    def __init__(self, folder: Path, fps: int, video_sizes: Mapping[str, tuple[int, int]],
                 environment_names: Sequence[str] = (), environment_state: bool = True):
        self.folder = Path(folder)
        self.fps = fps
        self.video_sizes = dict(video_sizes)
        self.features = recorder_features(self.video_sizes, environment_names, environment_state)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            (self.folder / "work").mkdir(exist_ok=True)
        except OSError as error:
            raise DatasetError(f"cannot keep episodes in {self.folder}: {error.strerror or error}") from None
        self._count = len(spooled(self.folder))

    def start_episode(self, task: str) -> EpisodeRecorder:
        encoders = {key: videos.StreamingEncoder(self.folder / "work" / f"{self._count}-{key}.mp4", self.fps, width,
                                                 height, inspect=image_histogram)
                    for key, (width, height) in self.video_sizes.items()}
        return EpisodeRecorder(self, task, frame_features(self.features), encoders)  # type: ignore[arg-type]

    def episode_ended(self) -> None:
        """The recorder's call when an episode with video is saved or dropped: nothing to tidy here."""

    def commit_episode(self, task: str, columns: dict[str, np.ndarray],
                       encoded: dict[str, videos.EncodedVideo], seed: int | None = None,
                       scenario: dict[str, object] | None = None) -> EpisodeSummary:
        number = self._count
        staging = self.folder / f".{PREFIX}{number:06d}"
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir()
        np.savez(staging / COLUMNS_FILE, **columns)  # type: ignore[arg-type]
        meta: dict[str, Any] = {"task": task, "seed": seed, "scenario": scenario, "videos": {}}
        for key, video in encoded.items():
            os.replace(video.path, staging / f"{key}.mp4")
            np.save(staging / _histograms_file(key), np.stack(video.inspected))
            meta["videos"][key] = {"frames": video.frames, "duration_s": video.duration_s}
        (staging / META_FILE).write_text(json.dumps(meta), encoding="utf-8")
        os.replace(staging, self.folder / f"{PREFIX}{number:06d}")
        self._count += 1
        length = len(next(iter(columns.values())))
        return EpisodeSummary(number, length, (task,), length / self.fps)

    def close(self) -> None:
        shutil.rmtree(self.folder / "work", ignore_errors=True)


def spooled(folder: Path) -> list[Path]:
    """The whole episodes in `folder`, in the order they were saved."""
    if not folder.is_dir():
        return []
    return sorted(path for path in folder.iterdir() if path.name.startswith(PREFIX) and path.is_dir())


def pop(episode: Path, writer: DatasetWriter) -> EpisodeSummary:
    """Add a spooled episode to `writer`'s dataset, then remove it from the spool. Its videos move
    into the dataset's work folder first: a save names the files it moves by their place in the
    dataset, so that the next open completes a save a crash cut short."""
    meta = json.loads((episode / META_FILE).read_text(encoding="utf-8"))
    with np.load(episode / COLUMNS_FILE) as stored:
        columns = {key: stored[key] for key in stored.files}
    work = writer.root / WORK_DIR
    work.mkdir(exist_ok=True)
    encoded = {}
    for key, info in meta["videos"].items():
        moved = work / f"spooled-{os.getpid()}-{episode.name}-{key}.mp4"
        shutil.move(episode / f"{key}.mp4", moved)
        encoded[key] = videos.EncodedVideo(moved, int(info["frames"]), float(info["duration_s"]),
                                           list(np.load(episode / _histograms_file(key))))
    try:
        summary = writer.commit_episode(meta["task"], columns, encoded, meta.get("seed"), meta.get("scenario"))
    except CommitIncomplete:
        raise  # its videos stay where its journal names them, for the next open
    except BaseException:
        for key, video in encoded.items():  # back where they were: the episode stays whole in the spool
            shutil.move(video.path, episode / f"{key}.mp4")
        raise
    for video in encoded.values():
        video.path.unlink(missing_ok=True)  # joined into the dataset's file, or moved there
    try:
        work.rmdir()
    except OSError:
        pass  # another episode's files are in it
    shutil.rmtree(episode, ignore_errors=True)
    return summary
