"""URDF content is kept or refused, never silently changed: a planar joint moves in the plane
its ``<axis>`` names, an axis must be normalisable, ``lower == upper`` locks a joint, a tree too
deep for Pinocchio's recursive parser is refused before it can crash, and parsing from several
threads never loses the process's stderr. Before: the planar axis was ignored (always the x-y
plane), an axis of norm 1e-170 gave fk() a non-rotation, a locked joint became unlimited, a
3,900-link chain killed the interpreter (SIGSEGV) and two threads parsing at once could leave
fd 2 pointing at a deleted temporary file."""

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin import urdf_check
from sjt_pin.urdf_check import AXIS_EPSILON, MAX_DEPTH

ROOT = Path(__file__).parents[1]


def planar_urdf(axis: str | None) -> str:
    axis_tag = "" if axis is None else f'<axis xyz="{axis}"/>'
    return f"""<robot name="slider"><link name="table"/>
      <link name="puck"><visual><origin xyz="0.05 0 0"/><geometry><box size="0.1 0.05 0.02"/>
        </geometry></visual></link><link name="tip"/>
      <joint name="slide" type="planar"><parent link="table"/><child link="puck"/>
        <origin xyz="0.1 -0.2 0.3" rpy="0.3 -0.2 0.5"/>{axis_tag}</joint>
      <joint name="tool" type="fixed"><parent link="puck"/><child link="tip"/>
        <origin xyz="0.1 0.2 0.3" rpy="0.1 0.2 0.3"/></joint></robot>"""


ORIGIN = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.2, 0.5), np.array([0.1, -0.2, 0.3]))
TOOL = pin.SE3(pin.rpy.rpyToMatrix(0.1, 0.2, 0.3), np.array([0.1, 0.2, 0.3]))


@pytest.mark.parametrize("axis, normal", [
    ("0 0 1", [0, 0, 1]), ("0 0 -1", [0, 0, -1]), ("0 1 0", [0, 1, 0]),
    ("1 1 1", np.ones(3) / np.sqrt(3)), ("0.3 -2 0.5", np.array([0.3, -2, 0.5]) / np.sqrt(4.34)),
    (None, [1, 0, 0]),  # the URDF default axis
])
def test_a_planar_joint_moves_in_the_plane_normal_to_its_axis(axis, normal, rng):
    robot = sjt.Robot.from_urdf(planar_urdf(axis), ee_frame="tip")
    normal = np.asarray(normal, dtype=float)
    assert robot.nq == 4 and robot.nv == 3
    # at rest, every placement is the URDF's
    assert np.allclose(robot.fk(pin.neutral(robot.model)).homogeneous,
                       (ORIGIN * TOOL).homogeneous, atol=1e-12)
    for _ in range(5):
        q = robot.random_configuration(rng)
        q[:2] = rng.uniform(-1, 1, 2)
        theta = np.arctan2(q[3], q[2])
        puck = ORIGIN.actInv(robot.fk(q, "puck"))  # in the joint's frame
        assert abs(puck.translation @ normal) < 1e-12  # a translation within the plane
        assert np.allclose(puck.rotation, pin.exp3(theta * normal), atol=1e-12)
        assert np.allclose(robot.fk(q).homogeneous, (ORIGIN * puck * TOOL).homogeneous,
                           atol=1e-12)
        # the viewer's meshes follow the link
        data, gdata = robot.model.createData(), pin.GeometryData(robot.visual_model)
        pin.forwardKinematics(robot.model, data, q)
        pin.updateGeometryPlacements(robot.model, data, robot.visual_model, gdata)
        box = robot.fk(q, "puck") * pin.SE3(np.eye(3), np.array([0.05, 0, 0]))
        assert np.allclose(gdata.oMg[0].homogeneous, box.homogeneous, atol=1e-12)


def test_a_planar_robot_reaches_a_target_in_its_plane():
    robot = sjt.Robot.from_urdf(planar_urdf("1 1 1"), ee_frame="tip", load_visuals=False)
    q_goal = np.array([0.3, -0.2, np.cos(0.7), np.sin(0.7)])
    result = sjt.SJTSolver(robot).solve(robot.fk(q_goal), pin.neutral(robot.model))
    assert result.success
    assert np.allclose(robot.fk(result.q).homogeneous, robot.fk(q_goal).homogeneous, atol=1e-6)


def axis_urdf(axis: str, limits: str = 'lower="-1" upper="1"') -> str:
    return f"""<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
      <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="{axis}"/>
        <limit {limits} effort="1" velocity="1"/></joint>
      <joint name="k" type="revolute"><parent link="b"/><child link="c"/><origin xyz="1 0 0"/>
        <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
    </robot>"""


