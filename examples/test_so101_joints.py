"""Course step B (test_so101_joints.py): turn joints 0-4 and print the angles reached.

Run:  python examples/test_so101_joints.py            (a window where a display exists)
      SO101_MODE=direct python examples/test_so101_joints.py --steps 0   (headless)

The same as `so101 joints`, with the raw PyBullet calls. As in the course, every
step re-sends the five targets with setJointMotorControl2 (PyBullet would keep
them anyway: a POSITION_CONTROL target holds until replaced). Differences from
the course's script: the model comes from this repo's assets/SO101, a headless
machine runs DIRECT and stops, and radians become degrees with math.degrees
rather than 180 / 3.14159. The set-up (model and display checks, connect,
gravity, ground) is open_course_world in so101/cli/course_steps.py, as in step A.
"""

import argparse
import math
import sys
import time

import pybullet as p

from so101.cli.course_steps import open_course_world, step_course_world

ARM_JOINT_INDICES = [0, 1, 2, 3, 4]  # index 5 is the fixed gripper_frame_joint, 6 the gripper
TARGETS_RAD = [0.5, -0.5, 0.5, -0.5, 0.5]  # PyBullet works in radians: 0.5 rad = 28.6°
DRIVE_STEPS = 500


def main() -> int:
    parser = argparse.ArgumentParser(description="Course step B: drive joints 0-4 and print the angles reached.")
    parser.add_argument("--steps", type=int, help="after printing, simulate this many more steps and exit "
                        "(default: until Ctrl+C with a window, 0 headless)")
    args = parser.parse_args()

    mode, urdf = open_course_world("test_so101_joints.py")  # SO101_MODE=gui|direct|auto picks the mode
    robot_id = p.loadURDF(str(urdf), useFixedBase=True)

    for _ in range(DRIVE_STEPS):
        for joint_index, target_rad in zip(ARM_JOINT_INDICES, TARGETS_RAD):
            p.setJointMotorControl2(
                bodyUniqueId=robot_id,
                jointIndex=joint_index,
                controlMode=p.POSITION_CONTROL,
                targetPosition=target_rad,
                maxVelocity=3.0,  # rad/s
            )
        p.stepSimulation()
        if mode == "gui":
            time.sleep(1 / 240)

    print("\n当前关节角度:")
    for joint_index in ARM_JOINT_INDICES:
        angle_rad = p.getJointState(robot_id, joint_index)[0]  # [0] is the position, in radians
        print(f"  关节 {joint_index}: {math.degrees(angle_rad):.1f}°")

    steps = args.steps if args.steps is not None else (None if mode == "gui" else 0)
    step_course_world(mode, steps, waiting="\n观察机械臂姿态,按 Ctrl+C 退出")
    p.disconnect()
    return 0


if __name__ == "__main__":
    sys.exit(main())
