"""A dataset's joint units: stated, said, or told by values that can only be one; never guessed.

LeRobot's `so101_follower` writes the five body joints in one of two units, and nothing in its
dataset says which:
- degrees (`use_degrees`, LeRobot 0.4's default): 0° at the middle of the calibrated range;
- normalized (earlier releases' default, so many Hub datasets): -100..100 across the calibrated range.
The gripper is 0..100 across its range in both. This project writes degrees and says so in
info.json (`UNITS_KEY`). For a dataset from elsewhere, `--units` says which, and the follower's
calibration (`range_min`, `range_max`, `drive_mode`) turns normalized values into degrees: a joint's
100 units are half its calibrated range. A body joint beyond ±100 can only be degrees. Otherwise a
reader refuses, in one line naming both options. Pure numpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import numpy.typing as npt

from so101.dataset.layout import DatasetError
from so101.feetech.calibration import DEG_PER_STEP, MotorCalibration
from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS

# In info.json, beside LeRobot's keys: the joints' units, "degrees" or "normalized".
UNITS_KEY = "so101_joint_units"
DEGREES, NORMALIZED = "degrees", "normalized"
UNITS = (DEGREES, NORMALIZED)
NORMALIZED_BOUND = 100.0
UNITS_HELP = ("the dataset's joint units, where its meta does not say (LeRobot's so101_follower writes degrees with "
              "use_degrees, LeRobot 0.4's default, else normalized: -100..100 across each joint's calibrated range)")


class UnitsError(DatasetError):
    """A dataset whose joint units cannot be known, or that contradict what was said; one line."""


@dataclass(frozen=True)
class JointUnits:
    """How a dataset's joints are read: `units`, and for normalized ones each body joint's degrees per
    100 units, from a calibration or nominal."""

    units: str
    how: str  # one line: where the units and the scale came from
    degrees_per_100: tuple[float, ...] = ()

    def as_degrees(self, values: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """A dataset's joints, (..., 6), as LeRobot's degree-mode values: the body in degrees, the gripper 0..100."""
        joints = np.array(values, dtype=np.float64)
        if self.units == NORMALIZED:
            joints[..., :NUM_ARM_JOINTS] *= np.asarray(self.degrees_per_100) / NORMALIZED_BOUND
        return joints


def calibrated_degrees_per_100(calibration: Mapping[str, MotorCalibration]) -> tuple[float, ...]:
    """Each body joint's degrees per 100 normalized units: half its calibrated range (LeRobot's RANGE_M100_100).
    LeRobot negates a drive_mode 1 joint's normalized value, as so101.feetech.calibration turns its degrees:
    no sign here."""
    return tuple((calibration[joint.name].range_max - calibration[joint.name].range_min) / 2 * DEG_PER_STEP
                 for joint in ACTUATED_JOINTS[:NUM_ARM_JOINTS])


def nominal_degrees_per_100() -> tuple[float, ...]:
    """Half each body joint's range in the URDF: an arm calibrated across its whole travel."""
    return tuple((joint.upper_deg - joint.lower_deg) / 2 for joint in ACTUATED_JOINTS[:NUM_ARM_JOINTS])


def joint_units(info: Mapping[str, Any], joints: npt.ArrayLike, said: str | None = None,
                calibration: Mapping[str, MotorCalibration] | None = None, calibration_name: str = "") -> JointUnits:
    """How to read a dataset's joints: its meta's `UNITS_KEY`, else `said` (--units), else degrees where a
    body joint of `joints` (its actions and states, (N, 6)) is beyond ±100; UnitsError otherwise, and
    where what is said contradicts the meta or the values."""
    stated = info.get(UNITS_KEY)
    if stated is not None and stated not in UNITS:
        raise UnitsError(f"info.json says the joints are in {stated!r}: accepted {' or '.join(UNITS)}")
    body = np.abs(np.asarray(joints, dtype=np.float64).reshape(-1, len(ACTUATED_JOINTS))[:, :NUM_ARM_JOINTS])
    widest = float(body.max()) if body.size else 0.0
    beyond = widest > NORMALIZED_BOUND + 1e-3
    if stated is not None and said is not None and said != stated:
        raise UnitsError(f"the dataset says its joints are in {stated}, not {said}: leave --units out")
    units = stated or said
    if units == NORMALIZED and beyond:
        raise UnitsError(f"a body joint reaches {widest:.1f}, beyond ±{NORMALIZED_BOUND:g}: these joints are degrees, "
                         "not normalized")
    if units is None:
        if not beyond:
            raise UnitsError(f"the dataset does not say its joints' units, and its values (within ±{NORMALIZED_BOUND:g}) "
                             "could be degrees or LeRobot's normalized units: say --units degrees, or --units normalized "
                             "(with --calibration FILE, the recording follower's calibration)")
        return JointUnits(DEGREES, f"joints in degrees: a body joint reaches {widest:.1f}, beyond normalized's "
                                   f"±{NORMALIZED_BOUND:g}")
    source = "stated in the dataset" if stated else "said by --units"
    if units == DEGREES:
        return JointUnits(DEGREES, f"joints in degrees ({source})")
    if calibration is not None:
        return JointUnits(NORMALIZED, f"joints in LeRobot's normalized units ({source}), made degrees with the "
                                      f"calibrated ranges of {calibration_name or 'the calibration'}",
                          calibrated_degrees_per_100(calibration))
    return JointUnits(NORMALIZED, f"joints in LeRobot's normalized units ({source}), made degrees with the URDF's "
                                  "joint ranges as the calibrated ones (--calibration FILE gives the arm's own)",
                      nominal_degrees_per_100())
