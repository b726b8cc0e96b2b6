"""Planar joints whose plane is the one their URDF ``<axis>`` says.

A URDF ``planar`` joint moves its child in the plane normal to its ``<axis>`` (default
``1 0 0``: the y-z plane) and turns it about that normal. Pinocchio's URDF parser ignores the
axis and always builds a joint in the x-y plane of the joint frame. :func:`orient_planar_joints`
puts the plane where the URDF says: the joint frame is turned by the rotation R taking +z onto
the axis (the shortest one), and everything attached to the joint — the child link's frames,
its inertia, the joints below it — is turned back by R^T, so that at rest (q neutral) every
placement is the URDF's and a motion of the joint is a translation within the plane normal to
the axis plus a rotation about it. The configuration stays Pinocchio's ``(x, y, cos, sin)``,
with x and y along R's first two columns.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pinocchio as pin


def orient_planar_joints(model: pin.Model, normals: Mapping[str, np.ndarray]) -> pin.Model:
    """``model`` (changed in place and returned) with the plane of each planar joint named in
    ``normals`` normal to its (unit) normal, given in the joint's frame."""
    z = np.array([0.0, 0.0, 1.0])
    for name, normal in normals.items():
        j = model.getJointId(name)
        R = pin.Quaternion.FromTwoVectors(z, np.asarray(normal, dtype=float)).matrix()
        if np.allclose(R, np.eye(3), rtol=0.0, atol=1e-15):
            continue
        turn, back = pin.SE3(R, np.zeros(3)), pin.SE3(R.T, np.zeros(3))
        model.jointPlacements[j] = model.jointPlacements[j] * turn
        model.inertias[j] = back.act(model.inertias[j])
        for child in range(j + 1, model.njoints):
            if model.parents[child] == j:
                model.jointPlacements[child] = back * model.jointPlacements[child]
        for f in range(model.nframes):
            frame = model.frames[f]
            if frame.parentJoint == j:
                frame.placement = back * frame.placement
                model.frames[f] = frame
    return model
