"""The task's pure core, no simulator: its layouts, where a cube may start, success, and the words that name them."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, strategies as st

from so101.tasks import CUBE_TO_BOX, TASKS, parse_reset, parse_seed, task_named
from so101.tasks.cube_to_box import OBJECT_STATE_NAMES, REST_SPEED_M_S

TASK = CUBE_TO_BOX
BOX = TASK.box
CUBE_HALF = TASK.cube.half_size_m


def test_a_seed_gives_the_same_layout_every_time_and_seeds_differ():
    assert TASK.layout(7) == TASK.layout(7)
    assert len({TASK.layout(seed).cube_xyz_m for seed in range(100)}) == 100
    # Pinned: Python's random.Random sequence for a seed is the same on every platform and release.
    first = TASK.layout(0)
    assert [round(value, 4) for value in first.cube_xyz_m] == [0.2432, -0.0244, 0.0125]
    assert round(math.degrees(first.cube_yaw_rad), 2) == -7.15


@given(st.integers(min_value=0, max_value=2**63))
def test_every_seed_puts_the_cube_on_the_floor_in_its_sector_and_outside_the_box(seed):
    layout = TASK.layout(seed)
    x, y, z = layout.cube_xyz_m
    assert z == CUBE_HALF  # resting on the floor
    radius, bearing = math.hypot(x, y), math.atan2(y, x)
    assert TASK.sector.radius_m[0] <= radius <= TASK.sector.radius_m[1]
    assert TASK.sector.bearing_rad[0] <= bearing <= TASK.sector.bearing_rad[1]
    assert -math.pi / 4 <= layout.cube_yaw_rad <= math.pi / 4
    assert layout.box_xyz_m == (*BOX.xy_m, 0.0)
    # Not in the box, nor touching its outer walls: the cube's corners stay clear of the footprint.
    reach = CUBE_HALF * math.sqrt(2)
    assert (abs(x - BOX.xy_m[0]) > BOX.outer_half_m + reach or abs(y - BOX.xy_m[1]) > BOX.outer_half_m + reach)


def test_the_sector_is_apart_from_the_box_at_every_corner():
    # The sector is convex in radius and bearing; its extremes are its corners and arc middles.
    reach = CUBE_HALF * math.sqrt(2)
    for x, y in TASK.sector.corners_xy_m():
        assert abs(x - BOX.xy_m[0]) > BOX.outer_half_m + reach or abs(y - BOX.xy_m[1]) > BOX.outer_half_m + reach


@pytest.mark.parametrize("bad", [-1, 1.5, "3", True, None])
def test_a_seed_that_is_not_a_whole_number_is_refused_in_one_line(bad):
    with pytest.raises(ValueError, match="a seed is a whole number >= 0"):
        TASK.layout(bad)


# -- success: the cube at rest inside the box -----------------------------------------------------------

BOX_XYZ = (*BOX.xy_m, 0.0)
ON_THE_BOX_FLOOR_Z = BOX.floor_thickness_m + CUBE_HALF


def at(dx, dy, z):
    return (BOX.xy_m[0] + dx, BOX.xy_m[1] + dy, z)


@pytest.mark.parametrize("cube_xyz, speed, expected", [
    pytest.param(at(0, 0, ON_THE_BOX_FLOOR_Z), 0.0, True, id="inside, at rest"),
    pytest.param(at(BOX.inner_half_m - CUBE_HALF, -(BOX.inner_half_m - CUBE_HALF), ON_THE_BOX_FLOOR_Z), 0.001, True,
                 id="inside, in a corner"),
    pytest.param(at(BOX.outer_half_m - BOX.wall_thickness_m / 2, 0, BOX.wall_height_m + CUBE_HALF), 0.0, False,
                 id="on the rim"),
    pytest.param(at(BOX.outer_half_m + CUBE_HALF + 0.01, 0, CUBE_HALF), 0.0, False, id="outside, beside it"),
    pytest.param((0.2, -0.1, CUBE_HALF), 0.0, False, id="where it started"),
    pytest.param(at(0, 0, 0.03), 0.4, False, id="still falling into it"),
    pytest.param(at(0, 0, ON_THE_BOX_FLOOR_Z), REST_SPEED_M_S * 1.5, False, id="inside, still sliding"),
    pytest.param(at(0, 0, 0.15), 0.0, False, id="held above it"),
    pytest.param(at(0, 0, ON_THE_BOX_FLOOR_Z + 0.015), 0.0, False, id="held still inside it, above its floor"),
    pytest.param(at(BOX.inner_half_m - CUBE_HALF * math.sqrt(2), 0, ON_THE_BOX_FLOOR_Z + CUBE_HALF * (math.sqrt(2) - 1)),
                 0.0, True, id="tilted on an edge against a wall"),
])
def test_success_is_the_cube_at_rest_inside_the_box(cube_xyz, speed, expected):
    assert TASK.succeeded(cube_xyz, BOX_XYZ, speed) is expected
    assert TASK.reward(expected) == (1.0 if expected else 0.0)


def test_success_follows_the_box_where_it_stands():
    moved = (0.3, -0.2, 0.0)
    assert TASK.succeeded((0.3, -0.2, ON_THE_BOX_FLOOR_Z), moved, 0.0)
    assert not TASK.succeeded(at(0, 0, ON_THE_BOX_FLOOR_Z), moved, 0.0)


# -- names ----------------------------------------------------------------------------------------------

def test_the_object_state_names_are_the_contracts():
    assert OBJECT_STATE_NAMES[:10] == ("cube.x", "cube.y", "cube.z", "cube.qx", "cube.qy", "cube.qz", "cube.qw",
                                       "box.x", "box.y", "box.z")
    assert TASK.object_state_names == OBJECT_STATE_NAMES


def test_tasks_are_found_by_name_and_an_unknown_one_is_named_back():
    assert task_named("cube_to_box") is CUBE_TO_BOX
    assert list(TASKS) == ["cube_to_box"]
    with pytest.raises(ValueError, match=r"^unknown task 'cube_to_bin'; the tasks are: cube_to_box$"):
        task_named("cube_to_bin")


@pytest.mark.parametrize("text, seed", [("reset", None), ("reset 7", 7), ("  reset   0 ", 0)])
def test_a_reset_command_names_its_seed_or_none(text, seed):
    assert parse_reset(text) == seed


@pytest.mark.parametrize("text", ["", "reset x", "reset -1", "reset 1 2", "home"])
def test_a_bad_reset_command_is_refused_in_one_line(text):
    with pytest.raises(ValueError) as caught:
        parse_reset(text)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("text", ["seven", "-3", "1.5", ""])
def test_a_typed_seed_must_be_a_whole_number(text):
    with pytest.raises(ValueError, match="a seed is a whole number >= 0"):
        parse_seed(text)


@pytest.mark.parametrize("options, message", [
    (["--task", "cube_to_bin"], "so101 teleop: error: argument --task: unknown task 'cube_to_bin'; the tasks are: cube_to_box"),
    (["--task", "cube_to_box", "--seed", "seven"], "so101 teleop: error: argument --seed: a seed is a whole number >= 0, "
                                                   "got 'seven'"),
    (["--seed", "3"], "so101 teleop: --seed goes with --task NAME"),
    (["--task", "cube_to_box", "--body", "real", "--port", "/dev/ttyACM0", "--calibration", "arm.json"],
     "so101 teleop: --task cube_to_box is for a simulated body (--body pybullet or mujoco): nothing reports where a "
     "real cube is, so the real arm has no task scene and no object_state"),
    (["--observe", "state,front"], "so101 teleop: --observe says what a recording's frames show: it goes with --record DIR"),
    (["--record", "DIR", "--observe", "state,environment,front"],
     "so101 teleop: --observe state,environment,front: environment is a task's objects: it goes with --task"),
    (["--task", "cube_to_box", "--looks", "varied"], "so101 teleop: --looks varied goes with --task NAME on a simulated "
     "body, and --record DIR or a --policy that sees: the task's cameras draw only for them"),
])
def test_teleop_refuses_a_task_it_cannot_run_in_one_line_before_starting_anything(tmp_path, capsys, options, message):
    from so101.cli import main as cli

    log_file = tmp_path / "dora.log"
    try:
        code = cli.main(["teleop", "--mode", "direct", "--lang", "en", "--log", str(log_file),
                         *(str(tmp_path / "dataset") if option == "DIR" else option for option in options)])
    except SystemExit as exit:  # argparse's refusals
        code = exit.code
    assert code == 2
    error_lines = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("usage:")
                   and not line.startswith(" ")]
    assert error_lines == [message]
    assert not log_file.exists()  # no dataflow was started
