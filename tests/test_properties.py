"""Property-based tests: whatever arrives as a `joint_cmd`, decoding never raises.

Examples per property: the `ci` profile (a few hundred) by default, the `soak`
profile (10,000) with HYPOTHESIS_PROFILE=soak; both are registered in conftest.py.
"""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from so101.joint_cmd import decode_joint_cmd
from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS

NUMERIC_DTYPES = [
    np.int8, np.int16, np.int32, np.int64, np.uint8, np.uint16, np.uint32, np.uint64,
    np.float16, np.float32, np.float64,
]
LENGTHS = st.one_of(st.sampled_from([0, 1, 2, 5, 6]), st.integers(0, 40))

# Any double: NaN, ±inf, subnormals, ±1e308, -0.0.
any_float = st.floats(allow_nan=True, allow_infinity=True)
huge_int = st.integers(-(2**70), 2**70)


@st.composite
def numeric_arrays(draw):
    """Every integer and float width, any length, with NaN/inf/extremes and optional nulls."""
    dtype = np.dtype(draw(st.sampled_from(NUMERIC_DTYPES)))
    length = draw(LENGTHS)
    values = draw(hnp.arrays(dtype, length, elements=hnp.from_dtype(dtype)))
    if draw(st.booleans()):
        return pa.array(values)
    mask = draw(hnp.arrays(np.bool_, length))
    return pa.array(values, mask=mask)


def _python_array(values_strategy, arrow_type):
    return st.lists(st.one_of(st.none(), values_strategy), max_size=12).map(
        lambda values: pa.array(values, type=arrow_type)
    )


def other_typed_arrays():
    """Everything that is not a flat numeric array: each must be refused with a message."""
    floats_or_null = st.one_of(st.none(), any_float)
    return st.one_of(
        _python_array(st.booleans(), pa.bool_()),
        _python_array(st.text(max_size=8), pa.string()),
        _python_array(st.text(max_size=8), pa.large_string()),
        _python_array(st.binary(max_size=8), pa.binary()),
        st.integers(0, 12).map(lambda n: pa.nulls(n)),
        _python_array(st.integers(-(2**31), 2**31 - 1), pa.date32()),
        _python_array(st.integers(-(2**62), 2**62), pa.timestamp("ns")),
        _python_array(st.decimals(allow_nan=False, allow_infinity=False, places=2, min_value=-1e6, max_value=1e6),
                      pa.decimal128(12, 2)),
        _python_array(st.lists(floats_or_null, max_size=7), pa.list_(pa.float64())),
        _python_array(st.lists(st.integers(-(2**63), 2**63 - 1), max_size=7), pa.large_list(pa.int64())),
        _python_array(st.lists(floats_or_null, min_size=2, max_size=2), pa.list_(pa.float64(), 2)),
        _python_array(
            st.lists(st.lists(floats_or_null, max_size=3), max_size=3), pa.list_(pa.list_(pa.float64()))
        ),
        _python_array(
            st.fixed_dictionaries({"joint": st.integers(-128, 127), "angle": any_float}),
            pa.struct([("joint", pa.int8()), ("angle", pa.float64())]),
        ),
        # Dictionary-encoded numbers and strings: numeric-looking, but not a plain numeric array.
        st.lists(st.one_of(st.none(), any_float), max_size=12).map(lambda v: pa.array(v).dictionary_encode()),
        st.lists(st.text(max_size=4), max_size=12).map(lambda v: pa.array(v, pa.string()).dictionary_encode()),
    )


@st.composite
def sliced(draw, arrays):
    """Arrays with a non-zero offset, as a zero-copy slice of a bigger buffer produces."""
    array = draw(arrays)
    start = draw(st.integers(0, len(array)))
    return array.slice(start, draw(st.integers(0, len(array) - start)))


@st.composite
def chunked(draw, arrays):
    array = draw(arrays)
    cuts = sorted(draw(st.lists(st.integers(0, len(array)), max_size=3)))
    bounds = [0, *cuts, len(array)]
    return pa.chunked_array([array.slice(a, b - a) for a, b in zip(bounds, bounds[1:])], type=array.type)