@pytest.mark.parametrize("axis", ["1e-170 0 0", "1e-170 1e-170 0", "0 1e-10 0"])
def test_an_axis_too_short_to_normalise_is_refused(axis):
    with pytest.raises(sjt.URDFError, match=f"joint 'j'.*{axis}.*below {AXIS_EPSILON:g}"):
        sjt.Robot.from_urdf(axis_urdf(axis), ee_frame="c")


def test_a_short_axis_above_the_epsilon_is_normalised():
    robot = sjt.Robot.from_urdf(axis_urdf("1e-5 1e-5 0"), ee_frame="c")
    R = robot.fk(np.array([0.4, 0.2])).rotation
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.allclose(robot.fk(np.array([0.4, 0.0]), "b").rotation,
                       pin.exp3(0.4 * np.array([1, 1, 0]) / np.sqrt(2)), atol=1e-12)


def test_lower_equal_to_upper_locks_the_joint():
    locked = axis_urdf("0 0 1", 'lower="0.5" upper="0.5"').replace(
        "</robot>", """<link name="d"/><joint name="m" type="revolute"><parent link="c"/>
        <child link="d"/><origin xyz="0.8 0 0"/><axis xyz="0 0 1"/>
        <limit lower="-2" upper="2" effort="1" velocity="1"/></joint><link name="e"/>
        <joint name="t" type="fixed"><parent link="d"/><child link="e"/>
        <origin xyz="0.5 0 0"/></joint></robot>""")
    robot = sjt.Robot.from_urdf(locked, ee_frame="e")
    assert robot.lower_limits[0] == robot.upper_limits[0] == 0.5
    assert robot.q0[0] == 0.5  # the neutral configuration, clipped into the limits
    target = robot.fk(np.array([0.5, 0.7, -0.4])).translation
    solver = sjt.SJTSolver(robot, task=sjt.PositionTask(axes="xy"), dt=1e-2)
    q = np.array([0.0, 0.3, 0.6])  # a seed outside: brought to 0.5, then held
    for _ in range(1000):
        q = solver.step(q, target)
    assert q[0] == 0.5 and solver.error_norm < 1e-6
    result = solver.solve(target, np.array([-0.3, 0.3, 0.6]))
    assert result.success and result.q[0] == 0.5 and result.clipped == ("j",)


def test_lower_and_upper_both_zero_are_no_limit():
    # a <limit> without lower/upper, or the CAD exporters' "0 0" for a free joint
    for limits in ('lower="0" upper="0"', ""):
        robot = sjt.Robot.from_urdf(axis_urdf("0 0 1", limits), ee_frame="c")
        assert robot.lower_limits[0] == -np.inf and robot.upper_limits[0] == np.inf


def chain(links: int) -> str:
    body = "".join(
        f'<link name="l{i + 1}"/><joint name="j{i}" type="revolute"><parent link="l{i}"/>'
        f'<child link="l{i + 1}"/><origin xyz="0 0 0.01"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>' for i in range(links))
    return f'<robot name="deep"><link name="l0"/>{body}</robot>'


def test_a_tree_too_deep_for_the_parser_is_refused_before_parsing():
    # in a child process: before the check, Pinocchio's parser died of a SIGSEGV here
    code = ("import sjt_pin as sjt\nfrom tests.test_urdf_semantics import chain\n"
            "try:\n    sjt.Robot.from_urdf(chain(4000), ee_frame='l4000')\n"
            "except sjt.URDFError as e:\n    print(e)\n")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 0, run.stderr
    assert f"link 'l{MAX_DEPTH + 1}' is {MAX_DEPTH + 1} links below the root" in run.stdout
    assert "deeper than 1000" in run.stdout


def test_the_deepest_tree_accepted_loads():
    # (1000 joints: its pin.Data would take ~31 GB, above the default memory budget; the model
    # itself is small, and no Data is made here)
    robot = sjt.Robot.from_urdf(chain(MAX_DEPTH), ee_frame=f"l{MAX_DEPTH}", load_visuals=False,
                                memory_budget=float("inf"))
    assert robot.nv == MAX_DEPTH


def test_parsing_in_threads_never_loses_stderr(monkeypatch):
    # a parse that lets other threads run meanwhile (as a long one, or one that releases the
    # GIL, does): before the lock, the second capture saved the first one's temporary file as
    # "stderr" and restored it last
    parse = pin.buildModelFromXML

    def slow_parse(*args, **kwargs):
        time.sleep(0.01)
        return parse(*args, **kwargs)

    monkeypatch.setattr(urdf_check.pin, "buildModelFromXML", slow_parse)
    before = os.fstat(2)
    errors: list[BaseException] = []

    def load():
        try:
            for _ in range(5):
                sjt.Robot.from_urdf(axis_urdf("0 0 1"), ee_frame="c", load_visuals=False)
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=load) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    after = os.fstat(2)
    assert (after.st_dev, after.st_ino) == (before.st_dev, before.st_ino)
