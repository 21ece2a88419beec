"""MuJoCo's scene collides hulls and, without pictures, leaves the visual meshes out (issue 23).

The reference is the MJCF compiled as written (its full meshes in the collisions), on the
same floor, stepped by MuJoCo's own calls; the node's body must follow it at every step
through the course's motions and through contacts: bit for bit until the first contact,
within HULL_TOLERANCE_DEG after it (the hull's frame moves, so its vertices round apart).
"""

from __future__ import annotations

import numpy as np
import pytest

from so101 import assets
from so101.bodies import mujoco_model
from so101.bodies.mujoco_model import HULL_TOLERANCE_DEG, HULLS_NAME, collision_hulls, hulls_key, save_hulls, scene_model
from so101.bodies.mujoco_sim import SO101MuJoCo
from so101.robot import ACTUATED_JOINTS
from tests.helpers.course_motion import SCENARIOS, STEPS_PER_COMMAND

# MuJoCo as so101 imports it: imported here first, without the OpenGL back end mujoco_model
# chooses, it could not draw offscreen for the tests that come after (an abort, in the suite).
mujoco = mujoco_model.mujoco

pytestmark = pytest.mark.slow  # steps MuJoCo through the course's motions: not in the fast subset

FLOOR_CONTACT = ("world", "gripper")
SELF_CONTACT = ("shoulder", "gripper")
# Motion -> (commands, a pair of bodies that must touch in it): the course's motions, where
# shoulder_lift or elbow_flex at 90° already puts the gripper on the floor, and two more.
MOTIONS = {
    **{name: (commands, None) for name, commands in SCENARIOS.items()},
    "gripper pressed on the floor, then swept along it": ([[0.0, 90.0, 0.0, 0.0, 0.0, 30.0], [60.0, 90.0, 0.0, 0.0, 0.0, 30.0]], FLOOR_CONTACT),
    "folded: the gripper against the shoulder, then home": ([[0.0, -100.0, 90.0, 100.0, 0.0, 0.0], [0.0] * 6], SELF_CONTACT),
}


def quiet(message: str) -> None:
    pass


def contact_bodies(model, data) -> list[tuple[str, str]]:
    """The pairs of bodies in contact, by name, sorted."""
    return sorted(
        (model.body(model.geom_bodyid[contact.geom1]).name, model.body(model.geom_bodyid[contact.geom2]).name)
        for contact in data.contact[:data.ncon]
    )


class AsWritten:
    """The MJCF compiled as written on the floor (the scene before issue 23), stepped as SO101MuJoCo steps."""

    def __init__(self, substeps: int):
        self.model = scene_model(assets.mjcf_path(), hulls=None)
        self.data = mujoco.MjData(self.model)
        self.substeps = substeps
        self._qpos = [int(self.model.joint(joint.name).qposadr[0]) for joint in ACTUATED_JOINTS]
        self._actuators = [int(self.model.actuator(joint.name).id) for joint in ACTUATED_JOINTS]

    def tick(self, targets_deg) -> np.ndarray:
        self.data.ctrl[self._actuators] = np.radians(targets_deg)
        mujoco.mj_step(self.model, self.data, nstep=self.substeps)
        return np.degrees(self.data.qpos[self._qpos])


@pytest.mark.parametrize("commands, touching", MOTIONS.values(), ids=MOTIONS.keys())
def test_the_node_body_moves_as_the_mjcf_compiled_as_written(commands, touching):
    with SO101MuJoCo(mode="direct", renders=False, log=quiet) as sim:
        reference = AsWritten(sim.substeps)
        contact_steps = {}
        worst_deg = moved_deg = 0.0
        for targets_deg in commands:
            sim.set_targets_deg(targets_deg)
            for step in range(STEPS_PER_COMMAND):
                expected = reference.tick(targets_deg)
                sim.step()
                error_deg = float(np.max(np.abs(sim.joint_angles_deg() - expected)))
                touches = contact_bodies(sim.model, sim.data)
                assert touches == contact_bodies(reference.model, reference.data), f"{targets_deg} step {step}"
                for pair in set(touches):
                    contact_steps[pair] = contact_steps.get(pair, 0) + 1
                if not contact_steps:  # the hulls enter only collisions
                    assert error_deg == 0.0, f"{targets_deg} step {step}, before any contact"
                assert error_deg <= HULL_TOLERANCE_DEG, f"{targets_deg} step {step}: {error_deg}° off"
                worst_deg = max(worst_deg, error_deg)
                moved_deg = max(moved_deg, float(np.max(np.abs(expected))))
    assert moved_deg > 40  # a real move, not an arm at rest
    if touching is not None:
        assert contact_steps.get(touching, 0) > 20, contact_steps  # the comparison went through this contact
        assert worst_deg > 0.0  # and the contact is where the two models differ: the test can tell them apart