arrow_arrays = st.one_of(numeric_arrays(), other_typed_arrays())
non_arrow_values = st.one_of(
    st.none(), st.booleans(), huge_int, any_float, st.text(max_size=20), st.binary(max_size=20),
    st.lists(st.one_of(huge_int, any_float, st.none()), max_size=8),
    st.lists(st.one_of(huge_int, any_float), max_size=8).map(tuple),
    st.dictionaries(st.text(max_size=4), any_float, max_size=3),
    hnp.arrays(st.sampled_from(NUMERIC_DTYPES).map(np.dtype), st.integers(0, 8)),
    st.builds(object),
)
any_joint_cmd = st.one_of(arrow_arrays, sliced(arrow_arrays), chunked(arrow_arrays), non_arrow_values)

# What the node holds before a command arrives: always valid targets.
current_targets = st.tuples(
    *[st.floats(joint.lower_deg, joint.upper_deg) for joint in ACTUATED_JOINTS]
)


def assert_valid_targets(targets_deg):
    assert len(targets_deg) == len(ACTUATED_JOINTS)
    for joint, angle in zip(ACTUATED_JOINTS, targets_deg):
        assert isinstance(angle, float) and math.isfinite(angle), (joint.name, angle)
        assert joint.lower_deg <= angle <= joint.upper_deg, (joint.name, angle)


@given(value=any_joint_cmd, current=current_targets)
def test_decode_never_raises_and_gives_limited_targets_or_a_message(value, current):
    decoded = decode_joint_cmd(value, current)
    assert (decoded.targets_deg is None) != (decoded.error is None), decoded
    if decoded.error is not None:
        assert "accepted:" in decoded.error
        assert "\n" not in decoded.error, "a rejection must be one log line"
    else:
        assert_valid_targets(decoded.targets_deg)


def _as_floats(array: pa.Array) -> list[float]:
    return [float(number) for number in array.to_pylist()]


@st.composite
def well_formed_commands(draw):
    """A numeric array with no nulls, NaN or inf, in one of the three accepted shapes (angles may be huge)."""
    dtype = np.dtype(draw(st.sampled_from(NUMERIC_DTYPES)))
    finite = hnp.from_dtype(dtype, allow_nan=False, allow_infinity=False)
    shape = draw(st.sampled_from(["single", "arm", "arm+gripper"]))
    if shape == "single":
        index = draw(st.integers(0, len(ACTUATED_JOINTS) - 1))
        values = np.array([index, draw(finite)], dtype=dtype)
    else:
        length = NUM_ARM_JOINTS if shape == "arm" else len(ACTUATED_JOINTS)
        values = draw(hnp.arrays(dtype, length, elements=finite))
    array = pa.array(values)
    assume(all(math.isfinite(v) for v in _as_floats(array)))  # float16 index 5 etc. stay finite
    return array


@given(command=well_formed_commands(), current=current_targets)
def test_well_formed_commands_are_accepted_and_clamped_to_the_limits(command, current):
    decoded = decode_joint_cmd(command, current)
    assert decoded.error is None, decoded.error
    assert_valid_targets(decoded.targets_deg)
    numbers = _as_floats(command)
    expected = list(current)
    if len(numbers) == 2:
        index = int(numbers[0])
        assert decoded.joint_index == index
        updates = {index: numbers[1]}
    else:
        updates = dict(enumerate(numbers))
    for position, angle in updates.items():
        joint = ACTUATED_JOINTS[position]
        expected[position] = min(max(angle, joint.lower_deg), joint.upper_deg)
    assert decoded.targets_deg == tuple(expected)
    # Every clamped value is reported, and only those.
    clamped = [p for p, a in updates.items() if not ACTUATED_JOINTS[p].lower_deg <= a <= ACTUATED_JOINTS[p].upper_deg]
    assert len(decoded.notes) == len(clamped)
