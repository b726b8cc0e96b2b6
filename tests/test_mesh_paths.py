"""Mesh files are read only from the URDF's folder and package_dirs (untrusted URDFs)."""

import os

import pinocchio as pin
import pytest
import trimesh

import sjt_pin as sjt
from sjt_pin.viewer.meshes import visual_parts

URDF = """<robot name="r">
  <link name="base"><visual><geometry><mesh filename="{mesh}"/></geometry></visual></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="tip"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="tip"/>
</robot>"""


@pytest.fixture
def layout(tmp_path):
    """ws/pkg/urdf/ (the URDF), ws/pkg/meshes/box.stl, ws/other/x.stl, secret/outside.stl,
    and ws/pkg/meshes/link.stl, a symbolic link to secret/outside.stl."""
    ws, secret = tmp_path / "ws", tmp_path / "secret"
    for folder in (ws / "pkg" / "urdf", ws / "pkg" / "meshes", ws / "other", secret):
        folder.mkdir(parents=True)
    box = trimesh.creation.box()
    for path in (ws / "pkg" / "meshes" / "box.stl", ws / "other" / "x.stl",
                 secret / "outside.stl"):
        box.export(path)
    os.symlink(secret / "outside.stl", ws / "pkg" / "meshes" / "link.stl")
    return tmp_path


def write(layout, mesh):
    path = layout / "ws" / "pkg" / "urdf" / "r.urdf"
    path.write_text(URDF.format(mesh=mesh))
    return path


def escapes(layout):
    outside = layout / "secret" / "outside.stl"
    return {
        "../../../secret/outside.stl": outside,
        str(outside): outside,
        f"file://{outside}": outside,
        "package://pkg/../other/x.stl": layout / "ws" / "other" / "x.stl",
        "package://pkg/meshes/link.stl": outside,  # a link inside the package, pointing out
    }


def test_mesh_paths_outside_the_allowed_folders_are_refused(layout, monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError("Pinocchio must not read the meshes")

    for mesh, resolved in escapes(layout).items():
        path = write(layout, mesh)
        with monkeypatch.context() as patch:
            patch.setattr(pin, "buildGeomFromUrdf", never)
            with pytest.raises(sjt.URDFError, match="lies outside the URDF's folder") as caught:
                sjt.Robot.from_urdf(path, package_dirs=layout / "ws")
        assert str(resolved) in str(caught.value), mesh
        # also when no geometry is loaded now: a collision limit would read it later
        with pytest.raises(sjt.URDFError, match="lies outside"):
            sjt.Robot.from_urdf(path, package_dirs=layout / "ws", load_visuals=False)
        # the user may opt in
        robot = sjt.Robot.from_urdf(path, package_dirs=layout / "ws", allow_outside_meshes=True)
        assert robot.mesh_roots is None
        assert os.path.realpath(robot.visual_model.geometryObjects[0].meshPath) == str(resolved)


def test_meshes_inside_the_package_load(layout):
    for mesh in ("package://pkg/meshes/box.stl", "../meshes/box.stl"):
        robot = sjt.Robot.from_urdf(write(layout, mesh), package_dirs=[layout / "ws"])
        (geometry,) = robot.visual_model.geometryObjects
        assert visual_parts(geometry, folders=robot.mesh_roots)
    # the URDF's own folder alone does not hold ../meshes
    with pytest.raises(sjt.URDFError, match="lies outside"):
        sjt.Robot.from_urdf(write(layout, "../meshes/box.stl"))


def test_the_viewer_reads_no_mesh_outside_the_robots_folders(layout):
    outside = layout / "secret" / "outside.stl"
    robot = sjt.Robot.from_urdf(write(layout, str(outside)), allow_outside_meshes=True)
    (geometry,) = robot.visual_model.geometryObjects
    with pytest.raises(sjt.URDFError, match=f"resolved: {outside}"):
        visual_parts(geometry, folders=(layout / "ws",))
    assert visual_parts(geometry, folders=None)  # opted in: read
    # a visual model handed to Robot is checked against its folders too
    with pytest.raises(sjt.URDFError, match="lies outside"):
        sjt.Robot(robot.model, "tip", visual_model=robot.visual_model,
                  package_dirs=[str(layout / "ws")])
