"""Shared pytest set-up.

Hypothesis profiles: `ci` (the default, a few hundred examples per property) and
`soak` (10,000 per property, run by hand):
    HYPOTHESIS_PROFILE=soak .venv/bin/python -m pytest tests/test_properties.py tests/test_command_properties.py
No deadline in either: the suite has no timed tests, and a loaded CI machine
must not turn a slow example into a failure.
"""

import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

# tests/helpers/ holds code moved out of the test modules: its asserts report as theirs do.
pytest.register_assert_rewrite("tests.helpers")

from tests.helpers.network import network_of_its_own  # noqa: E402  (after the line above, to be rewritten)
# The policy environment and a tiny policy that sees, made once a session for every module that runs a policy.
from tests.helpers.policies import policy_python, seeing_policy, seeing_recipe  # noqa: E402,F401

settings.register_profile("ci", max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("soak", max_examples=10_000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


# -- in parallel (pytest-xdist: `-n auto --dist loadgroup`, pyproject's addopts) -------------------
# dora 1.1's `dora run` (and a daemon started without --local-listen-port, as `dora up`'s) always
# listens on port 53291 for dynamic nodes, the prompt among them: two at once and a prompt joins the
# wrong one. So each worker, where it may (root, with `ip`), runs in a network namespace of its own,
# loopback only: its dataflows, prompts and browsers have every port to themselves. Its tmux server
# is its own too (a shared one would start the other worker's terminals in its namespace). Where a
# worker cannot, every test that starts dora runs in one xdist group, one after another on one worker.
# These modules start dora in some of their tests (dora run, dora up, so101 teleop, replay, cluster).
DORA_MODULES = {
    "test_course_differences", "test_dataflow", "test_environment", "test_faults", "test_gui",
    "test_leader", "test_log_noise", "test_prompt_tmux", "test_real_arm", "test_record_replay",
    "test_two_dataflows", "test_two_machines", "test_web_view",
}
# These start dora's daemons with ports of their own (--local-listen-port, which `dora daemon` honours
# and `dora run` does not): without namespaces, beside the dora group, one test at a time among themselves.
OWN_PORT_MODULES = {"test_cluster", "test_policy_elsewhere"}
MAX_WORKERS = 4


def pytest_configure(config):
    if not hasattr(config, "workerinput"):
        return
    from tests.helpers.machine_lock import MachineLock

    config.so101_machine_lock = MachineLock(Path(config.workerinput["so101_lock_dir"]))
    if network_of_its_own():
        config.so101_own_network = True
        tmux_dir = Path(tempfile.mkdtemp(prefix=f"so101-tmux-{config.workerinput['workerid']}-"))
        os.environ["TMUX_TMPDIR"] = str(tmux_dir)


def pytest_unconfigure(config):
    tmux_dir = os.environ.get("TMUX_TMPDIR", "")
    if getattr(config, "so101_own_network", False) and Path(tmux_dir).name.startswith("so101-tmux-"):
        subprocess.run(["tmux", "kill-server"], capture_output=True)
        shutil.rmtree(tmux_dir, ignore_errors=True)


@pytest.hookimpl(optionalhook=True)  # an xdist hook
def pytest_xdist_auto_num_workers(config):
    """One worker per core, at most MAX_WORKERS."""
    return max(1, min(os.cpu_count() or 1, MAX_WORKERS))


def runs_alone(item) -> bool:
    """`alone` tests measure or load the whole machine; `realtime` ones (a driver and emulated servos
    keeping a real-time pace: every emulated_hardware test and every real-body one) are starved by
    what runs beside them on a machine of few cores, as a real arm's driver would be."""
    return item.get_closest_marker("alone") is not None or item.get_closest_marker("realtime") is not None


@pytest.hookimpl(tryfirst=True)  # before xdist's own, which reads the groups
def pytest_collection_modifyitems(config, items):
    """A real dataflow, a person's session or a realtime test is slow too: `-m "not slow"` is the fast subset. The
    tests that run alone are one xdist group, run one after another. Without a network of its own per
    worker, tests that start dora share one xdist group (DORA_MODULES)."""
    for item in items:
        if item.get_closest_marker("dataflow") or item.get_closest_marker("person"):
            item.add_marker(pytest.mark.slow)
        params = getattr(item, "callspec", None) and item.callspec.params
        if item.get_closest_marker("emulated_hardware") or (params and params.get("body") == "real"):
            item.add_marker(pytest.mark.realtime)
        if item.get_closest_marker("realtime"):  # it keeps the wall clock's pace: seconds, however fast the machine
            item.add_marker(pytest.mark.slow)
        module = item.module.__name__.rsplit(".", 1)[-1]
        if runs_alone(item):
            item.add_marker(pytest.mark.xdist_group("alone"))
        elif getattr(config, "so101_own_network", False):
            continue
        elif module in OWN_PORT_MODULES:
            item.add_marker(pytest.mark.xdist_group(module))
        elif item.get_closest_marker("dataflow") or item.get_closest_marker("person") or module in DORA_MODULES:
            item.add_marker(pytest.mark.xdist_group("dora"))


@pytest.hookimpl(trylast=True)
def pytest_collection_finish(session):
    """Under --dist loadgroup, xdist marks a grouped test's id with its group: without that mark the
    groups are silently ignored (pytest 9.2 with pytest-xdist 3.8, xdist issue #1386), and dora's
    tests would collide. Refuse to run then rather than fail at random."""
    if not getattr(session.config.option, "loadgroup", False):
        return
    for item in session.items:
        if item.get_closest_marker("xdist_group") and "@" not in item.nodeid.rsplit("]", 1)[-1]:
            raise pytest.UsageError(
                f"pytest-xdist does not group {item.nodeid} (pytest {pytest.__version__}): the tests that start "
                "dora would run two at a time. Install the test extra's pytest (pip install -e '.[test]'), "
                "or run with -n 0")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Under xdist, a test that runs alone holds the machine's lock exclusively, every other test holds
    it shared (tests/helpers/machine_lock.py); one alone test hands it to the next without letting go."""
    lock = getattr(item.config, "so101_machine_lock", None)  # a worker's (pytest_configure)
    if lock is not None:
        lock.take(exclusive=runs_alone(item))
    yield
    if lock is not None and not (nextitem is not None and runs_alone(item) and runs_alone(nextitem)):
        lock.release()


@pytest.hookimpl(optionalhook=True)  # an xdist hook
def pytest_configure_node(node):
    """xdist's controller: one folder for the machine's lock, shared by its workers."""
    lock_dir = getattr(node.config, "so101_lock_dir", None)
    if lock_dir is None:
        lock_dir = node.config.so101_lock_dir = tempfile.mkdtemp(prefix="so101-machine-lock-")
    node.workerinput["so101_lock_dir"] = lock_dir


# -- the model files -------------------------------------------------------------------


@pytest.fixture(scope="session")
def model_dir() -> Path:
    """The verified model this checkout uses (fails with our message if it is missing)."""
    from so101 import assets

    return assets.urdf_path().parent


@pytest.fixture
def model_copy(model_dir, tmp_path) -> Path:
    """A private copy of the verified model, to break."""
    from tests.helpers.dataflow import copy_model

    return copy_model(tmp_path / "SO101")


# -- simulators ------------------------------------------------------------------------
# Headless always: the suite must pass on a machine without a display.


@pytest.fixture(scope="session")
def shared_sim():
    """One DIRECT simulator for tests that only read (the joint table); never drive it."""
    from so101.bodies.pybullet_sim import SO101Sim

    sim = SO101Sim(mode="direct", log=lambda message: None)
    yield sim
    sim.close()


@pytest.fixture
def make_sim():
    """A factory of fresh DIRECT simulators, each at home and closed after the test."""
    from so101.bodies.pybullet_sim import SO101Sim

    made = []

    def make(**options):
        sim = SO101Sim(mode="direct", log=lambda message: None, **options)
        made.append(sim)
        return sim

    yield make
    for sim in made:
        sim.close()


# -- a display, and a machine free of other dataflows ------------------------------------


@pytest.fixture
def xvfb_display(tmp_path):
    """A fresh Xvfb server, stopped after the test."""
    from so101.runtime.display import DisplayError, virtual_display

    try:
        with virtual_display(tmp_path / "xvfb.log") as display:
            yield display
    except DisplayError as error:
        pytest.skip(str(error))


OTHERS_WAIT_S = 180


@pytest.fixture
def no_other_dataflow():
    """Another program's dataflow that takes a prompt (on a shared runner) would be the one named: wait for none."""
    from so101.prompt.join import port_holder, unreachable_dataflows

    deadline = time.monotonic() + OTHERS_WAIT_S
    while port_holder() or unreachable_dataflows("keyboard_control", None):
        if time.monotonic() > deadline:
            pytest.skip(f"another dora dataflow kept running on this machine for {OTHERS_WAIT_S} s")
        time.sleep(1)


# -- the course's joint table --------------------------------------------------------------
# The independent oracle for robot.JOINT_TABLE and every printed table: what the
# course shows for step A, stated here once and not derived from the code.
COURSE_JOINT_NAMES = (
    "shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper_frame_joint", "gripper",
)
COURSE_FIXED_JOINTS = {"gripper_frame_joint"}
COURSE_TYPE_WORDS_ZH = {"revolute": "旋转关节 (Revolute)", "fixed": "固定关节 (Fixed)"}


@pytest.fixture(scope="session")
def course_joint_table() -> list[tuple[int, str, str]]:
    """Course step A's seven joints as (PyBullet index, name, type)."""
    return [
        (index, name, "fixed" if name in COURSE_FIXED_JOINTS else "revolute")
        for index, name in enumerate(COURSE_JOINT_NAMES)
    ]


@pytest.fixture(scope="session")
def course_printed_table(course_joint_table) -> list[tuple[int, str, str]]:
    """The same rows as course step A prints them: (index, name, type in the course's Chinese words)."""
    return [(index, name, COURSE_TYPE_WORDS_ZH[kind]) for index, name, kind in course_joint_table]


@pytest.fixture(scope="session")
def course_step_b_deg() -> list[float]:
    """Course step B's targets, [0.5, -0.5, 0.5, -0.5, 0.5] rad, in degrees: 0.5 rad = 28.65°."""
    return [28.65, -28.65, 28.65, -28.65, 28.65]


@pytest.fixture(autouse=True)
def no_real_time_threads_after_the_test():
    """SVT-AV1 makes the thread that opens it SCHED_FIFO where it may (as root): tests that encode
    in their own thread (tests/helpers/lerobot_written.py writes as LeRobot does) left this process's main
    thread real-time, and every later test's emulated arm (a thread here) and window (a child,
    inheriting it) starved behind it. Each test starts as the last one began."""
    yield
    if not hasattr(os, "sched_getscheduler"):
        return
    for task in os.listdir("/proc/self/task"):
        try:
            if os.sched_getscheduler(int(task)) in (os.SCHED_FIFO, os.SCHED_RR):
                os.sched_setscheduler(int(task), os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass
