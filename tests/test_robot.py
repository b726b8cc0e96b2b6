from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.robot import DEFAULT_EE_FRAMES

FIXTURES = Path(__file__).parent / "fixtures" / "urdf"

CONTINUOUS_PRISMATIC = """<robot name="mixed">
  <link name="base"/><link name="a"/><link name="b"/><link name="tip"/><link name="side"/>
  <joint name="spin" type="continuous"><parent link="base"/><child link="a"/>
    <axis xyz="0 0 1"/></joint>
  <joint name="slide" type="prismatic"><parent link="a"/><child link="b"/>
    <origin xyz="0.5 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.1" upper="0.2" effort="1" velocity="0.5"/></joint>
  <joint name="tip_fixed" type="fixed"><parent link="b"/><child link="tip"/>
    <origin xyz="0.1 0 0.2"/></joint>
  <joint name="side_joint" type="revolute"><parent link="a"/><child link="side"/>
    <origin xyz="0 0.3 0"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def manifold_fd_jacobian(robot, q, h=1e-6):
    """LOCAL Jacobian by central differences on the manifold: log6(oMf(q)^-1 oMf(q + h e_i))."""
    pose = robot.fk(q)
    J = np.empty((6, robot.nv))
    for i in range(robot.nv):
        dv = np.zeros(robot.nv)
        dv[i] = h
        plus = robot.fk(pin.integrate(robot.model, q, dv))
        minus = robot.fk(pin.integrate(robot.model, q, -dv))
        J[:, i] = (pin.log6(pose.actInv(plus)) - pin.log6(pose.actInv(minus))).vector / (2 * h)
    return J


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_jacobian_matches_finite_differences(name, rng):
    robot = sjt.Robot.from_example(name)
    for _ in range(5):
        q = robot.random_configuration(rng)
        np.testing.assert_allclose(robot.jacobian(q), manifold_fd_jacobian(robot, q), atol=1e-6)


def test_example_defaults(ur5, panda):
    assert ur5.ee_frame == "tool0" and (ur5.nq, ur5.nv) == (6, 6)
    assert panda.ee_frame == "panda_hand" and (panda.nq, panda.nv) == (8, 8)  # finger 2 mimics 1
    assert panda.jacobian(panda.q0).shape == (6, 8)
    assert isinstance(panda.fk(panda.q0), pin.SE3)
    # Panda's URDF limits: joint 4 in [-3.0718, -0.0698], fingers prismatic in [0, 0.04]
    assert panda.upper_limits[3] == pytest.approx(-0.0698)
    assert panda.upper_limits[7] == pytest.approx(0.04)
    assert panda.velocity_limits[0] == pytest.approx(2.175)
    assert np.all((panda.q0 >= panda.lower_limits) & (panda.q0 <= panda.upper_limits))


def test_explicit_ee_frame_and_other_frames(panda):
    robot = sjt.Robot.from_example("panda", ee_frame="panda_link7")
    assert robot.ee_frame == "panda_link7"
    np.testing.assert_allclose(
        robot.fk(panda.q0).homogeneous, panda.fk(panda.q0, frame="panda_link7").homogeneous
    )


def test_urdf_with_continuous_prismatic_fixed_and_branch(tmp_path):
    path = tmp_path / "mixed.urdf"
    path.write_text(CONTINUOUS_PRISMATIC)
    for source in (path, str(path), CONTINUOUS_PRISMATIC):
        robot = sjt.Robot.from_urdf(source, ee_frame="tip")
        assert (robot.nq, robot.nv) == (4, 3)  # continuous joint: cos/sin
        q = pin.neutral(robot.model)
        assert robot.fk(q).translation == pytest.approx([0.6, 0.0, 0.2])
        J = robot.jacobian(q)
        assert J.shape == (6, 3)
        np.testing.assert_allclose(J, manifold_fd_jacobian(robot, q), atol=1e-6)
        model = robot.model
        names = ("spin", "slide", "side_joint")
        iv = {name: model.idx_vs[model.getJointId(name)] for name in names}
        iq = {name: model.idx_qs[model.getJointId(name)] for name in names}
        assert np.all(J[:, iv["side_joint"]] == 0)  # the side branch does not move the tip
        assert np.isinf(robot.upper_limits[iq["spin"]])
        assert robot.upper_limits[iq["slide"]] == pytest.approx(0.2)
        assert robot.velocity_limits[iv["slide"]] == pytest.approx(0.5)
        assert np.isinf(robot.velocity_limits[iv["spin"]])


def test_default_ee_frame_is_the_only_leaf():
    with pytest.raises(ValueError, match=r"several leaf links \['side', 'tip'\]"):
        sjt.Robot.from_urdf(CONTINUOUS_PRISMATIC)
    single = CONTINUOUS_PRISMATIC.split('<joint name="side_joint"')[0] + "</robot>"
    assert sjt.Robot.from_urdf(single.replace('<link name="side"/>', "")).ee_frame == "tip"


def test_random_configuration_respects_limits(panda, rng):
    for _ in range(100):
        q = panda.random_configuration(rng)
        assert np.all((q >= panda.lower_limits) & (q <= panda.upper_limits))


def test_robot_without_moving_joints_loads():
    robot = sjt.Robot.from_urdf(FIXTURES / "fixed_only.urdf")
    assert robot.ee_frame == "tool"  # the fixed joint's child, the only leaf
    assert (robot.nq, robot.nv) == (0, 0)
    q = np.zeros(0)
    assert robot.jacobian(q).shape == (6, 0)
    assert robot.fk(q).translation == pytest.approx([0.0, 0.0, 0.5])
    assert robot.velocity_names == [] and robot.lower_limits.shape == (0,)


def test_robot_with_one_joint_loads():
    robot = sjt.Robot.from_urdf(FIXTURES / "one_joint.urdf")
    assert robot.ee_frame == "tip" and (robot.nq, robot.nv) == (1, 1)
    q = np.array([np.pi / 2])
    assert robot.fk(q).translation == pytest.approx([0.0, 0.5, 0.0])
    J = robot.jacobian(q)
    assert J.shape == (6, 1)
    np.testing.assert_allclose(J, manifold_fd_jacobian(robot, q), atol=1e-6)
    assert robot.velocity_names == ["shoulder"]
    assert (robot.lower_limits[0], robot.upper_limits[0]) == (-2.0, 2.0)


@pytest.mark.parametrize("name", sorted(DEFAULT_EE_FRAMES))
@pytest.mark.filterwarnings("ignore:.*q0 is clipped into range:UserWarning")  # kinova, panda
def test_every_default_ee_frame_exists(name):
    robot = sjt.Robot.from_example(name)
    assert robot.ee_frame == DEFAULT_EE_FRAMES[name]
    assert robot.jacobian(robot.q0).shape == (6, robot.nv)


def test_the_ur3_example_is_a_ur3():
    """example-robot-data 5.0 registers "ur3" to UR5's loader: the robot asked for is a UR3
    (its own URDF, its reach at q = 0 about 0.46 m against UR5's 0.82 m), not a UR5."""
    ur3 = sjt.Robot.from_example("ur3")
    assert ur3.model.name == "ur3"
    assert abs(ur3.fk(np.zeros(6)).translation[0] - 0.4569) < 1e-3
    assert abs(sjt.Robot.from_example("ur3_gripper").fk(np.zeros(6)).translation[0]
               - 0.4569) < 1e-3  # (the same arm)


@pytest.mark.parametrize("name, hint", [("UR5", "did you mean 'ur5'"),
                                        ("pandas", "did you mean 'panda'"),
                                        ("talos-full", "did you mean 'talos_full'")])
def test_unknown_example_name_suggests_close_names(name, hint):
    with pytest.raises(ValueError, match=f"name {name!r} is not an example-robot-data robot; "
                                         f"{hint}.*known: \\['a1'"):
        sjt.Robot.from_example(name)
    with pytest.raises(TypeError, match="name must be a str"):
        sjt.Robot.from_example(["ur5"])
