"""Mimic joints are Pinocchio mimic joints: no coordinate of their own, their relation kept
exactly by fk, the Jacobians, step(), solve() and the viewer's meshes, their limits kept through
the relation. Before, ``<mimic>`` was ignored and the solver moved such joints freely (the
relation broken by up to 17.8 rad or m)."""

import copy
import pickle
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.viewer.viewer import _Rig

GRIPPER = Path(__file__).parent / "fixtures" / "mimic" / "gripper.urdf"
#: the relations written in gripper.urdf (tool_roll's composed through tool_tilt)
RELATIONS = {"right_finger": ("left_finger", -1.0, 0.0), "tool_tilt": ("wrist", 0.5, 0.1),
             "tool_roll": ("wrist", 1.0, 0.15)}


@pytest.fixture(scope="module")
def gripper() -> sjt.Robot:
    return sjt.Robot.from_urdf(GRIPPER, ee_frame="tcp")


@pytest.fixture(scope="module")
def free_model() -> pin.Model:
    """The same URDF with every joint a coordinate of its own (Pinocchio without mimic)."""
    return pin.buildModelFromUrdf(str(GRIPPER))


def full_q(robot: sjt.Robot, free: pin.Model, q: np.ndarray) -> np.ndarray:
    """``q`` of the mimic robot as a configuration of ``free``, from URDF's relations."""
    values = robot.joint_values(q)
    out = np.zeros(free.nq)
    for j in range(1, free.njoints):
        out[free.joints[j].idx_q] = values[free.names[j]]
    return out


def relation_error(robot, free, q) -> float:
    """Largest difference (m) between the frames of the mimic robot at ``q`` and those of the
    free model with every mimic joint set by its relation."""
    d1, d2 = robot.model.createData(), free.createData()
    pin.framesForwardKinematics(robot.model, d1, q)
    pin.framesForwardKinematics(free, d2, full_q(robot, free, q))
    return max(float(np.max(np.abs(a.homogeneous - b.homogeneous)))
               for a, b in zip(d1.oMf, d2.oMf, strict=True))


def test_mimic_joints_have_no_coordinate(gripper):
    assert (gripper.nq, gripper.nv) == (4, 4)
    assert gripper.velocity_names == ["shoulder", "elbow", "wrist", "left_finger"]
    relations = {m.joint: (m.mimicked, m.multiplier, m.offset) for m in gripper.mimic_joints}
    assert relations.keys() == RELATIONS.keys()
    for name, (mimicked, k, o) in RELATIONS.items():
        assert relations[name][:2] == (mimicked, k) and relations[name][2] == pytest.approx(o)


def test_mimic_limits_narrow_the_followed_joint(gripper):
    # tool_tilt = 0.5 wrist + 0.1 in [-0.2, 0.4] -> wrist in [-0.6, 0.6]; speed 0.25 / 0.5
    assert gripper.lower_limits[2] == pytest.approx(-0.6)
    assert gripper.upper_limits[2] == pytest.approx(0.6)
    assert gripper.velocity_limits[2] == pytest.approx(0.5)
    assert gripper.lower_limits[3] == 0.0 and gripper.upper_limits[3] == pytest.approx(0.04)


def test_jacobian_is_the_derivative_in_the_independent_coordinates(gripper):
    q = np.array([0.3, -0.4, 0.2, 0.01])
    J = gripper.jacobian(q, reference=pin.LOCAL)
    h = 1e-7
    for i in range(gripper.nv):
        dq = np.zeros(gripper.nv)
        dq[i] = h
        fd = pin.log6(gripper.fk(q).actInv(gripper.fk(pin.integrate(gripper.model, q, dq))))
        assert np.allclose(fd.vector / h, J[:, i], atol=1e-6), i


