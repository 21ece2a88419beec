"""The project's LeRobotDataset v3.0 reader reads what LeRobot 0.4.x writes.

Two sources, neither of them the project's writer:
* tests/helpers/lerobot_written.py, which writes datasets the way LeRobot 0.4.x does, by code of its own,
  here with and without video and in one file or spread over several data, video and
  episode-metadata files across chunks;
* tests/data/lerobot_made/, a small dataset that LeRobot 0.4.4 itself wrote (its README says how).

The last tests check the fixture against LeRobot: from the same inputs it writes the same files as
tests/data/lerobot_made/ (and, where a colleague left one, like /tmp/lerobot_made).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tests.helpers import lerobot_written as lw

MADE = Path(__file__).parent / "data" / "lerobot_made"
TMP_MADE = Path("/tmp/lerobot_made")
KEY = lw.IMAGE_KEY
FPS = 30
WIDTH, HEIGHT = 64, 48
LENGTHS = [6, 5, 7, 4, 8, 3, 5]
TASKS = ["pick the cube", "place the cube", "pick the cube", "wave", "place the cube", "pick the cube", "wave"]
# "several": 7 episodes in 4 data files (<= 12 frames), 3 video files (<= 16 frames) and 3
# episode-metadata files (3 episodes, row groups of 2), 2 files a chunk: all grouped differently.
LAYOUTS = {
    "one": {},
    "several": {
        "frames_per_data_file": 12,
        "frames_per_video_file": 16,
        "episodes_per_meta_file": 3,
        "chunks_size": 2,
        "metadata_buffer_size": 2,
    },
}


def make_episodes(with_video: bool) -> list[dict]:
    rng = np.random.default_rng(7)
    episodes = []
    for n, (length, task) in enumerate(zip(LENGTHS, TASKS)):
        episode = {
            "task": task,
            "action": rng.normal(0, 50, size=(length, 6)).astype(np.float32),
            "observation.state": rng.normal(0, 50, size=(length, 6)).astype(np.float32),
        }
        if with_video:
            episode["images"] = lw.structured_frames(length, seed=n, width=WIDTH, height=HEIGHT)
        episodes.append(episode)
    # Values a careless float conversion would change.
    episodes[0]["action"][0] = [np.float32(0.1), -0.0, np.float32(1e-30), np.float32(1.5e18), np.float32(-123.456), 100.0]
    return episodes


@pytest.fixture(scope="module", params=[(video, layout) for video in (False, True) for layout in LAYOUTS], ids=lambda p: f"{'video' if p[0] else 'no_video'}-{p[1]}")
def written(request, tmp_path_factory):
    """(root, episodes, with_video, layout) of a dataset written by tests/helpers/lerobot_written.py."""
    with_video, layout = request.param
    episodes = make_episodes(with_video)
    root = tmp_path_factory.mktemp("lerobot") / "dataset"
    lw.write_lerobot_dataset(root, episodes, fps=FPS, with_video=with_video, image_size=(WIDTH, HEIGHT), **LAYOUTS[layout])
    return root, episodes, with_video, layout


def open_dataset(root: Path):
    from so101.dataset.reader import Dataset

    return Dataset.open(root)


def dataset_error():
    from so101.dataset.layout import DatasetError

    return DatasetError


def assert_one_line(error: BaseException) -> None:
    message = str(error)
    assert message.strip() and "\n" not in message, repr(message)


# -- the fixture's datasets ------------------------------------------------------------------


def test_the_layout_is_spread_as_asked(written):
    """The fixture itself: "several" really is several files in two or more chunks of each kind."""
    root, episodes, with_video, layout = written
    files = lw.dataset_files(root)
    data = [f for f in files if f.startswith("data/")]
    meta = [f for f in files if f.startswith("meta/episodes/")]
    videos = [f for f in files if f.startswith("videos/")]
    if layout == "one":
        assert (len(data), len(meta), len(videos)) == (1, 1, 1 if with_video else 0)
    else:
        assert data == [f"data/chunk-00{c}/file-00{f}.parquet" for c, f in [(0, 0), (0, 1), (1, 0), (1, 1)]]
        assert meta == [f"meta/episodes/chunk-00{c}/file-00{f}.parquet" for c, f in [(0, 0), (0, 1), (1, 0)]]
        assert len(videos) == (3 if with_video else 0)
        assert pq.ParquetFile(root / meta[0]).metadata.num_row_groups == 2
    assert sum(pq.read_metadata(root / f).num_rows for f in data) == sum(LENGTHS)
    # Every row points at the files it is in and that hold its episode.
    for rel in meta:
        for row in pq.read_table(root / rel, columns=["episode_index", "meta/episodes/chunk_index", "meta/episodes/file_index", "data/chunk_index", "data/file_index"]).to_pylist():
            assert rel == lw.EPISODES_PATH.format(chunk_index=row["meta/episodes/chunk_index"], file_index=row["meta/episodes/file_index"])
            data_file = root / lw.DATA_PATH.format(chunk_index=row["data/chunk_index"], file_index=row["data/file_index"])
            assert row["episode_index"] in pq.read_table(data_file, columns=["episode_index"]).column(0).to_pylist()


def test_reads_the_metadata(written):
    root, episodes, with_video, _ = written
    ds = open_dataset(root)
    assert ds.fps == FPS
    assert ds.robot_type == "so101_follower"
    assert ds.total_frames == sum(LENGTHS)
    assert ds.tasks == ["pick the cube", "place the cube", "wave"]
    assert [e.index for e in ds.episodes] == list(range(len(LENGTHS)))
    assert [e.length for e in ds.episodes] == LENGTHS
    assert [e.tasks for e in ds.episodes] == [(t,) for t in TASKS]
    for e in ds.episodes:
        assert e.duration_s == pytest.approx(e.length / FPS, abs=1.5 / FPS)
    assert ds.video_keys == ([KEY] if with_video else [])
    assert ds.features["action"]["names"] == lw.MOTOR_NAMES


def test_reads_every_episodes_frames_exactly(written):
    root, episodes, _, _ = written
    ds = open_dataset(root)
    for n, episode in enumerate(episodes):
        frames = ds.episode_frames(n)
        for key in ("action", "observation.state"):
            assert frames[key].dtype == np.float32 and frames[key].shape == (LENGTHS[n], 6)
            assert frames[key].tobytes() == episode[key].tobytes(), (n, key)  # bit for bit, -0.0 too
        assert np.array_equal(frames["frame_index"], np.arange(LENGTHS[n]))
        np.testing.assert_allclose(frames["timestamp"], np.arange(LENGTHS[n]) / FPS, atol=1e-6)


def test_reads_every_episodes_pictures(written):
    root, episodes, with_video, _ = written
    ds = open_dataset(root)
    if not with_video:  # no pictures to give: a one-line error, not an empty episode
        with pytest.raises(dataset_error()) as caught:
            list(ds.episode_images(0, KEY))
        assert_one_line(caught.value)
        return
    for n, episode in enumerate(episodes):
        pictures = list(ds.episode_images(n, KEY))
        assert len(pictures) == LENGTHS[n], n
        written = episode["images"]
        for i, got in enumerate(pictures):
            assert got.shape == (HEIGHT, WIDTH, 3) and got.dtype == np.uint8
            # >= 30 dB for the right picture (about 40); a neighbour, whose square has moved, is
            # about 20 dB: so a picture off by one frame fails, even at an episode's ends.
            assert lw.psnr(got, written[i]) >= 30, (n, i, lw.psnr(got, written[i]))
            for j in (i - 1, i + 1):
                if 0 <= j < len(written):
                    assert lw.psnr(got, written[j]) < lw.psnr(got, written[i]), (n, i, j)
        others = [episodes[m]["images"] for m in (n - 1, n + 1) if 0 <= m < len(episodes)]
        assert all(lw.psnr(pictures[0], other[0]) < 30 for other in others), n


def test_a_missing_episode_is_a_one_line_error(written):
    root, _, with_video, _ = written
    ds = open_dataset(root)
    DatasetError = dataset_error()
    for index in (len(LENGTHS), 10_000):
        with pytest.raises(DatasetError) as caught:
            ds.episode_frames(index)
        assert_one_line(caught.value)
        if with_video:
            with pytest.raises(DatasetError) as caught:
                list(ds.episode_images(index, KEY))
            assert_one_line(caught.value)


def test_a_folder_that_is_not_a_dataset_is_a_one_line_error(tmp_path):
    DatasetError = dataset_error()
    (tmp_path / "empty").mkdir()
    (tmp_path / "other" / "meta").mkdir(parents=True)
    (tmp_path / "other" / "notes.txt").write_text("not a dataset\n")
    (tmp_path / "broken" / "meta").mkdir(parents=True)
    (tmp_path / "broken" / "meta" / "info.json").write_text("{not json")
    for folder in ("empty", "other", "broken", "missing"):
        with pytest.raises(DatasetError) as caught:
            open_dataset(tmp_path / folder)
        assert_one_line(caught.value)


# -- a dataset LeRobot 0.4.4 wrote -------------------------------------------------------------


MADE_LENGTHS = [5, 7, 4, 6, 3, 5]
MADE_TASKS = [("pick the cube",), ("place the cube",), ("pick the cube", "wave"), ("wave",), ("place the cube",), ("pick the cube",)]


def made_pictures(episode: int, length: int) -> np.ndarray:
    """The pictures tests/data/lerobot_made/README.md's script recorded for an episode."""
    yy, xx = np.mgrid[0:HEIGHT, 0:WIDTH]
    frames = []
    for i in range(length):
        x0 = (4 * i + 8 * episode) % (WIDTH - 16)
        img = np.stack([(xx * 4) % 256, (yy * 5) % 256, np.full_like(xx, 40 * episode % 256)], -1).astype(np.uint8)
        img[16:32, x0 : x0 + 16] = (255, 255, 255)
        frames.append(img)
    return np.stack(frames)


