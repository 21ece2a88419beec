"""One episode being recorded: its frames checked against the dataset's features, its rows in
memory, each video feature encoding as its pictures come; saved whole or dropped."""

from __future__ import annotations

import threading
from typing import Any, Mapping, Protocol

import numpy as np

from so101.dataset import video as videos
from so101.dataset.commit import CommitIncomplete
from so101.dataset.layout import DatasetError, EpisodeSummary



class EpisodeSink(Protocol):
    """Where a recorded episode goes (so101.dataset.writer.DatasetWriter): the recorder knows it by this only."""

    def commit_episode(self, task: str, columns: dict[str, np.ndarray], encoded: dict[str, videos.EncodedVideo],
                       seed: int | None = None, scenario: dict[str, object] | None = None) -> EpisodeSummary:
        """The episode added to the dataset, its summary returned."""

    def episode_ended(self) -> None:
        """The episode was saved or dropped."""


def _expected(feature: dict[str, Any]) -> str:
    """What a frame's value of `feature` must be, in words."""
    shape = tuple(feature["shape"])
    if feature["dtype"] == "video":
        return f"{shape} uint8 (RGB)"
    names = feature.get("names")
    if isinstance(names, list) and len(names) == int(np.prod(shape)):
        return f"{len(names)} values ({', '.join(str(name) for name in names)}), {feature['dtype']}"
    return f"shape {shape} {feature['dtype']}"


def checked_frame(frame: Mapping[str, Any], features: dict[str, dict[str, Any]]) -> dict[str, np.ndarray]:
    """`frame`'s values as the dataset stores them, or a one-line DatasetError naming the
    key at fault: every feature must be there and nothing else, each of its shape, and of its
    dtype or one that converts to it within its kind (float64 to float32); pictures are uint8."""
    missing = [key for key in features if key not in frame]
    extra = [key for key in frame if key not in features]
    if missing or extra:
        key = (missing or extra)[0]
        problem = f"has no {key!r}" if missing else f"has {key!r}, which is not a feature of this dataset"
        raise DatasetError(f"the frame {problem}: a frame holds {', '.join(features)}")
    checked = {}
    for key, feature in features.items():
        value = np.asarray(frame[key])
        dtype = np.dtype("uint8" if feature["dtype"] == "video" else feature["dtype"])
        fits = (value.dtype == dtype if feature["dtype"] == "video"
                else np.can_cast(value.dtype, dtype, casting="same_kind"))
        if value.shape != tuple(feature["shape"]) or not fits:
            raise DatasetError(f"{key} has shape {value.shape} {value.dtype}: it must be {_expected(feature)}")
        # Numbers are copied (the caller may reuse its arrays); an encoder copies the pictures it takes.
        checked[key] = value if feature["dtype"] == "video" else np.array(value, dtype=dtype, copy=True)
    return checked


class EpisodeRecorder:
    """One episode being recorded (DatasetWriter.start_episode): frames in, then save() or discard()."""

    def __init__(self, writer: EpisodeSink, task: str, features: dict[str, dict[str, Any]],
                 encoders: dict[str, videos.StreamingEncoder]):
        self._writer = writer
        self.task = task
        self.features = features  # a frame's keys: the dataset's features but those the writer fills in
        self._encoders = encoders  # one per video feature
        self._columns: dict[str, list[np.ndarray]] = {key: [] for key in features if key not in encoders}
        self._encoded: dict[str, videos.EncodedVideo] = {}
        self._saved: EpisodeSummary | None = None
        self._discarded = False
        self._lock = threading.Lock()
        self.frames = 0  # frames added so far
        self.seed: int | None = None  # a task's episode: the seed of its layout, kept in info.json (layout.SEEDS_KEY)
        # its scenario as drawn (so101.bodies.scenario.Scenario.metadata), kept beside (layout.SCENARIOS_KEY)
        self.scenario: dict[str, object] | None = None

    def add_frame(self, frame: Mapping[str, Any]) -> None:
        """One frame: a value for each of the dataset's features (self.features), e.g.
        {"observation.state": float32[6], "action": float32[6] (LeRobot's units: features.to_lerobot),
        "observation.images.front": (height, width, 3) uint8} for a dataset with that video."""
        if self._saved is not None or self._discarded:
            raise DatasetError("this episode is already " + ("saved" if self._saved else "discarded")
                               + ": start a new one to add frames")
        checked = checked_frame(frame, self.features)  # all of it, before any of it is kept
        for key, encoder in self._encoders.items():
            encoder.add(checked[key])
        for key, rows in self._columns.items():
            rows.append(checked[key])
        self.frames += 1

    def save(self) -> EpisodeSummary:
        """Commit the episode to the dataset: may take seconds (each video is joined to its file's);
        safe in a background thread. A failure (a full disk...) leaves the dataset as it was."""
        with self._lock:
            if self._saved is not None:
                return self._saved
            if self._discarded:
                raise DatasetError("this episode was discarded: it cannot be saved")
            if self.frames == 0:
                raise DatasetError("an episode of 0 frames is not saved: add frames first, or discard it")
            for key, encoder in self._encoders.items():
                if key in self._encoded:
                    continue
                try:
                    self._encoded[key] = encoder.finish()
                except videos.VideoWriteError as error:
                    self._drop_videos()
                    self._discarded = True
                    raise DatasetError(f"the episode's video {key} could not be written ({error}): the episode is "
                                       "not saved") from None
                if self._encoded[key].frames != self.frames:
                    raise DatasetError(f"the episode's video {key} has {self._encoded[key].frames} frames for "
                                       f"{self.frames} rows: the episode is not saved")
            columns = {key: np.stack(rows) for key, rows in self._columns.items()}
            try:
                self._saved = self._writer.commit_episode(self.task, columns, dict(self._encoded), self.seed,
                                                           self.scenario)
            except CommitIncomplete:
                # Its videos may still be in the work folder, named by the journal: kept for the next open.
                self._discarded = True
                raise
            if self._encoders:
                for encoded in self._encoded.values():
                    encoded.path.unlink(missing_ok=True)  # joined into the dataset's file, or moved there
                self._writer.episode_ended()
            self._columns = {key: [] for key in self._columns}  # the rows are in the dataset now
            return self._saved

    def discard(self) -> None:
        """Drop the episode: nothing of it stays on disk."""
        with self._lock:
            if self._saved is not None or self._discarded:
                return
            self._discarded = True
            self._drop_videos()
            self._columns = {key: [] for key in self._columns}

    def _drop_videos(self) -> None:
        for encoder in self._encoders.values():
            encoder.cancel()  # stops it if it is still encoding; removes its file either way
        if self._encoders:
            self._writer.episode_ended()