def test_step_and_solve_keep_the_relations_and_limits(gripper, free_model, rng):
    solver = sjt.SJTSolver(gripper, dt=1e-2)
    q = np.array([0.3, 0.3, 0.1, 0.02])
    for _ in range(5):
        goal = gripper.random_configuration(rng)
        target = gripper.fk(goal)
        for _ in range(300):
            q_next = solver.step(q, target)
            assert relation_error(gripper, free_model, q_next) < 1e-9
            speed = np.abs(solver.last.dq)
            assert np.all(speed <= gripper.velocity_limits * (1 + 1e-9))
            q = q_next
            assert np.all(q >= gripper.lower_limits) and np.all(q <= gripper.upper_limits)
        values = gripper.joint_values(q)
        assert -0.2 - 1e-12 <= values["tool_tilt"] <= 0.4 + 1e-12
        result = solver.solve(target, gripper.q0)
        assert result.success, result
        assert relation_error(gripper, free_model, result.q) < 1e-9
        assert np.all(result.q >= gripper.lower_limits)
        assert np.all(result.q <= gripper.upper_limits)


def test_a_target_that_needs_a_mimic_joint_beyond_its_limits_is_not_reached(gripper):
    # the wrist alone could reach this pose at 1.2 rad; tool_tilt's limit stops it at 0.6
    q_far = np.array([0.0, 0.0, 1.2, 0.0])
    free = pin.buildModelFromUrdf(str(GRIPPER))
    data = free.createData()
    pin.framesForwardKinematics(free, data, full_q(gripper, free, q_far))
    target = data.oMf[free.getFrameId("tcp")]
    solver = sjt.SJTSolver(gripper, dt=1e-2)
    q = np.zeros(4)
    for _ in range(400):
        q = solver.step(q, target)
    assert q[2] == pytest.approx(0.6, abs=1e-9)
    assert gripper.joint_values(q)["tool_tilt"] == pytest.approx(0.4, abs=1e-9)


def test_the_viewer_draws_the_mimic_joints_by_their_relation(gripper, free_model):
    q = np.array([0.5, -0.3, 0.4, 0.03])
    free_visuals = pin.buildGeomFromUrdf(free_model, str(GRIPPER), pin.VISUAL)
    data, gdata = free_model.createData(), pin.GeometryData(free_visuals)
    pin.forwardKinematics(free_model, data, full_q(gripper, free_model, q))
    pin.updateGeometryPlacements(free_model, data, free_visuals, gdata)
    expected = {g.name: gdata.oMg[i].homogeneous for i, g in
                enumerate(free_visuals.geometryObjects)}
    drawn = _DrawnRig(gripper)
    for name, placement in zip(drawn.names, drawn.placements(q), strict=True):
        assert np.allclose(placement, expected[name], atol=1e-12), name


class _DrawnRig(_Rig):
    """The viewer's robot rig without a meshcat scene: the placements it would draw."""

    def __init__(self, robot):  # noqa: D107 - only what placements() reads
        self.robot = robot
        self.geometries = list(range(robot.visual_model.ngeoms))
        self.names = [g.name for g in robot.visual_model.geometryObjects]
        self.data = robot.model.createData()
        self.geometry_data = pin.GeometryData(robot.visual_model)


def test_panda_fingers_move_together():
    panda = sjt.Robot.from_example("panda")
    assert (panda.nq, panda.nv) == (8, 8)
    assert [(m.joint, m.mimicked, m.multiplier, m.offset) for m in panda.mimic_joints] == [
        ("panda_finger_joint2", "panda_finger_joint1", 1.0, 0.0)]
    q = panda.q0.copy()
    q[7] = 0.03
    values = panda.joint_values(q)
    assert values["panda_finger_joint2"] == values["panda_finger_joint1"] == 0.03
    left = panda.fk(q, "panda_leftfinger").translation
    right = panda.fk(q, "panda_rightfinger").translation
    hand = panda.fk(q, "panda_hand")
    assert np.linalg.norm(hand.actInv(left) - hand.actInv(right)) == pytest.approx(0.06)


def _two_joints(mimic: str, first: str = "revolute", second: str = "revolute",
                limits: str = 'lower="-1" upper="1"') -> str:
    return f"""<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
      <joint name="j1" type="{first}"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
        <limit {limits} effort="1" velocity="1"/></joint>
      <joint name="j2" type="{second}"><parent link="b"/><child link="c"/><origin xyz="1 0 0"/>
        <axis xyz="0 0 1"/><limit {limits} effort="1" velocity="1"/>{mimic}</joint></robot>"""


@pytest.mark.parametrize("xml, fragments", [
    (_two_joints('<mimic joint="j2"/>'), ["joint 'j2'", "its own joint"]),
    (_two_joints("<mimic/>"), ["joint 'j2'", 'no joint="..."']),
    (_two_joints('<mimic joint="j1" multiplier="0"/>'), ["multiplier 0", "lower == upper"]),
    (_two_joints('<mimic joint="j1" multiplier="nan"/>'), ["multiplier='nan'", "finite"]),
    (_two_joints('<mimic joint="j1"/>', first="fixed"), ["'j1' is fixed"]),
    (_two_joints('<mimic joint="j1"/>', second="continuous"), ["continuous joint cannot",
                                                               "revolute joint 'j1'"]),
    (_two_joints('<mimic joint="j1"/><mimic joint="j1"/>'), ["appears 2 times"]),
    (_two_joints('<mimic joint="j1" offset="5"/>'), ["'j2' mimics 'j1'", "no value"]),
    (_two_joints('<mimic joint="j1"/>').replace(
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>\n      <joint name="j2"',
        '<limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="j2"/></joint>\n'
        '      <joint name="j2"'), ["'j1' -> 'j2' -> 'j1'", "cycle"]),
])
def test_mimic_relations_pinocchio_cannot_keep_are_refused(xml, fragments):
    with pytest.raises(sjt.URDFError) as error:
        sjt.Robot.from_urdf(xml, ee_frame="c", load_visuals=False)
    for fragment in fragments:
        assert fragment in str(error.value), (fragment, str(error.value))


def test_a_mimic_naming_no_joint_is_passed_over_with_a_warning():
    # example-robot-data's alex_psyonic_hands.urdf names "index_q1" for "Left_index_q1"
    with pytest.warns(UserWarning, match="joint 'j2': <mimic> names joint 'j11'.*'j1'"):
        robot = sjt.Robot.from_urdf(_two_joints('<mimic joint="j11"/>'), ee_frame="c",
                                    load_visuals=False)
    assert robot.nv == 2 and robot.mimic_joints == []


def test_a_mimic_on_a_fixed_joint_leaves_it_fixed():
    # example-robot-data's talos_reduced.urdf: welded gripper joints keep their <mimic>
    robot = sjt.Robot.from_urdf(_two_joints('<mimic joint="j1"/>', second="fixed"),
                                ee_frame="c", load_visuals=False)
    assert robot.nv == 1 and robot.mimic_joints == []


def test_continuous_joints_mimic_continuous_joints():
    robot = sjt.Robot.from_urdf(_two_joints('<mimic joint="j1" multiplier="2" offset="0.3"/>',
                                            "continuous", "continuous"),
                                ee_frame="c", load_visuals=False)
    assert (robot.nq, robot.nv) == (2, 1)
    angle = 0.4
    q = np.array([np.cos(angle), np.sin(angle)])
    assert robot.joint_values(q)["j2"] == pytest.approx(2 * angle + 0.3)
    rotation = robot.fk(q, "c").rotation
    assert np.arctan2(rotation[1, 0], rotation[0, 0]) == pytest.approx(3 * angle + 0.3)


