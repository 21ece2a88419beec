"""The URDF as nested frames (so101/web/urdf_scene.py) against PyBullet's own forward kinematics."""

from __future__ import annotations

import logging
import math
import time

import numpy as np
import pybullet
import pytest

from so101.assets import urdf_path
from so101.bodies.looks import varied_looks
from so101.bodies.physics import draw_physics
from so101.robot import ACTUATED_JOINTS
from so101.runtime.cluster import free_port
from so101.web.urdf_scene import axis_angle, load_urdf_scene, multiply, rotate, rpy
from so101.web.settings import page_address
from so101.web.view import LOOKS_LIGHT_INTENSITY, WebView, angles_markdown, layout_look, recording_html, rgb255

pytestmark = pytest.mark.slow


def test_quaternions_by_hand():
    quarter = axis_angle((0, 0, 1), math.pi / 2)
    assert rotate(quarter, (1.0, 0.0, 0.0)) == pytest.approx((0.0, 1.0, 0.0))
    # URDF's rpy: roll about x first, then yaw about the parent's z.
    assert rotate(rpy(math.pi / 2, 0, math.pi / 2), (0.0, 1.0, 0.0)) == pytest.approx((0.0, 0.0, 1.0))
    assert multiply(quarter, quarter) == pytest.approx(axis_angle((0, 0, 1), math.pi))


@pytest.fixture(scope="module")
def arm():
    client = pybullet.connect(pybullet.DIRECT)
    robot = pybullet.loadURDF(str(urdf_path()), useFixedBase=True, physicsClientId=client)
    yield client, robot
    pybullet.disconnect(client)


@pytest.mark.parametrize("seed", range(5))
def test_every_link_frame_matches_pybullets(arm, seed):
    client, robot = arm
    scene = load_urdf_scene(urdf_path())
    rng = np.random.default_rng(seed)
    angles = {joint.name: float(rng.uniform(joint.lower_deg, joint.upper_deg)) for joint in ACTUATED_JOINTS}
    for joint in ACTUATED_JOINTS:
        pybullet.resetJointState(robot, joint.index, math.radians(angles[joint.name]), physicsClientId=client)
    poses = scene.link_poses({name: math.radians(angle) for name, angle in angles.items()})
    for index in range(pybullet.getNumJoints(robot, physicsClientId=client)):
        link = pybullet.getJointInfo(robot, index, physicsClientId=client)[12].decode()
        state = pybullet.getLinkState(robot, index, computeForwardKinematics=True, physicsClientId=client)
        position, (x, y, z, w) = state[4], state[5]
        ours_position, ours_rotation = poses[link]
        assert ours_position == pytest.approx(position, abs=1e-6), link
        same = np.isclose(ours_rotation, (w, x, y, z), atol=1e-6).all() or np.isclose(ours_rotation, (-w, -x, -y, -z), atol=1e-6).all()
        assert same, (link, ours_rotation, (w, x, y, z))


def test_the_scene_has_every_visual_mesh_and_names_frames_by_joint():
    scene = load_urdf_scene(urdf_path())
    assert len(scene.visuals) == 17 and all(visual.mesh_file.is_file() for visual in scene.visuals)
    assert scene.link_path("gripper_link") == "/arm/base_link/shoulder_pan/shoulder_lift/elbow_flex/wrist_flex/wrist_roll"


def test_the_angle_text_names_every_joint_to_a_tenth_of_a_degree():
    text = angles_markdown([90.04, -12.35, 0.0, 3.0, -0.04, 45.5])
    assert text.splitlines()[2:] == ["shoulder_pan: 90.0°  ", "shoulder_lift: -12.3°  ", "elbow_flex: 0.0°  ",
                                     "wrist_flex: 3.0°  ", "wrist_roll: 0.0°  ", "gripper: 45.5°"]


