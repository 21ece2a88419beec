"""Eyes taught by the simulator (so101.perception): the camera's geometry, the maps read into places, the
landmarks that cancel a camera placed roughly, a seeing recipe's folder and how the dataflows run it,
and `so101 learn`'s refusals. The network's training is a documented command, not a test."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path
from dataclasses import replace

import numpy as np
import pytest

from so101.bodies.camera import TASK_FRONT_CAMERA
from so101.bodies.looks import varied_looks
from so101.perception.estimate import (
    KEYPOINTS, LIFT_SCALE_M, STRIDE, CubeFilter, Sighting, cube_in_world, object_state, read_maps,
)
from so101.perception.geometry import view_of
from so101.tasks import CUBE_TO_BOX
from tests.helpers.dataflow import SO101

SIZE = (160, 120)
CUBE, BOX = CUBE_TO_BOX.cube, CUBE_TO_BOX.box


def moved(camera, seed):
    """The task's front camera as `--looks varied` places it for `seed`."""
    looks = varied_looks(seed)
    return replace(camera, target_xyz_m=tuple(np.add(camera.target_xyz_m, looks.front_shift_m)),
                   yaw_deg=camera.yaw_deg + looks.front_turn_deg[0], pitch_deg=camera.pitch_deg + looks.front_turn_deg[1],
                   fov_deg=camera.fov_deg + looks.front_fov_deg)


@pytest.mark.parametrize("camera", [TASK_FRONT_CAMERA, moved(TASK_FRONT_CAMERA, 5)])
def test_a_point_seen_then_cast_back_to_its_height_is_where_it_was(camera):
    view = view_of(camera, *SIZE)
    points = np.array([[0.2, -0.1, 0.0125], [0.16, 0.19, 0.005], [0.1, 0.0, 0.12]])
    pixels = view.project(points)
    assert np.all((pixels >= 0) & (pixels <= SIZE)), pixels
    assert np.allclose(view.on_plane(pixels, points[:, 2]), points, atol=1e-9)
    assert np.isnan(view.project([view.eye - view.forward])).all()  # behind the camera: no pixel


def sighting_of(view, cube_xyz, tip_xyz, lift=0.0, yaw=0.0, sure=1.0):
    """What perfect eyes would see through `view` (the camera as it really is)."""
    pixels = view.project([cube_xyz, (*BOX.xy_m, BOX.floor_thickness_m), tip_xyz])
    return Sighting({name: tuple(pixel) for name, pixel in zip(KEYPOINTS, pixels)}, dict.fromkeys(KEYPOINTS, sure),
                    yaw, lift)


def test_the_box_and_the_tip_cancel_a_camera_placed_a_centimetre_and_two_degrees_off():
    believed = view_of(TASK_FRONT_CAMERA, *SIZE)
    bare, corrected, near_tip = [], [], []
    for seed in range(200):
        real = view_of(moved(TASK_FRONT_CAMERA, seed), *SIZE)
        cube = np.array(CUBE_TO_BOX.layout(seed).cube_xyz_m)
        tip = cube + np.array([0.0, 0.0, 0.03]) if seed % 2 else np.array([0.2, 0.0, 0.15])  # above it, or far
        sighting = sighting_of(real, cube, tip)
        bare.append(np.linalg.norm(cube_in_world(sighting, believed, CUBE, BOX, landmarks=False) - cube))
        corrected.append(np.linalg.norm(cube_in_world(sighting, believed, CUBE, BOX, tip) - cube))
        if seed % 2:
            near_tip.append(corrected[-1])
    assert np.median(bare) > 0.006  # the camera's offset alone: most cubes more than 6 mm off
    assert np.median(corrected) < 0.0025 and max(near_tip) < 0.003, (np.median(corrected), max(near_tip))


def test_a_lifted_cube_is_placed_at_the_height_the_maps_say():
    view = view_of(TASK_FRONT_CAMERA, *SIZE)
    held = np.array([0.15, 0.05, CUBE.half_size_m + 0.08])
    state = object_state(sighting_of(view, held, held, lift=0.08, yaw=math.radians(30)), view, CUBE, BOX, held)
    assert np.allclose(state[:3], held, atol=1e-9)
    assert np.allclose(state[3:7], [0, 0, math.sin(math.radians(15)), math.cos(math.radians(15))])
    assert state[7:] == [*BOX.xy_m, 0.0]  # the box where the task stands it


