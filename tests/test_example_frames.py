"""Frames for any robot: every example-robot-data name loads without an end effector given and
lists its frames, a robot that names none gets the tip of its longest chain (and is told so),
and the frame list of an error is complete (or filterable with ``robot.frames(text)``)."""

import warnings

import pinocchio as pin
import pytest
from example_robot_data.robots_loader import ROBOTS

import sjt_pin as sjt
from sjt_pin.robot import DEFAULT_EE_FRAMES, chain_tip


def _load(name: str, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        robot = sjt.Robot.from_example(name, **kwargs)
    return robot, [str(w.message) for w in caught]


def test_every_name_is_in_the_loop_below():
    """example-robot-data's list, as the issue counted it: 72 names."""
    assert len(ROBOTS) >= 72


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_every_example_robot_gives_its_frames_without_a_guess(name):
    """Loaded without ``ee_frame``: a robot, its end effector among its frames, a filter that
    keeps exactly the names holding the text; a robot with no known end effector says which
    frame it took. Only an SDF model on a Pinocchio without an SDF parser cannot load, and
    then the error says why."""
    if name == "cassie" and not getattr(pin, "WITH_SDFORMAT", False):
        with pytest.raises(sjt.URDFError, match="SDF model.*without an SDF parser"):
            sjt.Robot.from_example(name)
        return
    robot, messages = _load(name)
    frames = robot.frames()
    assert len(frames) == len(robot.model.frames) > 1
    names = [f.name for f in frames]
    assert robot.ee_frame in names
    assert [f.id for f in frames] == list(range(len(frames)))
    if name in DEFAULT_EE_FRAMES:
        assert robot.ee_frame == DEFAULT_EE_FRAMES[name]
        assert not any("no end effector given" in m for m in messages)
    else:
        said = [m for m in messages if "no end effector given" in m]
        assert len(said) == 1 and repr(robot.ee_frame) in said[0], messages
        # the frame it took is carried by a joint that moves: a task on it moves the robot
        assert robot.jacobian(robot.q0).any()
    text = robot.ee_frame[1:4].upper()
    kept = robot.frames(text)
    assert kept and all(text.lower() in f.name.lower() for f in kept)
    assert len(kept) == sum(text.lower() in n.lower() for n in names)


def test_a_robot_without_a_known_end_effector_takes_its_longest_chains_tip():
    """TIAGo: the arm and its hand are its longest chain (torso, 7 arm joints, fingers); the
    message names the frame and how to choose another."""
    tiago, messages = _load("tiago")
    chain = tiago.model.supports[tiago.model.frames[tiago.ee_frame_id].parentJoint]
    names = {tiago.model.names[j] for j in chain}
    assert {"torso_lift_joint", "arm_1_joint", "arm_7_joint"} <= names
    assert any("tip of its longest kinematic chain" in m and "robot.frames('hand')" in m
               for m in messages)
    hands = tiago.frames("hand")
    assert "hand_palm_link" in [f.name for f in hands]
    assert all("hand" in f.name for f in hands) and len(hands) < len(tiago.frames())
    chosen, _ = _load("tiago", ee_frame="hand_palm_link")
    assert chosen.ee_frame == "hand_palm_link"


def test_tiagos_reference_pose_on_its_lower_limits_is_said_at_load():
    """TIAGo's q0 has the torso lift and the first arm joint on their lower limits."""
    _, messages = _load("tiago_no_hand", ee_frame="arm_tool_link")
    said = [m for m in messages if "at a limit of their URDF range" in m]
    assert len(said) == 1
    assert "torso_lift_joint (lower)" in said[0] and "arm_1_joint (lower)" in said[0]
    _, quiet = _load("ur5")  # UR5's q0 is inside its range: nothing said
    assert not any("at a limit" in m for m in quiet)


def test_the_frame_error_lists_every_frame_of_a_large_robot():
    """TIAGo's 156 frames all appear in the message (the list was cut after 30), and the
    message says how to filter them."""
    with pytest.raises(sjt.FrameNotFound) as caught:
        sjt.Robot.from_example("tiago", ee_frame="hand")
    message = str(caught.value)
    tiago, _ = _load("tiago")
    assert all(repr(f.name) in message for f in tiago.frames())
    assert "robot.frames('text')" in message and "robot.frames()" in message
    assert caught.value.available == [f.name for f in tiago.frames()]


def test_frames_filter_refuses_what_is_not_text(ur5):
    with pytest.raises(TypeError, match="pattern must be a str"):
        ur5.frames(3)
    assert ur5.frames("TOOL") == [f for f in ur5.frames() if "tool" in f.name.lower()]
    assert ur5.frames("no such frame") == []


def test_chain_tip_is_the_deepest_link_of_the_longest_chain():
    """A tree with a 3-joint branch and a 1-joint branch: the tip of the 3-joint one, a link
    before a joint frame; a locked joint does not count toward a chain's length."""
    def link(name):
        return f'<link name="{name}"/>'

    def joint(name, parent, child, x=0.1):
        return (f'<joint name="{name}" type="revolute"><parent link="{parent}"/>'
                f'<child link="{child}"/><origin xyz="{x} 0 0"/><axis xyz="0 0 1"/>'
                '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')

    urdf = ('<robot name="tree">' + "".join(link(n) for n in
                                            ["base", "a1", "a2", "a3", "b1", "c1", "c2"])
            + joint("ja1", "base", "a1") + joint("ja2", "a1", "a2") + joint("ja3", "a2", "a3")
            + joint("jb1", "base", "b1", x=5.0)
            + joint("jc1", "base", "c1") + joint("jc2", "c1", "c2") + "</robot>")
    robot = sjt.Robot.from_urdf(urdf, ee_frame="a3")
    assert chain_tip(robot.model) == "a3"
    assert chain_tip(robot.model, locked=["ja2", "ja3"]) == "c2"