def test_the_recording_marker_names_the_episode_and_escapes_the_task():
    assert recording_html(None) == ""
    marker = recording_html((3, "put <the> cube & go"))
    assert "● recording episode 3: put &lt;the&gt; cube &amp; go" in marker
    assert recording_html((0, "")).endswith("● recording episode 0</div>")


@pytest.mark.parametrize("host, address", [
    ("127.0.0.1", "http://127.0.0.1:8101/"), ("0.0.0.0", "http://127.0.0.1:8101/"), ("::", "http://127.0.0.1:8101/"),
    ("192.168.1.20", "http://192.168.1.20:8101/"), ("fe80::1", "http://[fe80::1]:8101/"),
])
def test_the_printed_address_is_one_to_open(host, address):
    assert page_address(host, 8101) == address


def test_a_connection_closed_before_its_request_is_no_error(caplog):
    # A browser's speculative connection, or a port scan: websockets would log each with a traceback.
    import socket

    port = free_port()
    view = WebView(load_urdf_scene(urdf_path(None)), "127.0.0.1", port)
    try:
        for _ in range(3):
            socket.create_connection(("127.0.0.1", port)).close()
        time.sleep(1)
        view.show([10.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    finally:
        view.close()
        view.close()  # safe twice
    errors = [record for record in caplog.records if record.levelno >= logging.ERROR]
    assert errors == [], [record.getMessage() for record in errors]


def test_a_tasks_cube_and_box_are_drawn_where_object_state_puts_them():
    import socket

    from so101.tasks import CUBE_TO_BOX

    with socket.socket() as probe:  # a free port
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    view = WebView(load_urdf_scene(urdf_path(None)), "127.0.0.1", port)
    try:
        view.show_objects([0.2, -0.1, 0.0125, 0, 0, 0, 1, 0.16, 0.19, 0])  # no task added: nothing to pose
        view.add_task(CUBE_TO_BOX)
        assert not view._cube.visible and not view._box.visible  # until an object_state poses them
        yaw = np.radians(30)
        state = [0.2, -0.1, 0.0125, 0, 0, np.sin(yaw / 2), np.cos(yaw / 2), 0.16, 0.19, 0]
        view.show_objects(state)
        assert view._cube.visible and view._box.visible
        assert np.allclose(view._cube.position, state[0:3]) and np.allclose(view._cube.wxyz, [state[6], 0, 0, state[5]])
        assert np.allclose(view._box.position, state[7:10])
        view.show_objects([0.2001, *state[1:]])  # a tenth of a millimetre: not sent again
        assert np.allclose(view._cube.position, state[0:3])
        view.show_objects([0.25, *state[1:]])
        assert np.allclose(view._cube.position, [0.25, -0.1, 0.0125])
        # Each layout as its pictures draw it: seed 7's colours, floor, light and cube size, then fixed again.
        looks, physics = varied_looks(7), draw_physics(7)
        view.show_layout(layout_look(CUBE_TO_BOX, looks, physics))
        assert view._cube.dimensions == pytest.approx((physics.cube_size_m,) * 3) and physics.cube_size_m != 0.025
        assert view._cube.color == rgb255(looks.object_rgbas[0]) != rgb255(CUBE_TO_BOX.cube.rgba)
        assert all(plate.color == rgb255(looks.object_rgbas[1]) for plate in view._plates) and len(view._plates) == 5
        assert view._ground.plane_color == rgb255(looks.floor_rgba) and view._ground.plane_opacity == 1.0
        # The light stands against its direction, as bright as the page's own at the looks' middle strength.
        assert np.allclose(np.negative(view._light.position) / 2.0, looks.light_dir) and view._light.visible
        assert view._light.intensity == pytest.approx(LOOKS_LIGHT_INTENSITY * looks.light_diffuse)
        view.show_layout(layout_look(CUBE_TO_BOX, None, None))
        assert view._cube.dimensions == pytest.approx((0.025,) * 3) and view._cube.color == rgb255(CUBE_TO_BOX.cube.rgba)
        assert view._ground.plane_opacity == 0.0 and not view._light.visible
    finally:
        view.close()