def made_inputs() -> list[dict]:
    """The episodes LeRobot recorded into tests/data/lerobot_made, as tests/helpers/lerobot_written.py takes them."""
    data = pa.concat_tables(pq.read_table(p) for p in sorted((MADE / "data").rglob("*.parquet")))
    tasks = pq.read_table(MADE / "meta" / "tasks.parquet").column("__index_level_0__").to_pylist()
    episodes, start = [], 0
    for n, length in enumerate(MADE_LENGTHS):
        rows = slice(start, start + length)
        episodes.append(
            {
                "frame_tasks": [tasks[t] for t in data.column("task_index").to_pylist()[rows]],
                "action": np.array(data.column("action").to_pylist()[rows], dtype=np.float32),
                "observation.state": np.array(data.column("observation.state").to_pylist()[rows], dtype=np.float32),
                "images": made_pictures(n, length),
            }
        )
        start += length
    return episodes


def test_reads_what_lerobot_wrote():
    ds = open_dataset(MADE)
    assert ds.fps == 30 and ds.total_frames == sum(MADE_LENGTHS)
    assert ds.tasks == ["pick the cube", "place the cube", "wave"]
    assert [(e.index, e.length) for e in ds.episodes] == list(enumerate(MADE_LENGTHS))
    assert [e.tasks for e in ds.episodes] == MADE_TASKS
    assert ds.video_keys == [KEY]
    for n, length in enumerate(MADE_LENGTHS):
        frames = ds.episode_frames(n)
        t = np.arange(6, dtype=np.float32) / 10
        want = np.stack([(n * 10 + i + t).astype(np.float32) for i in range(length)])
        assert np.array_equal(frames["action"], want), n
        assert np.array_equal(frames["observation.state"], -want), n
        pictures = list(ds.episode_images(n, KEY))
        assert len(pictures) == length, n
        for i, (got, expected) in enumerate(zip(pictures, made_pictures(n, length))):
            assert lw.psnr(got, expected) >= 30, (n, i, lw.psnr(got, expected))