def test_a_mimicking_joint_first_in_the_tree_becomes_the_independent_one():
    # j_a follows j_b, but Pinocchio numbers j_a first: the relation is inverted, j_a is the
    # coordinate and j_b follows it (the same relation)
    xml = """<robot name="r"><link name="root"/><link name="la"/><link name="lb"/>
      <joint name="j_a" type="prismatic"><parent link="root"/><child link="la"/>
        <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
        <mimic joint="j_b" multiplier="2" offset="0.1"/></joint>
      <joint name="j_b" type="prismatic"><parent link="root"/><child link="lb"/>
        <axis xyz="0 1 0"/><limit lower="-0.2" upper="0.2" effort="1" velocity="1"/></joint>
    </robot>"""
    robot = sjt.Robot.from_urdf(xml, ee_frame="lb", load_visuals=False)
    assert robot.velocity_names == ["j_a"]
    (mimic,) = robot.mimic_joints
    assert (mimic.joint, mimic.mimicked) == ("j_b", "j_a")
    # j_b in [-0.2, 0.2] <=> j_a = 2 j_b + 0.1 in [-0.3, 0.5]
    assert robot.lower_limits[0] == pytest.approx(-0.3)
    assert robot.upper_limits[0] == pytest.approx(0.5)
    for q_a in (-0.3, 0.0, 0.5):
        q = np.array([q_a])
        values = robot.joint_values(q)
        assert values["j_a"] == pytest.approx(2 * values["j_b"] + 0.1, abs=1e-12)
        assert robot.fk(q, "lb").translation[1] == pytest.approx(values["j_b"], abs=1e-12)
        assert robot.fk(q, "la").translation[1] == pytest.approx(q_a, abs=1e-12)


def test_copies_of_a_mimic_robot_and_its_solver_are_the_same(gripper):
    # Pinocchio 4.1 unpickles a mimic joint broken (fk then crashes the interpreter): a robot
    # pickles its model without mimic joints and applies the relations anew
    q = np.array([0.3, 0.2, 0.4, 0.01])
    target = gripper.fk(np.array([0.5, 0.4, 0.3, 0.02]))
    for copy_of in (lambda x: pickle.loads(pickle.dumps(x)), copy.deepcopy):
        robot = copy_of(gripper)
        assert robot.mimic_joints == gripper.mimic_joints
        assert np.array_equal(robot.lower_limits, gripper.lower_limits)
        assert np.array_equal(robot.velocity_limits, gripper.velocity_limits)
        assert robot.fk(q) == gripper.fk(q)
        solver = sjt.SJTSolver(gripper)
        twin = copy_of(solver)
        assert np.array_equal(twin.step(q, target), solver.step(q, target))
    panda = sjt.Robot.from_example("panda")
    twin = pickle.loads(pickle.dumps(panda))
    assert twin.nq == 8 and twin.fk(panda.q0) == panda.fk(panda.q0)
    results = sjt.solve_many(sjt.SJTSolver(gripper), [target] * 4, gripper.q0, processes=2,
                             chunk=2, progress=False)
    assert all(r.success for r in results)


def test_a_robot_with_pinocchio_mimic_joints_alone_refuses_to_pickle():
    model = pin.transformJointIntoMimic(pin.buildModelFromUrdf(str(GRIPPER)), 4, 5, -1.0, 0.0)
    with pytest.raises(TypeError, match="mimic joints but no model without them"):
        pickle.dumps(sjt.Robot(model, "tcp"))


def test_a_mimic_joint_outside_its_range_is_named_and_brought_back(gripper):
    """wrist = 1.0 puts tool_tilt (0.5 wrist + 0.1) at 0.6, past its own limit 0.4, while the
    wrist is within its own +-2: the step names tool_tilt (before: only the wrist) and brings
    the wrist back into the range tool_tilt leaves it, at its recovery speed (no jump)."""
    solver = sjt.SJTSolver(gripper, dt=1e-3)
    target = gripper.fk(np.array([0.3, 0.5, 0.2, 0.02]))
    q = np.array([0.0, 0.0, 1.0, 0.02])
    q = solver.step(q, target)
    assert solver.last.outside_limits == ("wrist", "tool_tilt")
    for _ in range(3000):
        previous = q
        q = solver.step(q, target)
        assert abs(q[2] - previous[2]) <= 0.25 / 0.5 * solver.dt * (1 + 1e-9)  # tool_tilt's
        # speed through its relation
    assert -0.2 <= gripper.joint_values(q)["tool_tilt"] <= 0.4
    assert solver.last.outside_limits == () and solver.error_norm < 1e-9


