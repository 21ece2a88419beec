"""A photo of the workspace behind the simulated scene (so101.bodies.backdrop, `--backdrop NAME=IMAGE`): fitted
to any picture size, drawn where the floor and the sky were and nowhere else, the same from either body,
kept in the dataset's scenario, and refused in one line when it is not a photo."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from so101.bodies.backdrop import (
    SHIFT, ZOOM, BackdropError, Placement, backdrop_picture, checked_backdrop, fitted, placement_for,
)
from so101.bodies.backdrop_pool import HELD_OUT_PANORAMAS, HELD_OUT_SURFACES, SIZE, pool_folder, view_of_panorama
from so101.bodies.registry import SIMULATED_BODIES
from so101.bodies.scenario import Scenario
from tests.helpers.dataflow import error_lines, run_so101

MAGENTA = (255, 0, 255)  # no floor, arm, cube or box is this colour


def photo(path: Path, width: int = 400, height: int = 200, colour=MAGENTA) -> Path:
    cv2.imwrite(str(path), np.full((height, width, 3), colour[::-1], dtype=np.uint8))
    return path


def test_a_photo_of_any_aspect_covers_the_picture_about_its_centre():
    wide = np.zeros((100, 400, 3), dtype=np.uint8)
    wide[:, 190:210] = 255  # a white stripe at the middle
    picture = fitted(wide, 64, 48)  # scaled to 48 rows (192 columns wide), its middle 64 columns kept
    assert picture.shape == (48, 64, 3)
    assert picture[:, 30:34].min() > 200 and picture[:, :20].max() == 0
    moved = fitted(wide, 64, 48, shift=(0.25, 0.0))  # the crop 16 columns to the right: the stripe 16 to the left
    assert moved[:, 14:18].min() > 200 and moved[:, 30:34].max() < 50


def test_each_seed_draws_its_photo_and_under_varied_looks_a_small_shift_zoom_and_tint(tmp_path):
    for index in range(3):
        photo(tmp_path / f"{index}.png", colour=(50 * index, 0, 0))
    drawn = {placement_for(str(tmp_path), seed, varied=False).photo.name for seed in range(30)}
    assert drawn == {"0.png", "1.png", "2.png"}
    assert placement_for(str(tmp_path), 4, varied=False) == Placement(placement_for(str(tmp_path), 4, False).photo)
    varied = [placement_for(str(tmp_path), seed, varied=True) for seed in range(30)]
    assert all(abs(shift) <= SHIFT for each in varied for shift in each.shift)
    assert all(1 <= each.zoom <= 1 + ZOOM for each in varied) and len({each.gains for each in varied}) == 30
    assert placement_for(str(tmp_path), 7, True) == placement_for(str(tmp_path), 7, True)


def test_a_panorama_is_seen_through_a_camera_that_looks_down_at_its_floor():
    panorama = np.zeros((180, 360, 3), dtype=np.uint8)
    panorama[90:] = (0, 200, 0)  # below the horizon, the floor: green; above, black
    panorama[90:, 180:] = (0, 0, 200)  # the floor's half about heading 90° (longitudes 0-180°): blue
    level = view_of_panorama(panorama, 90.0, 0.0, 60.0, (64, 48))
    assert level[:20].max() == 0 and (level[28:, :, 2] == 200).all()  # the horizon across the middle
    down = view_of_panorama(panorama, 90.0, 45.0, 60.0, (64, 48))
    assert (down[:, :, 2] == 200).all()  # the floor ahead, all blue
    behind = view_of_panorama(panorama, 270.0, 45.0, 60.0, (64, 48))
    assert (behind[:, :, 1] == 200).mean() > 0.95


def test_the_pool_is_made_the_same_on_every_machine_and_its_held_out_part_shares_nothing_with_it(tmp_path, monkeypatch):
    import hashlib

    def made(cache: Path) -> dict[str, dict[str, str]]:
        monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
        return {name: {file.name: hashlib.sha256(file.read_bytes()).hexdigest() for file in pool_folder(name).iterdir()}
                for name in ("pool", "pool-held-out")}

    first, again = made(tmp_path / "a"), made(tmp_path / "b")
    assert first == again
    seen, held_out = first["pool"], first["pool-held-out"]
    assert not set(seen.values()) & set(held_out.values()) and len(seen) > 100 and len(held_out) > 40
    assert {name.split("-")[1] for name in held_out if name.endswith(".png")} == {*HELD_OUT_PANORAMAS, *HELD_OUT_SURFACES}
    assert not {name.split("-")[1] for name in seen if name.endswith(".png")} & {*HELD_OUT_PANORAMAS, *HELD_OUT_SURFACES}
    sources = (pool_folder("pool") / "SOURCES.txt").read_text().splitlines()
    assert sorted(line.split(":")[0] for line in sources) == sorted(name for name in seen if name.endswith(".png"))
    assert any("Poly Haven" in line and "(CC0)" in line for line in sources)
    assert cv2.imread(str(next(pool_folder("pool").glob("*.png")))).shape == (SIZE[1], SIZE[0], 3)
    # Unseen looks draw the front camera's backdrop from the held-out pool, unless one is given.
    assert Scenario("unseen").backdrops == {"front": "pool-held-out"} and Scenario("varied").backdrops == {}
    assert Scenario("unseen", backdrops={"front": "pool"}).backdrops == {"front": "pool"}
    assert checked_backdrop("front=pool") == ("front", "pool")


@pytest.mark.parametrize("given, message", [
    ("front={missing}", "{missing} does not exist: give a photo of the workspace, a folder of them, or pool or "
                        "pool-held-out"),
    ("front={text}", "{text} cannot be read as a picture: give a .png, .jpg, .jpeg, .bmp, .webp file"),
    ("front={empty}", "{empty} holds no images (.png, .jpg, .jpeg, .bmp, .webp)"),
    ("side={good}", "--backdrop takes NAME=IMAGE, NAME front or wrist: got 'side="),
])
def test_what_is_not_a_photo_is_refused_in_one_line_and_nothing_is_written(tmp_path, given, message):
    paths = {"missing": tmp_path / "missing.png", "text": tmp_path / "notes.png", "empty": tmp_path / "empty",
             "good": photo(tmp_path / "good.png")}
    paths["text"].write_text("not a picture")
    paths["empty"].mkdir()
    with pytest.raises(BackdropError, match="^" + re.escape(message.format(**paths))):
        checked_backdrop(given.format(**paths))
    out = tmp_path / "demos"
    done = run_so101("demos", str(out), "--task", "cube_to_box", "--episodes", "1", "--camera-size", "96x72",
                     "--backdrop", given.format(**paths))
    assert done.returncode == 2 and message.format(**paths) in error_lines(done.stderr)[-1], done.stderr
    assert not out.exists()


@pytest.mark.parametrize("command, line", [
    (["eval", "--idle"], "so101 eval: --backdrop shapes a task's pictures, and this run draws none: it goes with --video FILE, or "
               "a --policy that sees"),
    (["demos", "{out}", "--no-video"], "so101 demos: --backdrop shapes a task's pictures, and this run draws none"),
])
def test_a_backdrop_where_no_picture_is_drawn_is_refused_in_one_line(tmp_path, command, line):
    done = run_so101(*[arg.format(out=tmp_path / "demos") for arg in command], "--task", "cube_to_box",
                     "--backdrop", f"front={photo(tmp_path / 'table.png')}")
    assert done.returncode == 1 and error_lines(done.stderr)[0].startswith(line), done.stderr  # as demos' and eval's others
    assert len(error_lines(done.stderr)) == 1 and not (tmp_path / "demos").exists()


@pytest.mark.parametrize("body", SIMULATED_BODIES)
def test_the_photo_is_drawn_where_the_floor_was_from_either_body_and_the_dataset_keeps_it(tmp_path, body):
    from so101.dataset.layout import SCENARIOS_KEY
    from so101.dataset.reader import Dataset

    backdrop, out = photo(tmp_path / "table.png"), tmp_path / "demos"
    done = run_so101("demos", str(out), "--task", "cube_to_box", "--body", body, "--episodes", "1", "--seed", "3",
                     "--camera-size", "96x72", "--time-limit", "0.5", "--keep", "all", "--backdrop", f"front={backdrop}")
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"demos: the front camera's backdrop: {backdrop.resolve()}, 400x200; scaled to cover the 96x72 pictures and " \
           "cropped about the centre" in done.stdout.splitlines()
    dataset = Dataset.open(out)
    front = next(dataset.episode_images(0, "observation.images.front")).astype(int)
    wrist = next(dataset.episode_images(0, "observation.images.wrist")).astype(int)
    near_magenta = np.abs(front - MAGENTA).max(axis=2) < 40  # an mp4's colours, a few levels off
    assert near_magenta[60:, :30].mean() > 0.95  # the floor in front of the arm is the photo
    assert 0.5 < near_magenta.mean() < 0.95  # and the arm, the cube and the box are drawn over it
    assert (np.abs(wrist - MAGENTA).max(axis=2) < 40).mean() < 0.05  # the wrist has no backdrop of its own
    kept = dataset.info[SCENARIOS_KEY]["0"]["backdrops"]
    assert set(kept) == {"front"} and kept["front"]["photo"] == str(backdrop.resolve())
    assert len(kept["front"]["sha256"]) == 64
    # Made again from the episode: the arm left out where the simulator draws it, the photo is what remains.
    made = tmp_path / "made.png"
    done = run_so101("cameras", "--backdrop", "front", "--from", str(out), "-o", str(made), "--max-holes", "0.5")
    assert done.returncode == 0 and "the episode's pictures with the arm left out" in done.stderr, done.stderr
    again = cv2.imread(str(made))[:, :, ::-1].astype(int)
    assert (np.abs(again - MAGENTA).max(axis=2) < 40).mean() > 0.9  # the box stays: it is on every floor


def test_the_backdrop_picture_is_the_photo_fitted_and_tinted(tmp_path):
    placement = Placement(photo(tmp_path / "grey.png", colour=(100, 100, 100)), gains=(1.1, 1.0, 0.9))
    assert backdrop_picture(placement, 32, 24)[0, 0].tolist() == [110, 100, 90]


if __name__ == "__main__":
    sys.exit(pytest.main([__file__]))


# -- a backdrop made from what a camera saw (so101 cameras --backdrop) ------------------------------------------

def test_each_pixel_is_the_median_of_the_frames_that_do_not_cover_it_and_too_many_holes_are_refused():
    from so101.perception.backdrop_maker import BackdropMakingError, median_backdrop

    room = np.random.default_rng(0).integers(0, 256, (24, 32, 3), dtype=np.uint8)
    frames, covered = [], []
    for step in range(8):  # an arm, black, sweeping across; its top row never leaves row 0..3, column 0..3
        frame, mask = room.copy(), np.zeros((24, 32), dtype=bool)
        mask[:, 4 * step:4 * step + 4] = True
        mask[0:4, 0:4] = True
        frame[mask] = 0
        frames.append(frame)
        covered.append(mask)
    made, seen = median_backdrop(frames, covered, max_holes=0.05)
    assert seen == pytest.approx(1 - 16 / (24 * 32))
    assert np.array_equal(made[4:], room[4:]) and np.array_equal(made[:4, 4:], room[:4, 4:])  # seen: exact
    with pytest.raises(BackdropMakingError, match=r"^the arm covers 2\.1% of the picture in every frame, more than 1%"):
        median_backdrop(frames, covered, max_holes=0.01)
    assert np.array_equal(median_backdrop([room, room, frames[0]])[0], room)  # no masks: the median of all


@pytest.mark.parametrize("args, message", [
    (["--backdrop", "front", "-o", "{out}"], "--backdrop front needs --from SOURCE: a camera (/dev/video0"),
    (["--backdrop", "front", "--from", "{video}"], "--backdrop front needs -o FILE.png (or .jpg)"),
    (["--backdrop", "wrist", "--from", "{dataset}", "-o", "{out}"], "--backdrop wrist --from DATASET: the wrist camera "
                                                                     "moves with the jaws"),
    (["--backdrop", "front", "--from", "{dataset}", "-o", "{out}"], "--backdrop front --from {dataset} needs "
                                                                     "--camera-pose front=FILE"),
])
def test_making_a_backdrop_refuses_in_one_line_and_writes_nothing(tmp_path, args, message):
    paths = {"out": tmp_path / "made.png", "video": tmp_path / "room.mp4",
             "dataset": Path(__file__).parent / "data" / "lerobot_made"}
    done = run_so101("cameras", *[arg.format(**paths) for arg in args])
    lines = error_lines(done.stderr)
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith(f"so101 cameras: {message.format(**paths)}") and not paths["out"].exists(), lines


def test_a_backdrop_from_a_video_of_the_arm_moving_is_the_room(tmp_path):
    room = np.zeros((48, 64, 3), dtype=np.uint8)
    room[:, :32], room[:, 32:] = (40, 160, 90), (200, 120, 30)
    video = cv2.VideoWriter(str(tmp_path / "room.mp4"), cv2.VideoWriter.fourcc(*"mp4v"), 30, (64, 48))
    for step in range(30):  # an arm, black, crossing: no pixel covered in more than a third of the frames
        frame = room.copy()
        frame[:, 2 * step:2 * step + 8] = 0
        video.write(frame[:, :, ::-1])
    video.release()
    done = run_so101("cameras", "--backdrop", "front", "--from", str(tmp_path / "room.mp4"), "-o", str(tmp_path / "b.png"))
    assert done.returncode == 0, done.stderr
    assert error_lines(done.stderr)[-1] == (f"wrote {tmp_path / 'b.png'} (64x48): the median of its frames, 30 frames; "
                                            f"100.0% of the picture seen. Use it: --backdrop front={tmp_path / 'b.png'}")
    made = cv2.imread(str(tmp_path / "b.png"))[:, :, ::-1].astype(int)
    assert np.abs(made[:, 4:28] - room[:, 4:28]).max() < 20 and np.abs(made[:, 36:60] - room[:, 36:60]).max() < 20
