"""Episodes, scores and lockstep frames: the plain functions of so101/tasks/episodes.py and so101/runtime/lockstep.py."""

from __future__ import annotations

import pytest

from so101.bodies.registry import SIMULATED_BODIES

from so101.runtime.lockstep import (
    FrameParts, FrameTag, LastAnswer, answers, frame_tag, lockstep_rates, steps_per_frame,
)
from so101.tasks.episodes import (
    EpisodeClock, Outcome, inference_line, read_outcomes, score_line, split_seeds, wilson_interval,
)


# -- the score --------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("successes, trials, low, high", [
    # Wilson's 95% interval, as statistics texts tabulate it.
    (0, 10, 0.0, 0.2775),
    (10, 10, 0.7225, 1.0),
    (5, 10, 0.2366, 0.7634),
    (95, 100, 0.8883, 0.9785),
    (100, 100, 0.9630, 1.0),
])
def test_the_wilson_interval_matches_its_formula(successes, trials, low, high):
    assert wilson_interval(successes, trials) == pytest.approx((low, high), abs=1e-4)


def test_the_interval_of_no_trials_says_nothing_and_a_bad_count_is_refused():
    assert wilson_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(ValueError, match="between 0 and the trials"):
        wilson_interval(11, 10)


def test_the_score_line_names_the_rate_its_interval_and_the_mean_time():
    outcomes = [Outcome(0, 0, True, 201, 8.0), Outcome(1, 1, False, 751, 30.0), Outcome(2, 2, True, 251, 10.0)]
    assert score_line(outcomes) == ("success: 2/3 (67%, 95% CI 21–94%, Wilson), mean time to success 9.00 s")
    assert score_line([Outcome(0, 5, False, 10, 0.4)]).endswith("mean time to success none (no success)")


def test_a_policys_inference_times_are_summed_up_over_its_episodes_and_no_driver_that_says_none_gets_a_line():
    outcomes = [Outcome(0, 0, True, 201, 8.0, inference_ms=[10.0, 12.0, 30.0]), Outcome(1, 1, False, 751, 30.0),
                Outcome(2, 2, True, 251, 10.0, inference_ms=[11.0, 200.0])]
    assert inference_line(outcomes) == ("inference: 5 action chunks, median 12 ms, 95th percentile 166 ms, "
                                        "longest 200 ms")
    assert inference_line(outcomes[1:2]) is None
    assert Outcome.from_json(outcomes[0].to_json()) == outcomes[0]


def test_an_outcome_goes_through_its_json_line_unchanged_and_reads_as_a_person_would():
    outcome = Outcome(3, 7, True, 214, 8.52, kept=True)
    assert Outcome.from_json(outcome.to_json()) == outcome
    assert outcome.line() == "episode 3 (seed 7): success in 8.52 s, 214 frames, kept"
    assert Outcome(4, 8, False, 751, 30.0).line() == "episode 4 (seed 8): failed (time limit, 30.0 s), 751 frames"
    lines = [outcome.to_json(), "", '"done"']
    assert read_outcomes(lines) == ([outcome], True)
    assert read_outcomes(lines[:1]) == ([outcome], False)


def test_an_episode_ends_at_its_first_success_or_at_its_time_limit():
    clock = EpisodeClock(fps=25, time_limit_s=2.0)
    assert clock.limit_frames == 50
    assert not clock.ended(49, False) and clock.ended(50, False) and clock.ended(3, True)
    assert clock.seconds(50) == 2.0


@pytest.mark.parametrize("count, workers, sizes", [(10, 2, [5, 5]), (7, 3, [3, 2, 2]), (2, 4, [1, 1])])
def test_seeds_are_split_in_order_into_runs_as_even_as_can_be(count, workers, sizes):
    seeds = list(range(100, 100 + count))
    runs = split_seeds(seeds, workers)
    assert [len(run) for run in runs] == sizes
    assert [seed for run in runs for seed in run] == seeds


# -- lockstep ---------------------------------------------------------------------------------------------------