@pytest.mark.parametrize("robot_name", ["gripper", "panda"])
def test_a_mimic_joint_that_no_task_moves_says_it_stays_outside(robot_name, gripper):
    """A finger outside its range and off every task's chain stays there, as any joint no task
    moves: the first step warns and names the finger and its mimic, every step's StepInfo too;
    a posture task within the range brings both back."""
    robot = gripper if robot_name == "gripper" else sjt.Robot.from_example("panda")
    finger, mimic = (("left_finger", "right_finger") if robot_name == "gripper"
                     else ("panda_finger_joint1", "panda_finger_joint2"))
    index = robot.velocity_names.index(finger)
    q0 = robot.q0.copy() if robot_name == "panda" else np.array([0.1, 0.2, 0.1, 0.02])
    target = robot.fk(q0)
    q0[index] = 0.05  # both fingers 1 cm past their 4 cm
    solver = sjt.SJTSolver(robot, dt=1e-3)
    with pytest.warns(UserWarning, match=f"{finger}.*{mimic}.*no task moves them"):
        q = solver.step(q0, target)
    for _ in range(200):
        q = solver.step(q, target)
        assert solver.last.outside_limits == (finger, mimic)
    assert q[index] == 0.05
    posture = q0.copy()
    posture[index] = 0.02
    solver = sjt.SJTSolver(robot, dt=1e-3, posture=sjt.PostureTask(posture, weight=0.1))
    q = q0
    for _ in range(2000):
        q = solver.step(q, target)
    assert solver.last.outside_limits == ()
    values = robot.joint_values(q)
    assert abs(values[finger]) <= 0.04 and abs(values[mimic]) <= 0.04


def test_a_continuous_joint_locked_takes_its_continuous_mimic_along():
    """Locking a continuous joint that a continuous joint mimics: the follower is locked at
    its relation's angle, as (cos, sin). Before, its angle went into the cosine alone and the
    locked chain's rotation was not a rotation (|R^T R - I| = 0.99 on a random tree)."""
    urdf = """<robot name="twist"><link name="base"/><link name="a"/><link name="b"/>
      <link name="c"/><link name="tip"/>
      <joint name="ja" type="continuous"><parent link="base"/><child link="a"/>
        <axis xyz="0 0 1"/></joint>
      <joint name="jb" type="continuous"><parent link="a"/><child link="b"/>
        <origin xyz="0.2 0 0"/><axis xyz="1 0 0"/>
        <mimic joint="ja" multiplier="2.0" offset="0.1"/></joint>
      <joint name="jc" type="revolute"><parent link="b"/><child link="c"/>
        <origin xyz="0.2 0 0"/><axis xyz="0 1 0"/>
        <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
      <joint name="t" type="fixed"><parent link="c"/><child link="tip"/>
        <origin xyz="0.2 0 0"/></joint></robot>"""
    robot = sjt.Robot.from_urdf(urdf, ee_frame="tip")
    q = np.array([np.cos(0.7), np.sin(0.7), 0.3])
    arm = robot.reduced(["ja"], q=q)
    assert arm.nv == 1 and arm.mimic_joints == []
    for angle in (0.3, -1.1):
        pose = arm.fk(np.array([angle]))
        np.testing.assert_allclose(pose.rotation.T @ pose.rotation, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(pose.homogeneous,
                                   robot.fk(np.array([q[0], q[1], angle])).homogeneous,
                                   atol=1e-12)
