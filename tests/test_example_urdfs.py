"""Every URDF file example-robot-data ships, loaded from disk with ``Robot.from_urdf``."""

import shutil
import warnings
from pathlib import Path

import example_robot_data as erd
import pytest

import sjt_pin as sjt
from sjt_pin import mesh_paths

#: example-robot-data's robots folder; its meshes are package://example-robot-data/robots/...
ROBOTS = Path(erd.getModelPath("ur_description/urdf/ur5_robot.urdf")).resolve()
#: the folder that contains ``example-robot-data``: what finds every mesh
SHARE = ROBOTS.parent.parent
FILES = sorted(ROBOTS.rglob("*.urdf"))

#: files that cannot load, each with the reason the error must give (none is skipped)
BROKEN = {
    "falcon_description/urdf/falcon.urdf": "names child link 'Z_propeller', which is not defined",
    "ur_description/urdf/ur3.urdf": "<robot> has no <link>",  # an empty xacro output
    # absolute paths to a Romeo SDK folder: outside the URDF's folder, and absent
    "romeo_description/urdf/romeo_laas_small.urdf":
        "mesh file '/usr/Romeo/naoqi-sdk-2.3.0.14-linux64/share/alrobotmodel/meshes/romeo/",
}


def test_every_file_is_tested():
    assert len(FILES) >= 70
    names = {str(f.relative_to(ROBOTS)) for f in FILES}
    assert set(BROKEN) <= names


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROBOTS)))
def test_example_robot_data_urdf_loads_from_disk(path):
    """The model builds, and every mesh it names resolves inside example-robot-data (what
    ``load_visuals=True`` then loads; loading them all would take minutes)."""
    name = str(path.relative_to(ROBOTS))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # q0 outside limits, memory: not the point here
        if name in BROKEN:
            with pytest.raises(sjt.URDFError, match=BROKEN[name].replace("(", r"\(")):
                robot = sjt.Robot.from_urdf(path, ee_frame=0, load_visuals=False)
                mesh_paths.check_references(name, path.read_bytes(), path.parent,
                                            robot.package_dirs)
            return
        robot = sjt.Robot.from_urdf(path, ee_frame=0, load_visuals=False)
    assert robot.model.njoints >= 1 and robot.visual_model is None
    assert str(SHARE) in robot.package_dirs or not mesh_paths.mesh_references(path.read_bytes())
    mesh_paths.check_references(name, path.read_bytes(), path.parent, robot.package_dirs)


@pytest.mark.parametrize("name", ["bravo7_description/urdf/bravo7_no_ee.urdf",
                                  "so_arm_description/urdf/so101.urdf",
                                  "z1_description/urdf/z1.urdf",
                                  "ur_description/urdf/ur5_robot.urdf"])
def test_the_four_files_tried_load_with_their_meshes(name):
    robot = sjt.Robot.from_urdf(ROBOTS / name, ee_frame=0)  # failed before: meshes not found
    meshes = [g.meshPath for g in robot.visual_model.geometryObjects
              if Path(g.meshPath).is_absolute()]  # not primitives ("CYLINDER")
    assert meshes and all(Path(m).resolve().is_relative_to(SHARE) for m in meshes)


def test_a_copy_elsewhere_names_the_folder_to_pass(tmp_path):
    copy = tmp_path / "z1.urdf"
    shutil.copy(ROBOTS / "z1_description/urdf/z1.urdf", copy)
    with pytest.raises(sjt.URDFError) as caught:
        sjt.Robot.from_urdf(copy)
    message = str(caught.value)
    assert "no folder 'example-robot-data'" in message
    assert f"package_dirs=[{str(SHARE)!r}]" in message
    robot = sjt.Robot.from_urdf(copy, package_dirs=SHARE)  # the folder the message names
    assert len(robot.visual_model.geometryObjects) == 9
    # no meshes wanted: nothing to find
    assert sjt.Robot.from_urdf(copy, load_visuals=False).visual_model is None
