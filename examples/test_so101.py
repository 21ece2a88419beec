"""Course step A (test_so101.py): load the SO-101 in PyBullet and print its joints.

Run:  python examples/test_so101.py            (a window where a display exists)
      SO101_MODE=direct python examples/test_so101.py --steps 240   (headless)

The same as `so101 inspect`, written with the raw PyBullet calls so each one is
visible. Differences from the course's script: the model comes from this repo's
assets/SO101 (verified first, so a missing file gives a clear message, not
"Cannot load URDF file"), and a machine without a display runs DIRECT and stops
after a bounded number of steps instead of dying on "cannot connect to X server".
Those two checks, and the course's connect/gravity/ground calls, are in
open_course_world (so101/cli/course_steps.py), shared with step B.
"""

import argparse
import sys

import pybullet as p

from so101.cli.course_steps import open_course_world, step_course_world

JOINT_TYPE_LABELS = {
    p.JOINT_REVOLUTE: "旋转关节 (Revolute)",
    p.JOINT_PRISMATIC: "棱柱关节 (Prismatic)",
    p.JOINT_FIXED: "固定关节 (Fixed)",
}


def main() -> int:
    parser = argparse.ArgumentParser(description="Course step A: load the SO-101 and print its joint table.")
    parser.add_argument("--steps", type=int, help="simulate this many steps, then exit (default: until Ctrl+C "
                        "with a window, 240 headless)")
    args = parser.parse_args()

    mode, urdf = open_course_world("test_so101.py")  # SO101_MODE=gui|direct|auto picks the mode
    # The URDF's mesh paths (assets/*.stl) are relative to the URDF file itself,
    # so loading it by its full path is enough.
    robot_id = p.loadURDF(str(urdf), basePosition=[0, 0, 0], baseOrientation=[0, 0, 0, 1], useFixedBase=True)
    print(f"SO-101 已加载,robot_id = {robot_id}")

    num_joints = p.getNumJoints(robot_id)
    print(f"关节数量: {num_joints}\n")
    for index in range(num_joints):
        info = p.getJointInfo(robot_id, index)
        name, joint_type = info[1].decode(), info[2]  # the name comes back as bytes
        label = JOINT_TYPE_LABELS.get(joint_type, f"其他 ({joint_type})")
        print(f"  关节 {index}: {name:22s} 类型: {label}")

    steps = args.steps if args.steps is not None else (None if mode == "gui" else 240)
    if step_course_world(mode, steps, waiting="\n运行中... 按 Ctrl+C 退出"):
        print("\n停止仿真")
    p.disconnect()
    return 0


if __name__ == "__main__":
    sys.exit(main())
