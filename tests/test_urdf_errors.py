"""Bad URDF input is rejected with an error naming the file (or argument) and the culprit.

``fixtures/urdf/`` holds one minimal URDF per failure class; before ``sjt_pin.urdf_check`` most
of them gave only Pinocchio's "The XML stream does not contain a valid URDF model." and some
(``zero_axis``, ``lower_above_upper``, ``cycle``) loaded without complaint.
"""

import os
import re
from os.path import join
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from example_robot_data.robots_loader import ROBOTS
from example_robot_data.utils import getModelPath

import sjt_pin as sjt
from sjt_pin.urdf_check import captured_stderr, check_urdf, read_urdf

FIXTURES = Path(__file__).parent / "fixtures" / "urdf"
ROBOTS_DIR = Path(__file__).parents[1] / "robots"

#: fixture -> fragments its error message must contain (besides the file's path)
BROKEN = {
    "truncated.urdf": ["not well-formed XML", "Premature end of data in tag joint line 6"],
    "wrong_root.urdf": ["root element is <sdf>, not <robot>"],
    "unnamed_joint.urdf": ["<joint> without a name", "line 6"],
    "duplicate_link.urdf": ["two links named 'arm'"],
    "missing_link.urdf": ["joint 'j2'", "child link 'tool'", "not defined", "'tool0'"],
    "two_parents.urdf": ["link 'tip' has two parents", "joint 'j2'", "joint 'j3'"],
    "cycle.urdf": ["'a' -> 'b' -> 'a'", "cycle", "a_to_b", "b_to_a"],
    "two_roots.urdf": ["several root links", "'base'", "'floor'"],
    "bad_joint_type.urdf": ["joint 'shoulder'", "type 'ball'"],
    "zero_axis.urdf": ["joint 'elbow'", "xyz='0 0 0'", "zero-length"],
    "nan_axis.urdf": ["joint 'elbow'", "<axis> xyz='0 nan 1'", "not three finite numbers"],
    "bad_origin.urdf": ["joint 'wrist'", "<origin> xyz='0.1 0.2'", "not three finite numbers"],
    "inf_link_origin.urdf": ["link 'tip'", "<visual><origin> xyz='0 0 inf'"],
    "lower_above_upper.urdf": ["joint 'elbow'", "lower='1.5' upper='-1.5'", "lower > upper"],
    "bad_limit_value.urdf": ["joint 'slider'", "upper='half'", "not a finite number"],
    "negative_velocity.urdf": ["joint 'elbow'", "<limit velocity='-2'> is negative"],
    "no_limit.urdf": ["Pinocchio cannot parse it", "Joint [elbow]", "does not specify limits"],
    "bad_visual.urdf": ["Pinocchio's parser reports", "radius [thick] is not a valid float",
                        "Link [arm]"],
    "empty.urdf": ["empty URDF"],
    "not_xml.urdf": ["not XML text", "b'solid cube"],
}


def _example_urdfs() -> list:
    """(name, URDF path) of every example-robot-data robot that has a URDF (a few, such as
    cassie, are SDF models only: there is no URDF to check)."""
    params = []
    for name, loader in ROBOTS.items():
        if not loader.urdf_filename:
            continue
        subpath = join(loader.path, loader.urdf_subpath, loader.urdf_filename)
        params.append(pytest.param(name, Path(getModelPath(subpath)) / subpath))
    return params


@pytest.mark.parametrize("fixture, fragments", BROKEN.items(), ids=list(BROKEN))
def test_broken_urdf_names_the_file_and_the_culprit(fixture, fragments):
    path = FIXTURES / fixture
    for source in (path, str(path)):
        with pytest.raises(sjt.URDFError) as info:
            sjt.Robot.from_urdf(source, load_visuals=False)
        message = str(info.value)
        assert str(path) in message
        for fragment in fragments:
            assert fragment in message


@pytest.mark.parametrize("fixture", [f for f in BROKEN if f not in ("empty.urdf",
                                                                    "not_xml.urdf")])
def test_broken_urdf_text_says_urdf_string(fixture):
    with pytest.raises(sjt.URDFError, match="invalid URDF <URDF string>: "):
        sjt.Robot.from_urdf((FIXTURES / fixture).read_text(), load_visuals=False)


@pytest.mark.parametrize("value, error, match", [
    ("", sjt.URDFError, "empty URDF: path_or_xml is ''"),
    (" \n\t", sjt.URDFError, "empty URDF"),
    ("\x00\x7fELF\x02\x01", sjt.URDFError,
     "path_or_xml is neither a URDF file path nor URDF XML text"),
    (b"\x89PNG\r\n\x1a\n", TypeError, "path_or_xml as bytes must be URDF XML text"),
    (b"<robot name='r'><link name='\xff'/></robot>", sjt.URDFError, "not UTF-8"),
    (None, TypeError, "path_or_xml must be a URDF file path .* got NoneType"),
    (42, TypeError, "path_or_xml must be a URDF file path .* got int"),
    ("x" * 5000, sjt.URDFError, "File name too long"),
])
def test_bad_path_or_xml_argument(value, error, match):
    with pytest.raises(error, match=match):
        sjt.Robot.from_urdf(value)


def test_missing_file_and_directory_name_the_path(tmp_path):
    missing = tmp_path / "arm.urdf"
    with pytest.raises(sjt.URDFError, match=f"URDF file not found: {re.escape(str(missing))}$"):
        sjt.Robot.from_urdf(str(missing))
    (tmp_path / "arm.urdf").write_text((FIXTURES / "one_joint.urdf").read_text())
    with pytest.raises(sjt.URDFError, match=rf"{re.escape(str(tmp_path))} is a directory, not a "
                                            r"file \(URDF files in it: \['arm.urdf'\]\)"):
        sjt.Robot.from_urdf(tmp_path)


def test_bytes_path_and_text_give_the_same_robot():
    path = ROBOTS_DIR / "planar3.urdf"  # has an XML declaration with encoding="utf-8"
    text = path.read_text()
    q = np.array([0.3, -0.2, 0.1])
    sources = {str(path): (path, str(path)),
               text: (text, text.encode(), b"\xef\xbb\xbf" + text.encode())}
    for urdf, group in sources.items():
        for source in group:
            robot = sjt.Robot.from_urdf(source, ee_frame="ee")
            assert robot.urdf == urdf and len(robot.visual_model.geometryObjects) == 8
            np.testing.assert_allclose(robot.fk(q).translation,
                                       sjt.Robot.planar3().fk(q).translation)


def test_single_package_dir_is_one_folder():
    robot = sjt.Robot.from_urdf(FIXTURES / "one_joint.urdf", package_dirs=str(ROBOTS_DIR))
    assert robot.package_dirs == [str(ROBOTS_DIR), str(FIXTURES.resolve())]


def test_pinocchio_stderr_is_captured_not_lost(capfd):
    with captured_stderr() as printed:
        os.write(2, b"Error:   from C++\n")
    assert printed.getvalue() == "Error:   from C++\n"
    assert capfd.readouterr().err == ""


@pytest.mark.parametrize("name, path", _example_urdfs())
def test_every_example_robot_urdf_passes_the_checks(name, path):
    check_urdf(read_urdf(path))
    robot = sjt.Robot.from_urdf(path, ee_frame="universe", load_visuals=False)
    assert list(robot.model.names) == list(pin.buildModelFromUrdf(str(path)).names)


def test_paper_planar3_urdf_passes_the_checks():
    check_urdf(read_urdf(ROBOTS_DIR / "planar3.urdf"))
    assert sjt.Robot.planar3().nv == 3