def test_leaving_out_the_visual_meshes_changes_no_physics():
    commands, _ = MOTIONS["folded: the gripper against the shoulder, then home"]
    with SO101MuJoCo(mode="direct", renders=True, log=quiet) as drawn, \
            SO101MuJoCo(mode="direct", renders=False, log=quiet) as stepped:
        for targets_deg in commands:
            drawn.set_targets_deg(targets_deg)
            stepped.set_targets_deg(targets_deg)
            for step in range(STEPS_PER_COMMAND):
                drawn.step()
                stepped.step()
                assert np.array_equal(drawn.data.qpos, stepped.data.qpos), f"{targets_deg} step {step}"
                assert np.array_equal(drawn.data.qvel, stepped.data.qvel), f"{targets_deg} step {step}"
        # What the node without pictures holds: the 10 collision hulls, no full-resolution mesh.
        hulls = collision_hulls(assets.mjcf_path())
        assert stepped.model.nmesh == len(hulls) == 10
        assert stepped.model.nmeshvert == sum(len(vertices) for vertices, _ in hulls.values()) < 30_000
        assert drawn.model.nmeshvert > 180_000  # the 13 meshes at full resolution, and the hulls


def test_each_collision_mesh_is_its_own_hull():
    # MuJoCo, taking a hull as a mesh, keeps every vertex on its hull: nothing of the full mesh is left.
    model = scene_model(assets.mjcf_path(), collision_hulls(assets.mjcf_path()), visual=False)
    for mesh in range(model.nmesh):
        hull_vertex_count = int(model.mesh_graph[model.mesh_graphadr[mesh]])
        assert hull_vertex_count == model.mesh_vertnum[mesh], model.mesh(mesh).name


def write_other_mujocos_hulls(path, monkeypatch):
    monkeypatch.setattr(mujoco, "__version__", "3.3.7")
    save_hulls(path, collision_hulls(assets.mjcf_path()))
    monkeypatch.undo()


STALE_HULLS = {
    "none yet (so101 assets ran before issue 23)": lambda path, monkeypatch: None,
    "from another MuJoCo": write_other_mujocos_hulls,
    "not a hull file": lambda path, monkeypatch: path.write_bytes(b"PK\x03\x04 cut short"),
}


@pytest.mark.parametrize("make", STALE_HULLS.values(), ids=STALE_HULLS.keys())
def test_missing_or_stale_hulls_are_derived_again(model_copy, monkeypatch, make):
    path = model_copy / HULLS_NAME
    make(path, monkeypatch)
    told = []
    with SO101MuJoCo(mode="direct", renders=False, assets_dir=model_copy, log=told.append) as sim:
        sim.set_targets_deg([0.0, 90.0, 0.0, 0.0, 0.0, 0.0])
        sim.step(100)
        assert sim.joint_angles_deg()[1] > 40
    assert told == [f"MuJoCo collision hulls derived from the MJCF's meshes for mujoco {mujoco.__version__}: {path}"]
    with np.load(path) as saved:
        assert str(saved["key"]) == hulls_key()
        assert str(saved["key"]).startswith(f"mujoco {mujoco.__version__}; model ")


def test_current_hulls_are_read_not_derived(model_copy, monkeypatch):
    save_hulls(model_copy / HULLS_NAME, collision_hulls(assets.mjcf_path()))

    def derive(mjcf):
        raise AssertionError("derived again")

    monkeypatch.setattr(mujoco_model, "derive_hulls", derive)
    told = []
    with SO101MuJoCo(mode="direct", renders=False, assets_dir=model_copy, log=told.append) as sim:
        assert sim.model.nmesh == 10
    assert told == []


def test_hulls_that_cannot_be_saved_are_used_and_said_so(model_copy, monkeypatch):
    def refuse(path, hulls):
        raise PermissionError(f"[Errno 13] Permission denied: '{path}'")

    monkeypatch.setattr(mujoco_model, "save_hulls", refuse)
    told = []
    with SO101MuJoCo(mode="direct", renders=False, assets_dir=model_copy, log=told.append) as sim:
        assert sim.model.nmesh == 10
    assert told == [
        "MuJoCo collision hulls derived from the MJCF's meshes, not saved "
        f"([Errno 13] Permission denied: '{model_copy / HULLS_NAME}'): derived again on each start"
    ]
    assert not (model_copy / HULLS_NAME).exists()


def test_so101_assets_derives_the_hulls(model_copy, capsys):
    from so101.cli.main import main

    assert main(["assets", "--dir", str(model_copy)]) == 0
    with np.load(model_copy / HULLS_NAME) as saved:
        assert str(saved["key"]) == hulls_key()
    assert f"collision hulls derived from the MJCF's meshes for mujoco {mujoco.__version__}" in capsys.readouterr().out