def test_the_fixture_writes_what_lerobot_wrote(tmp_path):
    """From the inputs of tests/data/lerobot_made, with the file limits LeRobot's sizes came to,
    tests/helpers/lerobot_written.py writes the same files: the same parquet schemas, schema metadata
    and contents, info.json, stats.json and tasks; mp4s that decode to the same frames at the
    same times (their bytes differ: another build of the encoder)."""
    root = tmp_path / "written"
    lw.write_lerobot_dataset(
        root, made_inputs(), fps=30, with_video=True, frames_per_data_file=1, frames_per_video_file=13,
        episodes_per_meta_file=3, chunks_size=2, metadata_buffer_size=3, data_files_size_in_mb=1e-6, video_files_size_in_mb=0.004,
    )
    assert lw.dataset_files(root) == [f for f in lw.dataset_files(MADE)]
    for rel in lw.dataset_files(MADE):
        ours, theirs = root / rel, MADE / rel
        if rel.endswith(".parquet"):
            ours_file, theirs_file = pq.ParquetFile(ours), pq.ParquetFile(theirs)
            assert ours_file.schema_arrow.remove_metadata() == theirs_file.schema_arrow.remove_metadata(), rel
            ours_meta, theirs_meta = ours_file.schema_arrow.metadata or {}, theirs_file.schema_arrow.metadata or {}
            assert sorted(ours_meta) == sorted(theirs_meta), rel
            if b"huggingface" in theirs_meta:
                assert json.loads(ours_meta[b"huggingface"])["info"] == json.loads(theirs_meta[b"huggingface"])["info"]
            if b"pandas" in theirs_meta:
                ours_pandas, theirs_pandas = json.loads(ours_meta[b"pandas"]), json.loads(theirs_meta[b"pandas"])
                for versions in (ours_pandas, theirs_pandas):
                    versions.pop("creator"), versions.pop("pandas_version")
                assert ours_pandas == theirs_pandas
            assert ours_file.metadata.num_row_groups == theirs_file.metadata.num_row_groups, rel
            ours_rows, theirs_rows = ours_file.read().to_pylist(), theirs_file.read().to_pylist()
            for ours_row, theirs_row in zip(ours_rows, theirs_rows, strict=True):
                assert ours_row.keys() == theirs_row.keys()
                for key, value in theirs_row.items():
                    if key.startswith("stats/"):
                        np.testing.assert_allclose(ours_row[key], value, rtol=1e-9, atol=1e-12, err_msg=f"{rel} {key}")
                    else:
                        assert ours_row[key] == value, (rel, key)
        elif rel.endswith("info.json"):
            assert json.loads(ours.read_text()) == json.loads(theirs.read_text())
            assert list(json.loads(ours.read_text())) == list(json.loads(theirs.read_text()))
        elif rel.endswith("stats.json"):
            ours_stats, theirs_stats = json.loads(ours.read_text()), json.loads(theirs.read_text())
            assert ours_stats.keys() == theirs_stats.keys()
            for key, stats in theirs_stats.items():
                assert list(ours_stats[key]) == list(stats)
                for name, value in stats.items():
                    np.testing.assert_allclose(ours_stats[key][name], value, rtol=1e-9, atol=1e-12, err_msg=f"{key} {name}")
        else:
            import av

            with av.open(str(ours)) as a, av.open(str(theirs)) as b:
                sa, sb = a.streams.video[0], b.streams.video[0]
                assert (sa.codec_context.name, sa.time_base, sa.duration, sa.average_rate) == (sb.codec_context.name, sb.time_base, sb.duration, sb.average_rate)
                assert [f.pts for f in a.decode(video=0)] == [f.pts for f in b.decode(video=0)]
            for x, y in zip(lw.decode_frames(ours), lw.decode_frames(theirs), strict=True):
                assert lw.psnr(x, y) >= 30, rel


