"""One scenario value (so101.bodies.scenario): what nodes are told and read back, refused in one line when it
makes no sense, and what a dataset keeps of it by episode, datasets from before it included."""

from __future__ import annotations

import json

import pytest

from so101.bodies.camera_file import camera_file_from, default_camera_file
from so101.bodies.looks import looks_metadata
from so101.bodies.physics import physics_metadata, physics_mode
from so101.bodies.scenario import SCENARIO_ENV_VAR, Scenario, parse_scenario
from so101.dataset.layout import SCENARIOS_KEY, episode_scenario


def test_a_scenario_reaches_a_node_whole_and_the_defaults_say_nothing(tmp_path):
    ranges = tmp_path / "mine.json"
    ranges.write_text(json.dumps({"command_delay_s": [0.1, 0.15]}))
    front = camera_file_from(default_camera_file("front").as_dict())  # as a file holds it, to 1 µm
    scenario = Scenario("varied", {"front": front}, physics_mode(str(ranges)))
    assert parse_scenario(scenario.env()[SCENARIO_ENV_VAR]) == scenario  # no file needed where the node runs
    assert Scenario().env() == {} and parse_scenario("") == Scenario()
    kept = scenario.metadata(7, ("front",), (160, 120))
    assert kept["looks"] == looks_metadata("varied", 7) and kept["physics"] == physics_metadata(scenario.physics, 7)
    assert set(kept["cameras"]) == {"front"}  # type: ignore[arg-type]
    assert Scenario().metadata(7) == {"physics": {"physics": "fixed"}}  # no pictures: no looks, no cameras


@pytest.mark.parametrize("text, message", [
    ("[1]", "a scenario is a JSON object of looks, camera_poses, physics, backdrops"),
    ('{"look": "varied"}', "a scenario has no 'look': it holds looks, camera_poses, physics, backdrops"),
    ('{"backdrops": {"front": "/no/such/table.png"}}', "the scenario: /no/such/table.png does not exist"),
    ('{"physics": {"cube_mass_kg": [0.05, 0.01]}}', "the scenario: the physics ranges: cube_mass_kg is [low, high]"),
    ('{"camera_poses": {"front": {}}}', "the scenario: "),
])
def test_a_scenario_that_makes_no_sense_is_one_line(text, message):
    with pytest.raises(ValueError, match="^" + message.replace("[", r"\[").replace("]", r"\]")) as refused:
        parse_scenario(text)
    assert "\n" not in str(refused.value)


def test_a_dataset_keeps_each_episodes_scenario_under_one_key_and_older_ones_still_read():
    kept = {"physics": {"physics": "fixed"}, "looks": {"looks": "fixed"}}
    assert episode_scenario({SCENARIOS_KEY: {"3": kept}}, 3) == kept
    older = {"so101_episode_looks": {"0": {"looks": "fixed"}}, "so101_episode_physics": {"0": {"physics": "fixed"}},
             "so101_episode_cameras": [{"front": {"fov_deg": 45.0}}, None]}
    assert episode_scenario(older, 0) == {"looks": {"looks": "fixed"}, "physics": {"physics": "fixed"},
                                          "cameras": {"front": {"fov_deg": 45.0}}}
    assert episode_scenario(older, 1) == {} and episode_scenario({}, 0) == {}