def test_maps_read_into_pixels_a_yaw_and_a_lift():
    rows, columns = SIZE[1] // STRIDE, SIZE[0] // STRIDE
    maps = np.zeros((3 * len(KEYPOINTS) + 3, rows, columns), dtype=np.float32)
    for index, (row, column) in enumerate([(10, 7), (20, 30), (5, 25)]):
        maps[index, row, column] = 20.0  # a sure peak
        maps[len(KEYPOINTS) + 2 * index:len(KEYPOINTS) + 2 * index + 2, row, column] = (0.25, -0.5)
    maps[3 * len(KEYPOINTS):, 10, 7] = (math.cos(4 * 0.3), math.sin(4 * 0.3), 0.05 / LIFT_SCALE_M)
    sighting = read_maps(maps)
    assert sighting.pixels["cube"] == ((7 + 0.75) * STRIDE, (10 + 0.0) * STRIDE)
    assert sighting.pixels["box"] == ((30 + 0.75) * STRIDE, 20 * STRIDE)
    assert math.isclose(sighting.cube_yaw_rad, 0.3, abs_tol=1e-6) and math.isclose(sighting.cube_lift_m, 0.05, abs_tol=1e-6)
    assert sighting.sure["cube"] > 0.99
    maps[0] = 0.0  # a flat map: nowhere in particular
    assert read_maps(maps).sure["cube"] < 0.01


def cube_at(x, yaw_deg=0.0):
    half = math.radians(yaw_deg) / 2
    return [x, 0.1, 0.0125, 0.0, 0.0, math.sin(half), math.cos(half), *BOX.xy_m, 0.0]


def test_the_cube_is_the_median_of_the_newest_sightings_held_while_unsure_and_followed_when_it_moves():
    cube = CubeFilter()
    assert cube.add(cube_at(0.20), sure=0.05)[0] == 0.20  # nothing seen yet: the best there is
    for x in (0.201, 0.199, 0.260, 0.200):  # one picture's outlier is out-voted
        sent = cube.add(cube_at(x, yaw_deg=40.0), sure=0.9)
    assert math.isclose(sent[0], 0.2, abs_tol=0.0015) and sent[7:] == [*BOX.xy_m, 0.0]
    assert math.isclose(2 * math.atan2(sent[5], sent[6]), math.radians(40.0), abs_tol=1e-6)
    assert cube.add(cube_at(0.5), sure=0.05) == sent  # the arm hides it: held
    for x in (0.35, 0.351):  # lifted away: followed at once, not averaged with where it lay
        sent = cube.add(cube_at(x), sure=0.9)
    assert math.isclose(sent[0], 0.3505, abs_tol=1e-9)
    cube.reset()
    assert cube.state() is None


def test_a_yaw_near_the_fold_is_averaged_across_it():
    cube = CubeFilter()
    for yaw in (44.0, -44.0, 45.0 - 0.5):  # the same cube: 44° and -44° are 2° apart, a quarter turn on
        sent = cube.add(cube_at(0.2, yaw), sure=0.9)
    yaw = math.degrees(2 * math.atan2(sent[5], sent[6]))
    assert abs(abs(yaw) - 45.0) < 1.5, yaw


# -- so101 learn's refusals: each one line, before anything is made ------------------------------------------------

def fake_policy_env(tmp_path):
    """A folder with a `python` and a `lerobot-train` beside it, as a policy environment has (never run here)."""
    folder = tmp_path / "env" / "bin"
    folder.mkdir(parents=True)
    for name in ("python", "lerobot-train"):
        (folder / name).write_text("#!/bin/sh\nexit 1\n")
    return folder / "python"


@pytest.mark.parametrize("setup, extra, message", [
    (None, "--policy-python /no/python", "so101 learn: /no/python does not exist: make the policy environment with "
                                         "`so101 policy-env`, or give --policy-python PY"),
    ("other files", "", "so101 learn: {out} is not empty and not a folder `so101 learn` began: give a new folder"),
    ("other options", "", "so101 learn: {out} was learned with other options (body 'mujoco' there, 'pybullet' now): "
                          "use those, or another folder"),
])
def test_learn_refuses_in_one_line_and_touches_nothing(tmp_path, setup, extra, message):
    out = tmp_path / "out"
    if setup == "other files":
        out.mkdir()
        (out / "mine.txt").write_text("kept")
    elif setup == "other options":
        out.mkdir()
        settings = {"task": "cube_to_box", "sees": True, "body": "mujoco", "physics": "fixed", "episodes": 300, "pictures": 40000,
                    "eyes_steps": 4000, "policy_steps": 6500, "seed": 1, "candidates": 2, "rounds": 1,
                    "round_episodes": 100, "round_steps": 2000, "validation": 20}
        (out / "so101_learn.json").write_text(json.dumps({"settings": settings, "done": {"demos": 180.0}}))
    before = sorted(path.name for path in out.iterdir()) if out.exists() else None
    python = extra.split()[-1] if extra else str(fake_policy_env(tmp_path))
    done = subprocess.run([str(SO101), "learn", str(out), "--task", "cube_to_box", "--sees", "--policy-python", python],
                          capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 2 and done.stderr.strip() == message.format(out=out.resolve()), done.stderr
    assert (sorted(path.name for path in out.iterdir()) if out.exists() else None) == before


def test_learn_on_a_machine_without_a_policy_environment_makes_it_first(tmp_path, monkeypatch, capsys):
    import argparse

    from so101.cli import learn
    from so101.policy.environment import PolicyEnvError

    made = []

    def build(folder, say):
        made.append(folder)
        say("+ python -m venv ...")
        raise PolicyEnvError("`pip install ...` failed: no network")

    monkeypatch.setattr(learn, "default_dir", lambda: tmp_path / "env")
    monkeypatch.setattr(learn, "build", build)
    parser = argparse.ArgumentParser()
    learn.add_arguments(parser, "learn")
    assert learn.run(parser.parse_args([str(tmp_path / "out"), "--task", "cube_to_box"])) == 2
    out, err = capsys.readouterr()
    assert made == [tmp_path / "env"] and out.splitlines() == [
        f"learn: no policy environment yet: making it in {tmp_path / 'env'} as `so101 policy-env` does (LeRobot and "
        "torch, several GB to download; once per machine)...", "learn: + python -m venv ..."]
    assert err == "so101 learn: the policy environment could not be made: `pip install ...` failed: no network\n"
    assert not (tmp_path / "out").exists()


def test_learn_keeps_the_policy_that_scored_best_on_the_validation_layouts(tmp_path):
    from so101.cli.learn import Learning, validation_successes

    assert validation_successes("episode 0 ...\nsuccess: 17/20 (85%, 95% CI 64–95%, Wilson), mean time to success 9.1 s\n") == 17
    assert validation_successes("so101 eval: the policy reads: observation.state\n") is None
    learning = Learning(tmp_path, tmp_path, {"seed": 3, "candidates": 3, "rounds": 2}, {}, Path("python"),
                        {"seed3": 15, "seed4": 18, "seed5": 18})
    assert learning.candidates() == ["seed3", "seed4", "seed5"]
    assert learning.best() == "seed4"  # a tie goes to the first seed; the rounds are not scored yet
    learning.scores.update({"round1": 18, "round2": 19})
    assert learning.best() == "round2" and learning.trained("round2") == tmp_path / "round2/checkpoints/last/pretrained_model"
    learning.scores["round2"] = 17
    assert learning.best() == "round1"  # a tie between a candidate and rounds goes to the latest round
    learning.scores["round1"] = 17
    assert learning.best() == "seed4"  # a round below what it learned from is not kept
    assert Learning(tmp_path, tmp_path, {"seed": 1, "candidates": 1}, {}, Path("python"), {}).best() == "seed1"


def test_learn_teaches_the_eyes_from_the_camera_and_over_the_backdrop_given_and_the_folder_keeps_them(tmp_path,
                                                                                                       capsys):
    import argparse
    import shutil
    from dataclasses import replace

    from so101.bodies.camera_file import default_camera_file, orbit_of
    from so101.cli import learn
    from so101.cli.learn import Learning
    from so101.perception.eyes import default_eyes_facts
    from so101.perception.recipe import read_recipe
    from tests.helpers.dataflow import ROOT

    parser = argparse.ArgumentParser()
    learn.add_arguments(parser, "learn")
    cv2 = pytest.importorskip("cv2")
    cv2.imwrite(str(tmp_path / "table.png"), np.full((30, 40, 3), 90, dtype=np.uint8))
    camera = tmp_path / "front.json"
    moved = default_camera_file("front")
    camera.write_text(replace(moved, fov_deg=50.0).as_json())
    given = ["--camera-pose", f"front={camera}", "--backdrop", f"front={tmp_path / 'table.png'}"]
    assert learn.run(parser.parse_args([str(tmp_path / "state"), "--task", "cube_to_box", "--policy-python",
                                        str(fake_policy_env(tmp_path)), *given])) == 2
    assert capsys.readouterr().err == ("so101 learn: --camera-pose and --backdrop shape the eyes' pictures: they go "
                                       "with --sees\n")
    args = parser.parse_args([str(tmp_path / "out"), "--task", "cube_to_box", "--sees", *given])
    settings = {"seed": 1, "candidates": 1, "sees": True, "task": "cube_to_box", "body": "pybullet",
                "camera_poses": {"front": args.camera_poses["front"].as_dict()},
                "backdrops": {"front": str((tmp_path / "table.png").resolve())}}
    learning = Learning(tmp_path / "out", tmp_path, settings, {}, Path("python"), {})
    assert learning.scenario_args() == ["--scenario", json.dumps({key: settings[key] for key in ("camera_poses", "backdrops")})]
    # Without a front backdrop, the default recipe draws half its pictures over the pool.
    pooled = Learning(tmp_path / "out", tmp_path, {**settings, "backdrops": {}, "backdrop_pool_share": learn.POOL_SHARE},
                      {}, Path("python"), {})
    assert pooled.scenario_args()[-2:] == ["--pool-share", "0.5"]
    assert learning.camera_args() == ["--camera-pose", f"front={tmp_path / 'camera-front.json'}",
                                      "--backdrop", f"front={settings['backdrops']['front']}"]
    (tmp_path / "eyes").mkdir()  # what the eyes' training leaves: then the folder says what they assume
    (tmp_path / "eyes" / "eyes.pt").write_bytes(b"weights")
    (tmp_path / "eyes" / "eyes.json").write_text(default_eyes_facts((64, 48), {}).as_json())
    shutil.copytree(ROOT / "tests" / "data" / "policy_act_tiny", tmp_path / "policy")
    learning.assemble_into(tmp_path / "folder", tmp_path / "policy")
    eyes = json.loads((tmp_path / "folder" / "eyes" / "eyes.json").read_text())
    assert eyes["camera"]["fov_deg"] == pytest.approx(orbit_of(args.camera_poses["front"]).fov_deg) == 50.0
    recipe = json.loads((tmp_path / "folder" / "so101_recipe.json").read_text())
    assert recipe["backdrops"] == settings["backdrops"] and recipe["camera_poses"] == settings["camera_poses"]
    recipe = read_recipe(tmp_path / "folder")
    assert recipe is not None and recipe.elsewhere(settings["backdrops"], settings["camera_poses"]) == []
    assert recipe.elsewhere({}, {}) == [  # eval or teleop run without them: said, one line each
        f"note: the eyes were taught over {settings['backdrops']['front']} behind the front camera, and run over the "
        "simulator's floor",
        "note: the eyes were taught from the front camera at a camera file's pose, and this run draws it at the "
        "simulator's own"]


# -- a seeing recipe's folder, and the dataflows that run it ---------------------------------------------------

def recipe_folder(tmp_path):
    import shutil

    from so101.perception.eyes import default_eyes_facts
    from so101.perception.recipe import write_recipe
    from tests.helpers.dataflow import ROOT

    folder = tmp_path / "recipe"
    shutil.copytree(ROOT / "tests" / "data" / "policy_act_tiny", folder / "policy")
    (folder / "eyes").mkdir()
    (folder / "eyes" / "eyes.pt").write_bytes(b"weights")
    (folder / "eyes" / "eyes.json").write_text(default_eyes_facts((64, 48), {}).as_json())
    write_recipe(folder, {"recipe": "eyes + state policy", "task": "cube_to_box"})
    return folder, sys.executable


def test_a_recipe_runs_its_policy_behind_the_eyes_and_the_policy_reads_no_simulator_state(tmp_path):
    from so101.launch.lockstep import Driver, Flow, lockstep_dataflow
    from so101.bodies.registry import BODIES
    from so101.policy.choice import choose_policy
    from so101.runtime.dataflow import POLICY_NODE_FILE

    folder, python = recipe_folder(tmp_path)
    chosen = choose_policy(folder, Path(python), None, ())  # no --task: the real arm's case
    assert chosen.folder == folder / "policy" and chosen.inputs == ("joint_state", "gripper_state", "object_state")
    assert chosen.body_pictures == (("image",), (64, 48))
    assert chosen.reads() == ("the policy reads: observation.state, observation.environment_state (from the perception "
                              "node, which sees observation.images.front and the joints)")
    assert chosen.perception_env("en") == {"SO101_EYES_DIR": str(folder / "eyes"), "SO101_TASK": "cube_to_box",
                                           "SO101_LANG": "en"}
    driver = Driver("policy", POLICY_NODE_FILE, chosen.inputs, {}, python, chosen.perception_env("en"))
    flow = Flow(BODIES["pybullet"], driver, {"SO101_TASK": "cube_to_box", "SO101_SEED": "0", "SO101_TIME_LIMIT_S": "2"},
                "en", ("image",), "64x48")
    nodes = {node["id"]: node for node in lockstep_dataflow(flow)["nodes"]}
    assert nodes["perception"]["inputs"]["image"]["source"] == "simulation/image"
    assert nodes["perception"]["inputs"]["joint_state"]["source"] == "simulation/joint_state"
    assert nodes["policy"]["inputs"]["object_state"]["source"] == "perception/object_state"
    assert all(spec["source"] != "simulation/object_state" for spec in nodes["policy"]["inputs"].values())


@pytest.mark.parametrize("damage, message", [
    ("no eyes", "holds no eyes.pt: give the folder `so101 learn` wrote"),
    ("no policy", "is a recipe without its policy (policy/config.json): `so101 learn` did not finish; run it again to resume"),
    ("bad recipe", "so101_recipe.json is not a recipe file"),
])
def test_an_incomplete_recipe_is_refused_in_one_line(tmp_path, damage, message):
    import shutil

    from so101.policy.choice import choose_policy

    folder, python = recipe_folder(tmp_path)
    if damage == "no eyes":
        (folder / "eyes" / "eyes.pt").unlink()
    elif damage == "no policy":
        shutil.rmtree(folder / "policy")
    else:
        (folder / "so101_recipe.json").write_text("{")
    with pytest.raises(ValueError, match=re.escape(message)):
        choose_policy(folder, Path(python), "cube_to_box", CUBE_TO_BOX.object_state_names)


def test_pictures_are_drawn_with_their_episodes_physics_and_measured_on_seeds_training_never_draws():
    """A varied-physics episode's pictures show its cube, and the tip where the arm truly was while its
    calibration reported the recorded angles; `tip_xyz` stays where the recorded angles put it (what the
    node computes); a fixed episode's are as they always were."""
    from so101.bodies.physics import draw_physics
    from so101.kinematics import Kinematics
    from so101.perception.pictures import Frames, draw_pictures, picture_seeds

    physics = replace(draw_physics(5), calibration_offsets_deg=(6.0, -5.0, 4.0, 0.0, 0.0, 0.0))
    pose = np.array([10.0, -20.0, 30.0, 40.0, 0.0, 20.0])
    half = {0: CUBE.half_size_m, 1: physics.cube_half_size_m}
    states = np.array([[0.20, 0.05, half[episode], 0, 0, 0, 1, *BOX.xy_m, 0.0] for episode in (0, 1)])
    frames = Frames(np.stack([pose, pose]), states, np.array([0, 1]), {0: None, 1: physics})
    drawn = draw_pictures(frames, 6, 3, SIZE, "fixed")
    view = view_of(TASK_FRONT_CAMERA, *SIZE)
    with Kinematics() as kinematics:
        reported_tip = np.asarray(kinematics.tip_mm(pose[:5])) / 1000.0
        true_tip = np.asarray(kinematics.tip_mm(physics.true_deg(pose)[:5])) / 1000.0
    varied = np.isclose(drawn["cube_half_m"], physics.cube_half_size_m)
    assert 0 < varied.sum() < 6 and np.allclose(drawn["cube_half_m"][~varied], CUBE.half_size_m)
    assert np.allclose(drawn["tip_xyz"], reported_tip)
    assert np.allclose(drawn["tip_px"][varied], view.project([true_tip])[0], atol=1e-6)
    assert np.allclose(drawn["tip_px"][~varied], view.project([reported_tip])[0], atol=1e-6)
    assert np.hypot(*(view.project([true_tip])[0] - view.project([reported_tip])[0])) > 2  # the offsets show
    # Over the backdrop pool (all of them here), the floor's corner shows a workspace, not the floor.
    pooled = draw_pictures(frames, 6, 3, SIZE, "fixed", pool_share=1.0)
    corner = (slice(None), slice(0, 4), slice(0, 4))
    assert (np.abs(pooled["pictures"][corner].astype(int) - drawn["pictures"][corner]).max(axis=(1, 2, 3)) > 8).all()
    # Held-out pictures draw their looks and layouts from spans training never draws.
    (looks, layouts), (held_looks, held_layouts) = picture_seeds(False), picture_seeds(True)
    assert looks[1] <= held_looks[0] and layouts[1] <= held_layouts[0]
