"""Frames a user can name: shared names, frame types and ids, the frame list, locked joints."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

#: a joint named like a link ("elbow"), as 28 of 1,000 random URDFs have it
SHARED_NAME = """<robot name="shared">
  <link name="base"/><link name="elbow"/><link name="tip"/>
  <joint name="elbow" type="revolute"><parent link="base"/><child link="elbow"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="2"/></joint>
  <joint name="wrist" type="revolute"><parent link="elbow"/><child link="tip"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="2"/></joint>
</robot>"""


@pytest.fixture(scope="module")
def z1() -> sjt.Robot:
    return sjt.Robot.from_example("z1")


def test_a_name_two_frames_share_picks_the_link(z1):
    # Z1's "gripperStator" is both a fixed joint and a link: Pinocchio refuses the name
    model = z1.model
    shared = [i for i, f in enumerate(model.frames) if f.name == "gripperStator"]
    assert len(shared) == 2
    with pytest.raises(ValueError, match="Several frames match"):
        model.getFrameId("gripperStator")
    fid = z1.frame_id("gripperStator")
    assert model.frames[fid].type == pin.FrameType.BODY
    fixed = z1.frame_id("gripperStator", frame_type="FIXED_JOINT")
    assert fixed != fid and model.frames[fixed].type == pin.FrameType.FIXED_JOINT
    assert z1.frame_id("gripperStator", pin.FrameType.FIXED_JOINT) == fixed
    assert z1.frame_id(fixed) == fixed  # a frame id is taken as it is
    robot = sjt.Robot.from_example("z1", ee_frame="gripperStator", frame_type="FIXED_JOINT")
    assert robot.ee_frame_id == fixed and robot.ee_frame == "gripperStator"
    by_id = sjt.Robot.from_example("z1", ee_frame=fixed)
    assert by_id.ee_frame_id == fixed
    with pytest.raises(sjt.FrameNotFound, match="of type JOINT not found.*FIXED_JOINT"):
        z1.frame_id("gripperStator", frame_type="JOINT")
    with pytest.raises(ValueError, match="frame_type must be"):
        z1.frame_id("gripperStator", frame_type="LINK")
    with pytest.raises(TypeError, match="frame id"):
        z1.frame_id(1.5)
    with pytest.raises(sjt.FrameNotFound, match="frame id 99 is outside"):
        z1.frame_id(99)


def test_shared_names_work_everywhere_a_frame_is_named(z1):
    q = z1.q0 + 0.1
    pose = z1.fk(q, frame="gripperStator")  # no raw Pinocchio error
    assert isinstance(pose, pin.SE3)
    assert z1.jacobian(q, frame="gripperStator").shape == (6, z1.nv)
    solver = sjt.SJTSolver(z1, task=sjt.PoseTask(frame="gripperStator"))
    result = solver.solve(pose, z1.q0, timeout=None)
    assert result.success
    np.testing.assert_allclose(z1.fk(result.q, "gripperStator").homogeneous, pose.homogeneous,
                               atol=1e-5)


def test_a_random_urdf_with_a_joint_named_like_a_link():
    robot = sjt.Robot.from_urdf(SHARED_NAME, ee_frame="elbow")
    assert robot.model.frames[robot.ee_frame_id].type == pin.FrameType.BODY
    joint = sjt.Robot.from_urdf(SHARED_NAME, ee_frame="elbow", frame_type="JOINT")
    assert joint.model.frames[joint.ee_frame_id].type == pin.FrameType.JOINT
    q = np.array([0.3, -0.4])
    # the link "elbow" and the joint "elbow" sit at the same place here
    np.testing.assert_allclose(robot.fk(q).homogeneous, joint.fk(q).homogeneous, atol=1e-12)
    solver = sjt.SJTSolver(robot, task=sjt.PositionTask(frame="elbow"))
    assert solver.step(q, [0.0, 0.0, 0.3]).shape == (2,)


def test_frames_lists_name_type_and_parent_joint(z1):
    frames = z1.frames()
    assert len(frames) == len(z1.model.frames)
    for info, frame in zip(frames, z1.model.frames, strict=True):
        assert info.name == frame.name
        assert info.type == str(frame.type).rsplit(".", 1)[-1]
        assert info.parent_joint == z1.model.names[frame.parentJoint]
        assert z1.model.frames[info.id].name == info.name
    assert ("gripperStator", "BODY", "joint6") in {(f.name, f.type, f.parent_joint)
                                                   for f in frames}


def test_frame_not_found_suggests_from_all_frames(z1):
    with pytest.raises(sjt.FrameNotFound) as caught:
        z1.frame_id("tool")
    message = str(caught.value)
    # before: only "close names: ['world']"; now every frame, and where to find more
    assert "gripperStator" in message and "link06" in message and "frames()" in message
    with pytest.raises(sjt.FrameNotFound, match=r"close names: \['gripperStator'"):
        z1.frame_id("gripperstator")
    with pytest.raises(sjt.FrameNotFound, match=r"close names: \['link06'"):
        z1.frame_id("link_06")


def test_z1_default_end_effector_is_rigid_and_the_gripper_is_locked(z1):
    # before: gripperMover, the moving jaw, so the gripper joint was an IK degree of freedom
    assert z1.ee_frame == "gripperStator"
    assert z1.model.frames[z1.ee_frame_id].type == pin.FrameType.BODY
    assert z1.locked_joints == ["jointGripper"]
    assert "jointGripper" not in z1.velocity_names and (z1.nq, z1.nv) == (6, 6)
    full = sjt.Robot.from_example("z1", locked_joints=())
    assert "jointGripper" in full.velocity_names and full.nv == 7
    # the same arm: the arm joints give the same tool pose in both models
    q = np.array([0.2, 0.5, -0.7, 0.1, 0.3, -0.2])
    q_full = np.append(q, full.q0[-1])
    np.testing.assert_allclose(z1.fk(q).homogeneous,
                               full.fk(q_full, "gripperStator").homogeneous, atol=1e-12)


def test_talos_grippers_are_locked_by_default():
    talos = sjt.Robot.from_example("talos_arm")
    assert talos.locked_joints == ["gripper_left_joint"] and talos.nv == 6
    assert talos.ee_frame == "gripper_left_joint"  # now a fixed joint's frame
    assert talos.model.frames[talos.ee_frame_id].type == pin.FrameType.FIXED_JOINT


def test_reduced_locks_joints_at_a_configuration(panda):
    fingers = ["panda_finger_joint1", "panda_finger_joint2"]
    arm = panda.reduced(fingers)
    assert (arm.nq, arm.nv) == (7, 7) and arm.locked_joints == fingers
    assert arm.ee_frame == "panda_hand"
    np.testing.assert_allclose(arm.q0, panda.q0[:7])
    assert len(arm.visual_model.geometryObjects) == len(panda.visual_model.geometryObjects)
    q = panda.q0.copy()
    q[:7] += 0.1
    np.testing.assert_allclose(arm.fk(q[:7]).homogeneous, panda.fk(q).homogeneous, atol=1e-12)
    # fingers locked open at 3 cm: their frames follow that value
    opened = panda.q0.copy()
    opened[7:] = 0.03
    wide = panda.reduced(fingers, q=opened)
    np.testing.assert_allclose(wide.fk(q[:7], "panda_leftfinger").homogeneous,
                               panda.fk(np.append(q[:7], [0.03]),
                                        "panda_leftfinger").homogeneous, atol=1e-12)
    assert sjt.SJTSolver(arm).step(arm.q0, arm.fk(arm.q0)).shape == (7,)
    with pytest.raises(ValueError, match=r"no joint 'panda_finger_joint3'.*close names"):
        panda.reduced(["panda_finger_joint3"])
    with pytest.raises(TypeError, match="locked_joints must be joint names"):
        panda.reduced([3])
    urdf = sjt.Robot.from_urdf(SHARED_NAME, ee_frame="tip", locked_joints=["wrist"])
    assert urdf.nv == 1 and urdf.velocity_names == ["elbow"]
    # (Pinocchio's buildReducedModel finds frames by name: a joint named as its link cannot
    # be locked, and says why)
    with pytest.raises(sjt.URDFError, match=r"a joint and a link share a name \(\['elbow'\]\)"):
        sjt.Robot.from_urdf(SHARED_NAME, ee_frame="tip", locked_joints=["elbow"])