@pytest.mark.skipif(not (TMP_MADE / "meta" / "info.json").exists(), reason="no /tmp/lerobot_made (a dataset LeRobot wrote on this machine)")
def test_the_fixture_is_shaped_like_tmp_lerobot_made(tmp_path):
    """Structure only: the same files, parquet columns and arrow types, schema-metadata keys and
    info.json keys as a dataset LeRobot wrote here, for as many episodes of the same lengths."""
    info = json.loads((TMP_MADE / "meta" / "info.json").read_text())
    episodes_meta = pa.concat_tables(pq.read_table(p) for p in sorted((TMP_MADE / "meta" / "episodes").rglob("*.parquet")))
    with_video = info.get("video_path") is not None
    video_keys = [k for k, ft in info["features"].items() if ft["dtype"] == "video"]
    assert video_keys in ([], [KEY]), f"the fixture writes one camera, {KEY}; /tmp/lerobot_made has {video_keys}"
    height, width = info["features"][KEY]["shape"][:2] if with_video else (HEIGHT, WIDTH)
    rng = np.random.default_rng(0)
    episodes = [
        {
            "frame_tasks": list(tasks) * length if len(tasks) == 1 else [tasks[i * len(tasks) // length] for i in range(length)],
            "action": rng.normal(size=(length, 6)).astype(np.float32),
            "observation.state": rng.normal(size=(length, 6)).astype(np.float32),
        }
        for tasks, length in zip(episodes_meta.column("tasks").to_pylist(), episodes_meta.column("length").to_pylist())
    ]
    root = tmp_path / "written"
    lw.write_lerobot_dataset(root, episodes, fps=info["fps"], with_video=with_video, image_size=(width, height), chunks_size=info["chunks_size"])
    assert lw.dataset_files(root) == lw.dataset_files(TMP_MADE)
    for rel in lw.dataset_files(TMP_MADE):
        if rel.endswith(".parquet"):
            assert lw.parquet_columns(root / rel) == lw.parquet_columns(TMP_MADE / rel), rel
            assert sorted(pq.read_schema(root / rel).metadata or {}) == sorted(pq.read_schema(TMP_MADE / rel).metadata or {}), rel
    ours, theirs = json.loads((root / "meta" / "info.json").read_text()), json.loads((TMP_MADE / "meta" / "info.json").read_text())
    assert list(ours) == list(theirs)
    assert {k: sorted(v) for k, v in ours["features"].items()} == {k: sorted(v) for k, v in theirs["features"].items()}
    ours_stats, theirs_stats = json.loads((root / "meta" / "stats.json").read_text()), json.loads((TMP_MADE / "meta" / "stats.json").read_text())
    assert {k: sorted(v) for k, v in ours_stats.items()} == {k: sorted(v) for k, v in theirs_stats.items()}


def test_a_data_file_that_disagrees_with_the_metadata_is_one_line(tmp_path):
    import pyarrow.parquet as pq

    from so101.dataset.features import ACTION_KEY, STATE_KEY, to_lerobot
    from so101.dataset.layout import DatasetError
    from so101.dataset.reader import Dataset
    from so101.dataset.writer import DatasetWriter

    with DatasetWriter.open(tmp_path / "set", 30, {}) as writer:
        episode = writer.start_episode("t")
        for _ in range(5):
            episode.add_frame({STATE_KEY: to_lerobot([0] * 6), ACTION_KEY: to_lerobot([0] * 6)})
        episode.save()
    data_file = tmp_path / "set" / "data" / "chunk-000" / "file-000.parquet"
    pq.write_table(pq.read_table(data_file).slice(0, 3), data_file)
    with pytest.raises(DatasetError) as refused:
        Dataset.open(tmp_path / "set").episode_frames(0)
    assert str(refused.value) == (f"episode 0 has 5 frames in its metadata but 3 rows in {data_file}: "
                                  "the dataset's files disagree")


def test_a_v21_dataset_is_converted_by_lerobots_own_converter_and_then_read(tmp_path, policy_python):
    """`so101 dataset DIR --convert`: LeRobot 0.4.4's converter, in place; the original kept as DIR_old;
    refused in one line, before anything runs, where the converter would replace a folder."""
    from so101.dataset.reader import Dataset
    from tests.helpers.dataflow import error_lines, run_so101

    root = tmp_path / "their_data"
    episodes = make_episodes(with_video=False)[:3]
    lw.write_v21_dataset(root, episodes, FPS)
    refused = run_so101("dataset", str(root))
    assert error_lines(refused.stderr) == [f"so101 dataset: {root} is a LeRobot v2.1 dataset: this reads and writes v3.0 "
                                           f"(`so101 dataset {root} --convert` runs LeRobot's own converter on it)"]
    (tmp_path / "their_data_old").mkdir()
    refused = run_so101("dataset", str(root), "--convert", "--policy-python", str(policy_python))
    assert refused.returncode == 2 and error_lines(refused.stderr) == [
        f"so101 dataset: {tmp_path / 'their_data_old'} exists, and LeRobot's converter would replace it: move it away first"]
    (tmp_path / "their_data_old").rmdir()

    done = run_so101("dataset", str(root), "--convert", "--policy-python", str(policy_python))
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.splitlines()[-1] == (f"converted: {root} is v3.0 (3 episodes, {sum(LENGTHS[:3])} frames); "
                                            f"the v2.1 original is kept in {tmp_path / 'their_data_old'}")
    assert json.loads((tmp_path / "their_data_old/meta/info.json").read_text())["codebase_version"] == "v2.1"
    dataset = Dataset.open(root)
    assert [episode.tasks for episode in dataset.episodes] == [(task,) for task in TASKS[:3]]
    for number, episode in enumerate(episodes):
        frames = dataset.episode_frames(number)
        for key in ("action", "observation.state"):
            np.testing.assert_array_equal(frames[key], episode[key])
