"""Course step A (test_so101.py): load the SO-101 in PyBullet and print its joints.

Run:  python examples/test_so101.py            (a window where a display exists)
      SO101_MODE=direct python examples/test_so101.py --steps 240   (headless)

The same as `so101 inspect`, written with the raw PyBullet calls so each one is
visible. Differences from the course's script: the model comes from this repo's
assets/SO101 (verified first, so a missing file gives a clear message, not
"Cannot load URDF file"), and a machine without a display runs DIRECT and stops
after a bounded number of steps instead of dying on "cannot connect to X server".
"""

import argparse
import os
import sys
import time

import pybullet as p
import pybullet_data

from so101.assets import ModelFilesError, urdf_path
from so101.display import DisplayError, resolve_mode

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

    try:
        urdf = urdf_path()
        mode, notice = resolve_mode(os.environ.get("SO101_MODE", "auto"))
    except (ModelFilesError, DisplayError, ValueError) as error:
        print(f"test_so101.py: {error}", file=sys.stderr)
        return 2
    if notice:
        print(notice)

    p.connect(p.GUI if mode == "gui" else p.DIRECT)
    p.setAdditionalSearchPath(pybullet_data.getDataPath())  # where plane.urdf lives
    p.setGravity(0, 0, -9.81)
    p.loadURDF("plane.urdf")
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
    if steps is None:
        print("\n运行中... 按 Ctrl+C 退出", flush=True)
    try:
        count = 0
        while steps is None or count < steps:
            p.stepSimulation()
            count += 1
            if mode == "gui":
                time.sleep(1 / 240)  # real time for the viewer; headless runs flat out
    except KeyboardInterrupt:
        print("\n停止仿真")
    p.disconnect()
    return 0


if __name__ == "__main__":
    sys.exit(main())
