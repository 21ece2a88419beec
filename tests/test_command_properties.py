"""Property-based tests of the prompt's parser: whatever a person types, it never raises.

Examples per property: the `ci` profile (a few hundred) by default, the `soak`
profile (10,000) with HYPOTHESIS_PROFILE=soak; both are registered in conftest.py.
"""

from __future__ import annotations

import dataclasses

from hypothesis import given
from hypothesis import strategies as st

from so101.lang import LANGUAGES
from so101.prompt.commands import (
    NO_ARGUMENT_COMMANDS, Batch, Empty, GoPose, ParseError, SavePose, SetJoint, parse_command,
)
from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS

LANGS = st.sampled_from(LANGUAGES)
# Words a person might mix up: the command words, numbers of every form, and noise.
COMMAND_WORDS = sorted(NO_ARGUMENT_COMMANDS) + ["batch", "grip", "save", "go"]
NUMBER_WORDS = st.one_of(
    st.integers(-1000, 1000).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["nan", "inf", "-inf", "1e999", "+5", ".5", "5.", "1e-3", "0x10", "1_000", "٣"]),
)
WORDS = st.one_of(st.sampled_from(COMMAND_WORDS), NUMBER_WORDS, st.text(min_size=1, max_size=12))
SEPARATORS = st.sampled_from([" ", "  ", "\t", ",", ",", " , "])


@st.composite
def typed_lines(draw):
    """Lines of words and separators, built from what the parser looks for, or any text at all."""
    if draw(st.booleans()):
        return draw(st.text(max_size=80))
    words = draw(st.lists(WORDS, max_size=8))
    line = ""
    for word in words:
        line += word + draw(SEPARATORS)
    return draw(st.sampled_from(["", " ", "\t"])) + line


def assert_in_limits(index: int, angle_deg: float) -> None:
    joint = ACTUATED_JOINTS[index]
    assert joint.lower_deg <= angle_deg <= joint.upper_deg, (joint.name, angle_deg)


@given(line=typed_lines(), lang=LANGS)
def test_any_line_gives_a_command_or_a_one_line_message(line, lang):
    result = parse_command(line, lang)
    if isinstance(result, ParseError):
        assert result.message.strip(), repr(line)
        assert "\n" not in result.message
        return
    assert dataclasses.is_dataclass(result)
    if isinstance(result, SetJoint):
        assert 0 <= result.index < len(ACTUATED_JOINTS)
        assert_in_limits(result.index, result.angle_deg)
    elif isinstance(result, Batch):
        assert len(result.angles_deg) in (NUM_ARM_JOINTS, NUM_ARM_JOINTS + 1)
        for index, angle in enumerate(result.angles_deg):
            assert_in_limits(index, angle)
    elif isinstance(result, (SavePose, GoPose)):
        assert result.name.strip() and len(result.name) <= 40
    elif isinstance(result, Empty):  # only blanks and commas
        assert line.replace(",", " ").replace(",", " ").split() == []


@given(
    index=st.integers(0, len(ACTUATED_JOINTS) - 1),
    angle=st.floats(-400, 400, allow_nan=False),
    lang=LANGS,
)
def test_a_joint_command_inside_the_limits_is_taken_and_one_outside_refused(index, angle, lang):
    joint = ACTUATED_JOINTS[index]
    typed = f"{angle:.3f}"
    shown = float(typed)
    result = parse_command(f"{index} {typed}", lang)
    if round(joint.lower_deg, 1) <= shown <= round(joint.upper_deg, 1):
        assert isinstance(result, SetJoint) and result.index == index
        assert abs(result.angle_deg - shown) <= 0.05  # only the hair past the exact URDF limit is clamped
        assert_in_limits(index, result.angle_deg)
    else:
        assert isinstance(result, ParseError)
        assert joint.name in result.message
