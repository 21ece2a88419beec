"""Which saved results of bench/results/ predate a change to the code they measure (`so101 bench --stale`).

Each result the docs quote names the files whose change moves its figures, and the command that
measures it again. A result is stale when a commit after the one that last saved it changed one of
those files: the change that moves a figure reruns it (tests/test_bench.py holds every result to
that). Read from git's history; a checkout without it cannot tell, and says so.
"""

from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path

RESULTS = Path("bench") / "results"

# The code on each benchmark's path: the body's tick, the cameras' pictures, the recorder, the lockstep loop.
PYBULLET_TICK = ("so101/bodies/pybullet_sim.py", "so101/bodies/command_path.py", "so101/bodies/node_loop.py",
                 "nodes/simulation_node.py")
MUJOCO_TICK = ("so101/bodies/mujoco_sim.py", "so101/bodies/command_path.py", "so101/bodies/node_loop.py",
               "nodes/simulation_mujoco.py")
RECORDING = ("nodes/recorder.py", "so101/dataset/recording.py", "so101/dataset/video.py", "so101/dataset/episode.py",
             "bench/record_bench.py")
PICTURES = ("so101/bodies/task_cameras.py", "so101/bodies/mujoco_sim.py", "nodes/camera.py", "bench/camera_bench.py")
LOCKSTEP = ("so101/bodies/task_cameras.py", "so101/bodies/node_loop.py", "so101/bodies/command_path.py",
            "nodes/episodes.py", "nodes/expert.py", "so101/launch/lockstep.py", "so101/dataset/video.py",
            "so101/dataset/episode.py", "bench/demos_bench.py")
GYM = ("so101/gym/", "so101/bodies/task_cameras.py", "so101/bodies/command_path.py", "bench/gym_bench.py")
WEB = ("nodes/web_view.py", "so101/web/", "bench/web_bench.py", "bench/browser.py")
CLUSTER = ("dataflow_cluster.yml", "so101/launch/on_cluster.py", "so101/runtime/cluster.py")
REAL = ("so101/bodies/real_arm.py", "so101/feetech/bus.py", "so101/feetech/fake_arm/", "nodes/arm_node.py",
        "bench/real_bench.py")


@dataclass(frozen=True)
class Measured:
    """A saved result, the files whose change moves its figures, and the command that measures it again."""

    result: str  # its name in bench/results/
    code: tuple[str, ...]  # files, or folders ending in /
    command: str


MEASURED = (
    Measured("latest.json", PYBULLET_TICK + RECORDING + ("bench/run_bench.py",), "so101 bench"),
    Measured("latest-mujoco.json", MUJOCO_TICK + RECORDING + ("bench/run_bench.py",), "so101 bench --body mujoco"),
    Measured("latest-real.json", REAL, "so101 bench --body real"),
    Measured("latest-cameras.json", PICTURES + RECORDING + ("so101/bodies/pybullet_sim.py",), "so101 bench --cameras"),
    Measured("latest-cameras-mujoco.json", PICTURES + RECORDING, "so101 bench --cameras --body mujoco"),
    Measured("latest-demos.json", LOCKSTEP + ("so101/bodies/pybullet_sim.py",), "so101 bench --demos"),
    Measured("latest-demos-mujoco.json", LOCKSTEP + ("so101/bodies/mujoco_sim.py",), "so101 bench --demos --body mujoco"),
    Measured("latest-gym.json", GYM + ("so101/bodies/pybullet_sim.py",), "so101 bench --gym"),
    Measured("latest-gym-mujoco.json", GYM + ("so101/bodies/mujoco_sim.py",), "so101 bench --gym --body mujoco"),
    Measured("latest-web.json", PYBULLET_TICK + WEB, "so101 bench --web"),
    Measured("latest-cluster.json", PYBULLET_TICK + CLUSTER + ("bench/cluster_bench.py",), "so101 bench --cluster"),
)
# Not here: the policy round trips (latest-round-trip*.json). They time a trained state policy of 300
# demonstrations that the repository does not hold (docs/loop/policy-elsewhere.md says how it was made):
# rerun them with one, `so101 bench --round-trip [--sealed] --policy DIR`.


def git(root: Path, *args: str) -> str:
    done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, check=True)
    return done.stdout.strip()


def has_history(root: Path) -> bool:
    """Whether `root` is a git checkout with the history that saved its results (not a shallow copy)."""
    try:
        return git(root, "rev-parse", "--is-shallow-repository") == "false"
    except (OSError, subprocess.CalledProcessError):
        return False


def changes_since_saved(root: Path, measured: Measured) -> list[str]:
    """The commits (`hash subject`, newest first) after the one that last saved `measured.result` that
    change its code; [] when it is up to date."""
    saved = git(root, "log", "-1", "--format=%H", "--", str(RESULTS / measured.result))
    if not saved:
        return [f"(never committed) {measured.result}"]
    listed = git(root, "log", "--format=%h %s", f"{saved}..HEAD", "--", *measured.code)
    return [line[:100] for line in listed.splitlines()]


def stale_lines(root: Path) -> list[str]:
    """One line for each stale result, with the command that measures it again; [] when all are up to date."""
    lines = []
    for measured in MEASURED:
        changes = changes_since_saved(root, measured)
        if changes:
            lines.append(f"{RESULTS / measured.result}: {len(changes)} later commit(s) change what it measures "
                         f"(newest {changes[0].split()[0]}); rerun: {measured.command}")
    return lines
