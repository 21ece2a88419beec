"""The spool of `so101 demos --workers`: episodes kept whole by each worker, added to the dataset in
order, make the dataset a single writer makes, byte for byte; an episode that cannot be added stays
whole in its spool; a half-kept one is never listed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from so101.dataset.layout import SEEDS_KEY, DatasetError
from so101.dataset.spool import EpisodeSpool, pop, spooled
from so101.dataset.writer import DatasetWriter
from tests.test_dataset_format import FPS, VIDEO, frame

LENGTHS = {0: 7, 1: 5, 2: 6}  # seed -> frames


def record(writer, seeds: list[int]) -> None:
    for seed in seeds:
        episode = writer.start_episode("pick")
        episode.seed = seed
        for i in range(LENGTHS[seed]):
            episode.add_frame(frame(seed, i))
        episode.save()


def files(root: Path) -> dict[str, bytes]:
    return {str(path.relative_to(root)): path.read_bytes() for path in sorted(root.rglob("*")) if path.is_file()}


def test_two_spools_merged_in_order_make_the_dataset_one_writer_makes(tmp_path):
    with DatasetWriter.open(tmp_path / "single", FPS, VIDEO) as writer:
        record(writer, [0, 1, 2])
    first, second = EpisodeSpool(tmp_path / "a", FPS, VIDEO), EpisodeSpool(tmp_path / "b", FPS, VIDEO)
    record(second, [2])  # the workers finish in any order
    record(first, [0, 1])
    first.close()
    second.close()
    assert [path.name for path in spooled(tmp_path / "a")] == ["episode-000000", "episode-000001"]
    with DatasetWriter.open(tmp_path / "merged", FPS, VIDEO) as writer:
        for episode in [*spooled(tmp_path / "a"), *spooled(tmp_path / "b")]:
            pop(episode, writer)
    assert spooled(tmp_path / "a") == spooled(tmp_path / "b") == []
    single, merged = files(tmp_path / "single"), files(tmp_path / "merged")
    assert "videos/observation.images.front/chunk-000/file-000.mp4" in single
    assert json.loads(single["meta/info.json"])[SEEDS_KEY] == {"0": 0, "1": 1, "2": 2}
    assert merged.keys() == single.keys()
    for name in single:
        assert merged[name] == single[name], name


def test_an_episode_that_cannot_be_added_stays_whole_in_its_spool(tmp_path):
    spool = EpisodeSpool(tmp_path / "spool", FPS, VIDEO)
    record(spool, [0])
    (episode,) = spooled(tmp_path / "spool")
    before = files(episode)
    writer = DatasetWriter.open(tmp_path / "dataset", FPS, VIDEO)
    writer.close()
    with pytest.raises(DatasetError, match="closed"):
        pop(episode, writer)
    assert spooled(tmp_path / "spool") == [episode] and files(episode) == before
    with DatasetWriter.open(tmp_path / "dataset", FPS, VIDEO) as writer:
        assert pop(episode, writer).length == LENGTHS[0]


def test_a_half_kept_episode_is_not_listed_and_the_count_goes_on(tmp_path):
    spool = EpisodeSpool(tmp_path / "spool", FPS, VIDEO)
    record(spool, [1])
    (tmp_path / "spool" / ".episode-000001").mkdir()  # a worker killed while keeping its next one
    assert [path.name for path in spooled(tmp_path / "spool")] == ["episode-000000"]
    again = EpisodeSpool(tmp_path / "spool", FPS, VIDEO)
    record(again, [2])
    assert [path.name for path in spooled(tmp_path / "spool")] == ["episode-000000", "episode-000001"]
