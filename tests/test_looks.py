"""Looks that vary by seed (so101.bodies.looks): drawn the same for the same seed, within their bounds."""

from __future__ import annotations

import json
import math

import pytest

from so101.bodies.looks import (
    FLOOR_PALETTE, FOV_DEG, FRONT_SHIFT_M, FRONT_TURN_DEG, LIGHT_DIFFUSE, LIGHT_ELEVATION_DEG, OBJECT_PALETTE,
    UNSEEN_BEYOND, UNSEEN_FLOOR_PALETTE, UNSEEN_LIGHT_ELEVATION_DEG, UNSEEN_OBJECT_PALETTE, WRIST_SHIFT_M, looks_for,
    looks_metadata, unseen_looks, varied_looks,
)


def test_the_same_seed_draws_the_same_looks_and_other_seeds_other_ones():
    assert varied_looks(7) == varied_looks(7)
    drawn = [varied_looks(seed) for seed in range(50)]
    assert len({looks.light_dir for looks in drawn}) == 50
    assert len({looks.floor_rgba for looks in drawn}) == len(FLOOR_PALETTE)  # every floor comes up in 50
    assert len({looks.object_rgbas for looks in drawn}) > 30


@pytest.mark.parametrize("seed", range(0, 1000, 37))
def test_looks_stay_within_their_bounds(seed):
    looks = varied_looks(seed)
    assert looks.seed == seed
    assert math.isclose(math.dist(looks.light_dir, (0, 0, 0)), 1.0, abs_tol=1e-5)
    elevation = math.degrees(math.asin(-looks.light_dir[2]))  # the light shines down, from above the floor
    assert LIGHT_ELEVATION_DEG[0] - 1e-3 <= elevation <= LIGHT_ELEVATION_DEG[1] + 1e-3
    assert LIGHT_DIFFUSE[0] <= looks.light_diffuse <= LIGHT_DIFFUSE[1]
    assert looks.floor_rgba in FLOOR_PALETTE
    assert len(looks.object_rgbas) == 2 and looks.object_rgbas[0] != looks.object_rgbas[1]
    assert all(rgba in OBJECT_PALETTE for rgba in looks.object_rgbas)
    assert all(abs(shift) <= FRONT_SHIFT_M for shift in looks.front_shift_m)
    assert all(abs(turn) <= FRONT_TURN_DEG for turn in looks.front_turn_deg)
    assert all(abs(shift) <= WRIST_SHIFT_M for shift in looks.wrist_shift_m)
    assert abs(looks.front_fov_deg) <= FOV_DEG and abs(looks.wrist_fov_deg) <= FOV_DEG


@pytest.mark.parametrize("seed", range(0, 1000, 37))
def test_unseen_looks_are_none_that_varied_draws(seed):
    looks = unseen_looks(seed)
    assert looks == looks_for("unseen", seed) and looks != varied_looks(seed)
    assert looks.floor_rgba in UNSEEN_FLOOR_PALETTE and looks.floor_rgba not in FLOOR_PALETTE
    assert all(rgba in UNSEEN_OBJECT_PALETTE and rgba not in OBJECT_PALETTE for rgba in looks.object_rgbas)
    elevation = math.degrees(math.asin(-looks.light_dir[2]))
    assert UNSEEN_LIGHT_ELEVATION_DEG[0] - 1e-3 <= elevation <= UNSEEN_LIGHT_ELEVATION_DEG[1] + 1e-3
    assert not LIGHT_DIFFUSE[0] < looks.light_diffuse < LIGHT_DIFFUSE[1]
    # Each camera's shift, turn and field of view past varied's spread, and not far past it.
    for values, spread in ((looks.front_shift_m, FRONT_SHIFT_M), (looks.front_turn_deg, FRONT_TURN_DEG),
                           ((looks.front_fov_deg, looks.wrist_fov_deg), FOV_DEG), (looks.wrist_shift_m, WRIST_SHIFT_M)):
        assert all(spread <= abs(value) <= UNSEEN_BEYOND * spread + 1e-6 for value in values), (values, spread)


def test_fixed_looks_change_nothing_and_a_dataset_keeps_either_as_json():
    assert looks_for("fixed", 3) is None
    assert looks_metadata("fixed", 3) == {"looks": "fixed"}
    kept = looks_metadata("varied", 3)
    assert json.loads(json.dumps(kept)) == kept
    assert kept["looks"] == "varied" and kept["seed"] == 3
    assert kept["floor_rgba"] == list(varied_looks(3).floor_rgba)


@pytest.mark.parametrize("mode, seed, message", [
    ("random", 3, r"^unknown looks 'random'; use one of: fixed, varied, unseen$"),
    ("unseen", -1, r"^a seed is a whole number >= 0, got -1$"),
    ("varied", -1, r"^a seed is a whole number >= 0, got -1$"),
])
def test_a_bad_mode_or_seed_is_refused_in_one_line(mode, seed, message):
    with pytest.raises(ValueError, match=message):
        looks_for(mode, seed)


@pytest.mark.parametrize("looks", ["varied", "fixed"])
def test_pybullets_window_lays_a_layout_out_as_its_pictures_show_it(looks):
    """The window's process (so101.gui.viewer) draws layout 1007 under varied physics with its cube's size and, in
    varied looks, its floor's and objects' colours; fixed looks keep PyBullet's own."""
    import pybullet as p
    import pybullet_data

    from so101.bodies.physics import physics_for
    from so101.gui.viewer import show_layout
    from so101.tasks import CUBE_TO_BOX

    client = p.connect(p.DIRECT)
    try:
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=client)
        plane = p.loadURDF("plane.urdf", physicsClientId=client)
        scene = CUBE_TO_BOX.pybullet_scene(client, 0)
        show_layout(scene, plane, client, 1007, looks, "varied")
        colour = {body: p.getVisualShapeData(body, physicsClientId=client)[0][7] for body in (plane, *scene.object_ids)}
        cube_extent_m = p.getVisualShapeData(scene.cube_id, physicsClientId=client)[0][3]
    finally:
        p.disconnect(client)
    assert cube_extent_m == pytest.approx([2 * physics_for("varied", 1007).cube_half_size_m] * 3, abs=1e-6)
    drawn = looks_for(looks, 1007)
    if drawn is None:
        assert colour[scene.cube_id] == pytest.approx(CUBE_TO_BOX.cube.rgba)
        assert colour[plane] == pytest.approx((1, 1, 1, 1))  # PyBullet's checkered floor, untinted
    else:
        assert [colour[body] for body in (plane, *scene.object_ids)] == pytest.approx(
            [drawn.floor_rgba, *drawn.object_rgbas])