def test_a_frame_is_a_whole_number_of_physics_steps_or_refused_naming_the_rates():
    assert steps_per_frame(25) == 10 and steps_per_frame(50) == 5 and steps_per_frame(250) == 1
    assert lockstep_rates() == [1, 2, 5, 10, 25, 50, 125, 250]
    with pytest.raises(ValueError, match=r"30 fps is not a whole number of 4 ms physics steps a frame; "
                                         r"lockstep takes 1, 2, 5, 10, 25, 50, 125, 250"):
        steps_per_frame(30)
    with pytest.raises(ValueError, match="frames per second >= 1"):
        steps_per_frame(0)


def test_a_tag_rides_in_metadata_and_a_command_answers_only_its_own_frame():
    tag = FrameTag(episode=2, frame=40, seed=7)
    assert frame_tag({**tag.metadata(), "stream": 1}) == tag
    assert frame_tag({"timestamp": 0}) is None and frame_tag(None) is None
    assert answers(tag, tag) and answers(None, tag)  # an untagged command: the frame now
    assert not answers(FrameTag(1, 40, 7), tag) and not answers(FrameTag(2, 39, 7), tag)


def test_a_frame_sent_again_gets_the_same_answer_without_asking_the_driver_again():
    asked: list[int] = []

    def driver(answer: float):
        return lambda: asked.append(1) or [answer]

    last = LastAnswer()
    assert last.to(FrameTag(1, 0, 3), driver(1.0)) == [1.0]
    assert last.to(FrameTag(1, 0, 3), driver(2.0)) == [1.0] and len(asked) == 1
    assert last.to(FrameTag(1, 1, 3), driver(3.0)) == [3.0] and len(asked) == 2
    assert last.to(FrameTag(2, 0, 4), driver(4.0)) == [4.0]  # another episode's frame 0


def test_frame_parts_give_a_frame_once_whole_even_with_another_frames_parts_between():
    parts = FrameParts(("joint_state", "object_state", "action"))
    first, second = FrameTag(1, 0, 3), FrameTag(2, 0, 4)
    assert parts.add("joint_state", first, "a") is None
    assert parts.add("joint_state", second, "b") is None
    assert parts.add("object_state", second, "c") is None
    assert parts.add("image", second, "not needed") is None
    assert parts.add("action", first, "late") is None  # the first frame still lacks its object_state
    assert parts.add("action", second, "d") == {"joint_state": "b", "object_state": "c", "action": "d"}
    # Only the newest few incomplete frames are kept.
    for frame in range(FrameParts.KEPT + 2):
        parts.add("joint_state", FrameTag(3, frame, 5), frame)
    assert parts.add("object_state", first, "x") is None
    assert parts.add("action", first, "y") is None  # its joint_state was forgotten: it is not completed


# -- a body in lockstep -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("body", SIMULATED_BODIES)
@pytest.mark.parametrize("last_frame, frames_out", [("2", [0, 1, 2, 0, 1]), ("0", [0, 1, 2, 3, 0, 1])])
def test_a_body_holds_still_after_an_episodes_last_frame_until_the_reset(monkeypatch, body, last_frame, frames_out):
    import pyarrow as pa

    from tests.helpers.dataflow import run_simulation_node

    def command(episode: int, frame: int) -> dict:
        return {"type": "INPUT", "id": "joint_cmd", "value": pa.array([10.0, 0, 0, 0, 0, 0]),
                "metadata": FrameTag(episode, frame, 4).metadata()}

    # The runner's reset comes after the driver has answered the last frame too (it watches beside the loop).
    events = [command(0, 0), command(0, 1), command(0, 2),
              {"type": "INPUT", "id": "task_cmd", "value": pa.array(["reset 5"]), "metadata": {}}, command(1, 0)]
    config = {"inputs": {"joint_cmd": "expert/joint_cmd", "task_cmd": "episodes/task_cmd"},
              "outputs": ["joint_state", "gripper_state", "object_state", "task_status"]}
    sent: list[int] = []
    code, node = run_simulation_node(
        monkeypatch, events, config, body=body, SO101_TASK="cube_to_box", SO101_SEED="4", SO101_LOCKSTEP_FPS="25",
        SO101_EPISODE_FRAMES=last_frame, on_send=lambda output, metadata: sent.append(metadata["frame"])
        if output == "joint_state" else None)
    assert code == 0
    # With SO101_EPISODE_FRAMES=2 the answer to frame 2 is not applied: no frame 3; the reset starts frame 0.
    assert sent == frames_out
