"""Generate the paper's planar arms and serial chains as URDF, with yourdfpy's object model.

- :func:`planar3`: the 3-link arm of the paper's Section 4 (Fig. 4): links 0.3, 0.4, 0.28 m and a
  fixed 0.2 m gripper ending in frame ``ee``; joints about +z, limits +-pi; stretched along +x at
  q = 0 (end effector at (1.18, 0, 0)).
- :func:`planar2`: the unit-length 2-link arm of Section 3.3 (motion ellipsoids).
- :func:`serial_chain`: any number of revolute joints with any axes (benchmarks, tests).

Run ``python robots/planar3.py`` (or ``python -m sjt_pin.robots.planar3``) to rewrite
``planar3.urdf`` beside this file; a test checks the committed file equals the generated one.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from lxml import etree
from yourdfpy import URDF
from yourdfpy.urdf import (
    Box,
    Color,
    Cylinder,
    Geometry,
    Joint,
    Limit,
    Link,
    Material,
    Robot,
    Visual,
)

PLANAR3_LENGTHS = (0.3, 0.4, 0.28)  # l1, l2, l3 in m (paper, Section 4)
PLANAR3_GRIPPER = 0.2  # m
PLANAR3_URDF = Path(__file__).with_name("planar3.urdf")

_COLORS = {
    "base": (0.25, 0.25, 0.28, 1.0),
    "link1": (0.85, 0.33, 0.10, 1.0),
    "link2": (0.93, 0.69, 0.13, 1.0),
    "link3": (0.47, 0.67, 0.19, 1.0),
    "gripper": (0.30, 0.45, 0.75, 1.0),
    "joint": (0.15, 0.15, 0.15, 1.0),
}
_Z = np.array([0.0, 0.0, 1.0])


def _pose(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 homogeneous transform from xyz (m) and roll-pitch-yaw (rad), as URDF composes them."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    T = np.eye(4)
    T[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    T[:3, 3] = xyz
    return T


def _material(name: str) -> Material:
    return Material(name=name, color=Color(rgba=np.array(_COLORS[name])))


def _rod(length: float, radius: float, material: str) -> Visual:
    """A cylinder along the link's +x from 0 to ``length`` (URDF cylinders point along z)."""
    return Visual(
        name=f"{material}_rod",
        origin=_pose((length / 2.0, 0.0, 0.0), (0.0, np.pi / 2.0, 0.0)),
        geometry=Geometry(cylinder=Cylinder(radius=radius, length=length)),
        material=_material(material),
    )


def _hub(radius: float, axis: np.ndarray) -> Visual:
    """A short cylinder on the joint axis, so each joint shows where it turns."""
    z = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    # rotate +z onto the axis: pitch then yaw
    pitch = np.arccos(np.clip(z[2], -1.0, 1.0))
    yaw = np.arctan2(z[1], z[0]) if np.hypot(z[0], z[1]) > 1e-12 else 0.0
    return Visual(
        name="joint_hub",
        origin=_pose(rpy=(0.0, pitch, yaw)),
        geometry=Geometry(cylinder=Cylinder(radius=1.6 * radius, length=4.0 * radius)),
        material=_material("joint"),
    )


def serial_chain(
    lengths: Sequence[float],
    *,
    name: str = "chain",
    axes: Sequence[Sequence[float]] | None = None,
    gripper: float = 0.0,
    joint_limit: float = np.pi,
    velocity_limit: float = 10.0,
    radius: float = 0.02,
) -> URDF:
    """A serial chain of revolute joints, link i of ``lengths[i]`` m along its own +x.

    Joint i sits at the end of link i-1 (the first at the base origin) and turns about
    ``axes[i]`` (default +z for all: a planar arm). A fixed ``gripper`` (m, 0 for none) follows
    the last link; the frame ``ee`` is at its tip. Limits: +-``joint_limit`` rad,
    ``velocity_limit`` rad/s.
    """
    lengths = [float(x) for x in lengths]
    if not lengths or min(lengths) < 0:
        raise ValueError(f"lengths must be a non-empty list of lengths >= 0 m, got {lengths}")
    axes = [_Z] * len(lengths) if axes is None else [np.asarray(a, dtype=float) for a in axes]
    if len(axes) != len(lengths) or any(a.shape != (3,) or np.linalg.norm(a) < 1e-9 for a in axes):
        raise ValueError("axes must hold one non-zero 3-vector per link")
    palette = ["link1", "link2", "link3"]
    links = [Link(name="base", visuals=[Visual(
        name="base_plate", origin=_pose((0.0, 0.0, -2.5 * radius)),
        geometry=Geometry(box=Box(size=np.array([6 * radius, 6 * radius, radius]))),
        material=_material("base"))])]
    joints = []
    parent, offset = "base", 0.0
    for i, (length, axis) in enumerate(zip(lengths, axes, strict=True), start=1):
        axis = axis / np.linalg.norm(axis)
        visuals = [_hub(radius, axis)]
        if length > 0:
            visuals.insert(0, _rod(length, radius, palette[(i - 1) % len(palette)]))
        links.append(Link(name=f"link{i}", visuals=visuals))
        joints.append(Joint(
            name=f"joint{i}", type="revolute", parent=parent, child=f"link{i}",
            origin=_pose((offset, 0.0, 0.0)), axis=axis,
            limit=Limit(effort=10.0, velocity=velocity_limit, lower=-joint_limit,
                        upper=joint_limit),
        ))
        parent, offset = f"link{i}", length
    if gripper > 0:
        links.append(Link(name="gripper", visuals=[Visual(
            name="gripper_box", origin=_pose((gripper / 2.0, 0.0, 0.0)),
            geometry=Geometry(box=Box(size=np.array([gripper, 1.5 * radius, 1.5 * radius]))),
            material=_material("gripper"))]))
        joints.append(Joint(name="gripper_joint", type="fixed", parent=parent, child="gripper",
                            origin=_pose((offset, 0.0, 0.0))))
        parent, offset = "gripper", gripper
    links.append(Link(name="ee"))
    joints.append(Joint(name="ee_joint", type="fixed", parent=parent, child="ee",
                        origin=_pose((offset, 0.0, 0.0))))
    robot = Robot(name=name, links=links, joints=joints)
    return URDF(robot=robot, build_scene_graph=False, load_meshes=False)


def planar3(scale: float = 1.0) -> URDF:
    """The paper's 3-link planar arm (Fig. 4); ``scale`` multiplies every length."""
    return serial_chain([scale * x for x in PLANAR3_LENGTHS], name="planar3",
                        gripper=scale * PLANAR3_GRIPPER, radius=0.02 * scale)


def planar2() -> URDF:
    """The unit-length planar 2-link arm of Section 3.3."""
    return serial_chain([1.0, 1.0], name="planar2", radius=0.05)


def to_xml(urdf: URDF) -> str:
    """URDF text of ``urdf``, indented (yourdfpy's own writer cannot pass pretty_print)."""
    return etree.tostring(urdf.write_xml(), pretty_print=True, xml_declaration=True,
                          encoding="utf-8").decode()


def main() -> None:
    PLANAR3_URDF.write_text(to_xml(planar3()))
    print(f"wrote {PLANAR3_URDF}")


if __name__ == "__main__":
    main()
